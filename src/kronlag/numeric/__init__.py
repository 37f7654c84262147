"""The numeric layer: equations turned into fast code and solved at given states.

- :mod:`.tolerances`: the numerical policy (rank decisions, projections), one place for Python and C;
- :mod:`.linalg`: the augmented solve, least-norm corrections, pseudo-inverses;
- :mod:`.projection`: Gauss-Newton onto ``Phi(q, t) = 0`` and the velocities onto ``B qd + c = 0``;
- :mod:`.codegen`: kernels printed as Python or C, compiled and cached (``source``, ``python_backend``,
  ``c_backend``, ``build``, ``layouts``);
- :mod:`.numeric_model`: :class:`NumericModel` (accessors from :mod:`.accessors`, forward dynamics, batches);
- :mod:`.inverse`, :mod:`.assembly`, :mod:`.reactions`: inverse dynamics, consistent initial states,
  named joint reactions.
"""

from ..core.errors import (
    ActuationWarning,
    AssemblyError,
    RedundantConstraintsWarning,
    SingularConfigurationError,
)
from .codegen.layouts import split_terms
from .codegen.python_backend import solve_dynamics_terms
from .linalg import least_norm, pseudo_inverses, solve_augmented, velocity_constraints
from .numeric_model import BATCH_MATRICES, NumericModel
from .results import ForwardDynamicsBatch, ForwardDynamicsResult, InverseDynamicsResult

__all__ = [
    "NumericModel",
    "ForwardDynamicsResult",
    "InverseDynamicsResult",
    "ForwardDynamicsBatch",
    "SingularConfigurationError",
    "AssemblyError",
    "RedundantConstraintsWarning",
    "ActuationWarning",
    "BATCH_MATRICES",
    "solve_augmented",
    "solve_dynamics_terms",
    "least_norm",
    "pseudo_inverses",
    "velocity_constraints",
    "split_terms",
]
