"""kronlag: equations of motion of constrained multibody systems in the
Kronecker-product matrix form of Lagrange's equations with multipliers
(Van Khang, Mech. Res. Commun. 38 (2011) 294-299)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0

The package is built in layers, each a subpackage that imports only from those below it
(``docs/architecture.md``; the direction is tested)::

    core -> model -> symbolic -> numeric -> simulation -> studies -> views -> app

This module gathers the public names; the module paths of earlier versions
(``kronlag.numeric``, ``kronlag.trajectory``, ...) keep working (:mod:`kronlag._legacy`).
"""

from importlib.metadata import PackageNotFoundError, version

from . import _legacy

_legacy.install()

from . import calculus, frames, joints, models  # noqa: E402  (old module paths: after the hook)
from .core.errors import (  # noqa: E402
    ActuationWarning,
    AssemblyError,
    CompilerError,
    DrivesNotAppliedWarning,
    EquilibriumError,
    InitialStateWarning,
    InputError,
    KronlagError,
    ModelError,
    NumericalError,
    ProjectionError,
    RedundantConstraintsWarning,
    SingularConfigurationError,
)
from .model.bodies import PlanarBody, PointMass, RigidBody, check_parameter_values  # noqa: E402
from .model.frames import Frame  # noqa: E402
from .model.free_bodies import FreeBody, free_body, mechanism  # noqa: E402
from .model.friction import Friction  # noqa: E402
from .model.joints import Joint  # noqa: E402
from .model.loads import Damper, Spring  # noqa: E402
from .model.modelfile import load_model  # noqa: E402
from .model.robot_formats import load_mjcf, load_sdf, load_urdf  # noqa: E402
from .model.rotations import RotationSequence  # noqa: E402
from .model.symbols import acceleration_symbol, coordinates, speed_symbol, t  # noqa: E402
from .model.system import System  # noqa: E402
from .numeric.numeric_model import NumericModel  # noqa: E402
from .numeric.reactions import Reaction  # noqa: E402
from .numeric.results import ForwardDynamicsBatch, ForwardDynamicsResult, InverseDynamicsResult  # noqa: E402
from .simulation.controllers import Sampled  # noqa: E402
from .simulation.problem import Solver  # noqa: E402
from .simulation.simulate import simulate  # noqa: E402
from .simulation.trajectory import LimitEvent, Result, SingularPassage, StictionEvent, Trajectory  # noqa: E402
from .studies.drives import InverseDynamicsRun, Kinematics, inverse_dynamics, kinematic_analysis  # noqa: E402
from .studies.equilibrium import Equilibrium  # noqa: E402
from .studies.linearization import LinearModel, linearize  # noqa: E402
from .studies.sweeps import SweepResult, sweep  # noqa: E402
from .symbolic.derivation import derive  # noqa: E402
from .symbolic.equations import Equations  # noqa: E402
from .views.fmu import export_fmu  # noqa: E402

try:
    __version__ = version("kronlag")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "unknown"

__all__ = [
    "calculus",
    "frames",
    "joints",
    "models",
    "Frame",
    "Friction",
    "Joint",
    "FreeBody",
    "free_body",
    "mechanism",
    "Reaction",
    "derive",
    "Equations",
    "load_model",
    "load_urdf",
    "load_mjcf",
    "load_sdf",
    "System",
    "LimitEvent",
    "StictionEvent",
    "PlanarBody",
    "RigidBody",
    "RotationSequence",
    "check_parameter_values",
    "PointMass",
    "Spring",
    "Damper",
    "coordinates",
    "speed_symbol",
    "acceleration_symbol",
    "t",
    "NumericModel",
    "ForwardDynamicsResult",
    "ForwardDynamicsBatch",
    "InverseDynamicsResult",
    "kinematic_analysis",
    "Kinematics",
    "inverse_dynamics",
    "InverseDynamicsRun",
    "simulate",
    "Sampled",
    "Solver",
    "Trajectory",
    "SingularPassage",
    "Result",
    "Equilibrium",
    "LinearModel",
    "linearize",
    "sweep",
    "SweepResult",
    "export_fmu",
    "KronlagError",
    "InputError",
    "ModelError",
    "NumericalError",
    "SingularConfigurationError",
    "AssemblyError",
    "ProjectionError",
    "EquilibriumError",
    "CompilerError",
    "RedundantConstraintsWarning",
    "ActuationWarning",
    "DrivesNotAppliedWarning",
    "InitialStateWarning",
]
