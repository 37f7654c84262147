"""The ALI3-P method: index-3 augmented Lagrangian with mass-orthogonal projections, compiled."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...core.errors import SingularConfigurationError
from ...numeric.friction import friction_joints
from ...numeric.tolerances import INDEX3_TIGHTEST
from ..drivers import Segment, require, run, segment_status, solution_of
from ..problem import MultibodyProblem, Solution, Solver, SolverOptions
from ..stepping import approach_scales
from .compiled import CompiledSolver

if TYPE_CHECKING:
    from ...numeric.numeric_model import NumericModel

__all__ = ["Index3Solver", "index3_segment"]


class Index3Solver(Solver):
    """Index-3 augmented Lagrangian with mass-orthogonal projections (ALI3-P), compiled.

    Integrates ``M qdd + C qd + g - f_Q + Phi_q^T lambda = 0``, ``Phi(q) = 0`` in
    positions with the trapezoidal rule: Newton's method on ``q`` with the exact
    tangent matrix ``J = M + h/2 D + h^2/4 (K + alpha Phi_q^T Phi_q)`` (``K``, ``D``
    generated symbolically: the ``"tangent"`` kernel of :mod:`kronlag.codegen`),
    the augmented Lagrangian update ``lambda* <- lambda* + alpha Phi`` and
    projections of the velocities and accelerations in the metric of ``J`` (see
    ``src/kronlag/simulation/c/index3.c``).  No rank decision enters a step: ``J`` stays
    positive definite where ``Phi_q`` loses rank, so the method passes singular
    configurations on the branch it is on (IFToMM A02) and integrates
    mechanisms with redundant constraints (IFToMM A04).  It does not detect a
    branch switch by itself: that it keeps the branch is checked by the tests
    (the cranks of A02 stay parallel from rtol 1e-2 to 1e-8).  The local error
    ``h^2/12 (qdd_{n+1} - qdd_n)`` in ``q`` is kept below ``atol + rtol |q|`` (both
    scaled: :attr:`TOLERANCE_SCALE`);
    outputs at ``t_eval`` are interpolated (cubic Hermite).  Second order: for
    tight tolerances on long runs :class:`SwitchingSolver` is much faster.
    """

    name = "ali3p"
    formulation = "index-3 augmented Lagrangian, mass-orthogonal projections (ALI3-P), compiled"
    integrator = "trapezoidal rule with local error control, compiled"
    order = 2
    requirements = ("the C backend, constant parameters, no nonholonomic constraints, no joint friction (its "
                    "index-3 iteration does not include it) and a C compiler")
    samples_inside = True
    #: The driver's ``rtol`` and ``atol`` are the requested ones divided by this, neither below
    #: :data:`~kronlag.numeric.tolerances.INDEX3_TIGHTEST`: the local error of a second-order
    #: method accumulates over ~1e4 steps, and its error control bounds the positions only, while
    #: the velocities' errors are what a later motion amplifies (IFToMM A02: with 3000 and ``atol``
    #: kept, the switching method's error of B0 was 2 to 12 mm at rtol 1e-4 to 1e-8, atol 1e-6;
    #: with 3e5 for both it is below 3e-4 m at rtol 1e-4 and 1e-5 m at rtol 1e-6 and tighter).
    TOLERANCE_SCALE = 3e5

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """C backend, constant parameters, no nonholonomic constraints, no joint friction, a C compiler."""
        return CompiledSolver.supports(model) and model.s == 0 and not friction_joints(model.equations.system)

    def solve(self, problem: MultibodyProblem) -> Solution:
        require(self, problem.model)
        segment = index3_segment(problem, self.options, problem.t0, problem.y0, handback=False)
        return solution_of([segment], *segment_status(segment, problem.model, "index3"))


def index3_segment(problem: MultibodyProblem, options: SolverOptions, t0: float, y0: np.ndarray,
                    handback: bool) -> Segment:
    """ALI3-P from the consistent state ``(t0, y0)`` until ``t1`` or, with ``handback``, until the
    motion has left the neighbourhood of a singular configuration (``flag``
    :data:`~kronlag.simulation.interface.HANDBACK`)."""
    model, m, r = problem.model, problem.m, problem.model.r
    q0, qd0 = y0[:m], y0[m:]
    try:
        start = model.forward_dynamics(q0, qd0, t0)
    except SingularConfigurationError:
        # exactly at a singular configuration: the least-squares accelerations of the
        # augmented Lagrangian start (the first step's Newton iteration corrects them)
        start = None
    a0 = np.zeros(m) if start is None else start.qdd
    lam0 = np.zeros(r) if start is None else start.lam
    scaled = options.scaled(Index3Solver.TOLERANCE_SCALE, INDEX3_TIGHTEST)
    return run("index3", problem, scaled, t0, y0, a0=a0, lam0=lam0, handback=int(handback),
               row_scale=approach_scales(problem))
