"""kronlag: equations of motion of constrained multibody systems in the
Kronecker-product matrix form of Lagrange's equations with multipliers
(Van Khang, Mech. Res. Commun. 38 (2011) 294-299)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0
"""

from . import calculus, models
from .derivation import derive
from .equations import Equations
from .modelfile import load_model
from .numeric import (
    AssemblyError,
    ForwardDynamicsResult,
    InverseDynamicsResult,
    NumericModel,
    RedundantConstraintsWarning,
    SingularConfigurationError,
)
from .simulation import simulate
from .trajectory import Trajectory
from .system import (
    Damper,
    ModelError,
    PlanarBody,
    PointMass,
    RigidBody,
    RotationSequence,
    Spring,
    System,
    acceleration_symbol,
    check_parameter_values,
    coordinates,
    speed_symbol,
    t,
)

__version__ = "0.1.0"

__all__ = [
    "calculus",
    "models",
    "derive",
    "Equations",
    "load_model",
    "System",
    "PlanarBody",
    "RigidBody",
    "RotationSequence",
    "check_parameter_values",
    "PointMass",
    "Spring",
    "Damper",
    "ModelError",
    "coordinates",
    "speed_symbol",
    "acceleration_symbol",
    "t",
    "NumericModel",
    "ForwardDynamicsResult",
    "InverseDynamicsResult",
    "SingularConfigurationError",
    "AssemblyError",
    "RedundantConstraintsWarning",
    "simulate",
    "Trajectory",
]
