"""The projection method: the index-1 ODE projected onto the constraints after every step, by DOP853."""

from __future__ import annotations

from ..dop853 import DOP853Stepper
from ..problem import MultibodyProblem, Solution, Solver
from ..stepping import march
from .baumgarte import BaumgarteSolver

__all__ = ["ProjectionSolver"]


class ProjectionSolver(Solver):
    """Index-1 ODE with coordinate projection after every accepted step, by DOP853.

    Each accepted step of the explicit Runge-Kutta method is followed by
    :meth:`MultibodyProblem.project`: Gauss-Newton onto ``Phi(q) = 0``, then the
    velocities onto ``Phi_q qd + Phi_t = 0``, ``A qd + b = 0``.  The method is one-step,
    so continuing from the projected state costs only one right-hand side (the
    first stage) and keeps the step size; outputs are interpolated and
    projected too (Hairer & Wanner, Solving ODEs II, Sec. VII.2).  The drift is
    therefore at the projection tolerance, ``atol / 100``, at every output.
    """

    name = "projection"
    formulation = "index-1 ODE, coordinate projection (positions and velocities) after each step"
    integrator = BaumgarteSolver.integrator
    order = BaumgarteSolver.order

    def solve(self, problem: MultibodyProblem) -> Solution:
        return march(lambda: DOP853Stepper(problem, self.options, project=True), problem, self.options)
