"""Model files: a mechanism, its parameter values and run settings in TOML.

:func:`load_model` reads a file into a :class:`ModelFile` (the
:class:`~kronlag.System` plus numbers for running it) and :func:`to_toml` /
:func:`dump_model` write one.  Expressions are text read by
:func:`kronlag.expressions.parse_expression`, which admits arithmetic, the
functions ``sin cos tan asin acos atan atan2 sinh cosh tanh sqrt exp log abs min max heaviside``
and ``pi`` only; nothing in a file is executed.  Every error names the file,
the entry (``bodies[2].position[1]``, indices from 0) and the problem.

Format (every table but ``coordinates`` is optional)::

    name = "four_bar"
    description = "Planar four-bar mechanism"
    coordinates = ["q1", "q2", "q3"]
    gravity = [0, "-g"]                         # 2 or 3 entries

    [parameters]                                # number, expression of other parameters,
    l1 = {value = 0.2, unit = "m"}              # or {value = ..., unit = "...", description = "..."};
    I1 = {value = "m1*l1**2/12", unit = "kg*m^2"}   # a parameter without value: {unit = "m"}
    tau = 0

    [points]                                    # named points, usable wherever a point is; their
    B = ["l1*cos(q1)", "l1*sin(q1)"]            # coordinates B_x, B_y (B_z) in any later expression

    [[bodies]]                                  # type = "planar" | "rigid" | "point"
    name = "crank"
    type = "planar"
    mass = "m1"
    inertia = "I1"                              # rigid: 3x3 matrix or 3 principal moments
    position = ["l1/2*cos(q1)", "l1/2*sin(q1)"]
    angle = "q1"                                # rigid: rotation = 3x3 matrix or
                                                # {axes = "zxz", angles = ["psi", "theta", "phi"]}
    points = {B = ["l1/2", 0]}                  # named points in body coordinates (from the centre
                                                # of mass, body axes), usable wherever a point is
    [[joints]]                                  # kronlag.joints: type, body_a ("ground" or a body),
    type = "revolute"                           # body_b; optional name, at_a, at_b (body coordinates
    body_a = "crank"                            # or the name of a point of that body), axis, axis_b,
    body_b = "coupler"                          # angle, rotation; adds the rows "<name>.x", ...
    at_a = "B"
    at_b = ["-l2/2", 0]

    [[constraints]]                             # f(q) = 0, or f(q, t) = 0 (a drive in every run)
    name = "loop x"
    expression = "l1*cos(q1) + l2*cos(q2) - l3*cos(q3) - l4"

    [[nonholonomic_constraints]]                # linear in the speeds q1d, q2d, ...
    [[springs]]        # name, point_a, point_b, stiffness, free_length
    [[dampers]]        # name, point_a, point_b, coefficient
    [[potentials]]     # name, expression
    [[forces]]         # name, point, force (vector; may use t and speeds)
    [[torques]]        # name, body, torque (scalar for planar bodies, 3-vector otherwise), frame
    [[generalized_forces]]   # name, force (one entry per coordinate)

    [initial]
    q = {q1 = 1.0, q2 = "pi/4"}                 # assembly guess (missing coordinates: 0)
    fixed = ["q1"]                              # held at the guess while assembling
    qd = {q1 = 2.0}                             # speed guess
    qd_fixed = ["q1"]

    [simulation]
    t_end = 2.0
    method = "auto"
    rtol = 1e-8
    atol = 1e-10

    [[drives]]                                  # prescribed motion for kinematics and inverse dynamics
    coordinate = "q1"                           # or target = "<expression of q>", e.g. "P_x" of a point P
    motion = "1 + 2*pi*t"                       # optional name (default "drive <target>")

    [controller]                                # a controller in the loop (docs/control.md):
    type = "state_feedback"                     # u = -K (x - x_ref); or type = "pid" (coordinate,
    input = "u"                                 # setpoint, kp, ki, kd, period)
    states = ["q1", "q1d"]
    gains = [{value = 20, unit = "N*m/rad"}, 2.0]   # SI numbers or {value, unit}
    period = 0.001                              # optional: sampled (zero-order hold)

    [[drawing]]                                 # name, points (list of points)
    [[traces]]                                  # name, point
"""

from ...core.errors import ModelFileError
from .model_file import ModelFile, PrescribedMotion, SimulationSettings
from .reader import load_model, loads_model
from .writer import dump_model, to_toml

__all__ = [
    "ModelFileError",
    "ModelFile",
    "PrescribedMotion",
    "SimulationSettings",
    "load_model",
    "loads_model",
    "to_toml",
    "dump_model",
]
