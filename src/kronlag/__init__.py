"""kronlag: equations of motion of constrained multibody systems in the
Kronecker-product matrix form of Lagrange's equations with multipliers
(Van Khang, Mech. Res. Commun. 38 (2011) 294-299)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0
"""

from . import calculus, frames, joints, models
from .analysis import Equilibrium, EquilibriumError, LinearModel
from .derivation import derive
from .drives import InverseDynamicsRun, Kinematics, inverse_dynamics, kinematic_analysis
from .equations import Equations
from .modelfile import load_model
from .numeric import (
    ActuationWarning,
    AssemblyError,
    ForwardDynamicsBatch,
    ForwardDynamicsResult,
    InverseDynamicsResult,
    NumericModel,
    RedundantConstraintsWarning,
    SingularConfigurationError,
)
from .simulation import simulate
from .sweeps import SweepResult, sweep
from .trajectory import Result, SingularPassage, Trajectory
from .reactions import Reaction
from .joints import FreeBody, Joint, free_body, mechanism
from .frames import Frame
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
    "frames",
    "joints",
    "models",
    "Frame",
    "Joint",
    "FreeBody",
    "free_body",
    "mechanism",
    "Reaction",
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
    "ForwardDynamicsBatch",
    "InverseDynamicsResult",
    "SingularConfigurationError",
    "AssemblyError",
    "RedundantConstraintsWarning",
    "ActuationWarning",
    "kinematic_analysis",
    "Kinematics",
    "inverse_dynamics",
    "InverseDynamicsRun",
    "simulate",
    "Trajectory",
    "SingularPassage",
    "Result",
    "Equilibrium",
    "EquilibriumError",
    "LinearModel",
    "sweep",
    "SweepResult",
]
