"""Studies on a numeric model: kinematics and inverse dynamics along drives (:mod:`.drives`), static
equilibrium (:mod:`.equilibrium`), the constraints' ranks by joint or loop (:mod:`.constraint_groups`),
linearization and modes (:mod:`.linearization`, with the exact Jacobians of :mod:`.tangent`) and
parameter sweeps (:mod:`.sweeps`)."""
