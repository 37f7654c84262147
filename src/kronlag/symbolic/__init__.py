"""The symbolic layer: matrix calculus (:mod:`.calculus`), the catalogue of the equation matrices
(:mod:`.matrices`), the derivation (:mod:`.derivation`) into an :class:`~kronlag.symbolic.equations.Equations`
object, point kinematics (:mod:`.kinematics`), and the equations written out: code in other languages
and reports (:mod:`.export`), CasADi and JAX functions (:mod:`.interop`)."""
