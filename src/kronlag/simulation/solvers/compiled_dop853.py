"""The compiled DOP853 method: the Baumgarte ODE integrated by DOP853 in C, outputs projected."""

from __future__ import annotations

from ..drivers import require, run
from ..problem import MultibodyProblem, Solution, Solver
from ..stepping import approach_scales
from .baumgarte import BaumgarteSolver
from .compiled import CompiledSolver, compiled_solution

__all__ = ["CompiledDOP853Solver"]


class CompiledDOP853Solver(Solver):
    """The Baumgarte index-1 ODE of :class:`CompiledSolver` integrated by DOP853 in compiled code,
    outputs projected.

    The same ``y = [q, qd]``, ``y' = [qd, qdd]`` with
    ``Phi_q qdd = gamma - 2 alpha Phi_q qd - beta^2 Phi`` and ``A qdd = gamma_nh - alpha (A qd + b)``,
    the same projection of every output onto the constraints, watch of singular configurations
    (the run ends at the approach to one with status -1, as :class:`CompiledSolver`'s) and outputs
    computed in C (``src/kronlag/simulation/c/dop853.c``, in the model's library).  The integrator is
    scipy's DOP853 (Dormand-Prince 8(5,3), the method of :class:`BaumgarteSolver`) written in C step
    for step, with its coefficients read from scipy: it takes the steps scipy's takes, and its
    global error at a tolerance is DOP853's, so the tolerances are used as given (CVODE needs them
    10^4 times tighter).  For smooth runs without limits or exact stiction it is the fastest method:
    four-bar, 10 s, rtol 1e-8, every step: 400 steps against CVODE's 5900 (``bench/bench_simulate.py``).
    Limits and exact stiction are not watched by this driver: such runs are refused.
    """

    name = "dop853"
    formulation = CompiledSolver.formulation
    stabilization = CompiledSolver.stabilization
    integrator = f"{BaumgarteSolver.integrator.split(',')[0]}, compiled (scipy's DOP853 step for step)"
    order = BaumgarteSolver.order
    requirements = CompiledSolver.requirements
    supports = staticmethod(CompiledSolver.supports)
    samples_inside = True

    def solve(self, problem: MultibodyProblem) -> Solution:
        require(self, problem.model)
        segment = run("dop853", problem, self.options, problem.t0, problem.y0,
                      projection_tol=self.options.projection_tol, alpha=problem.alpha, beta=problem.beta,
                      row_scale=approach_scales(problem))
        return compiled_solution(problem, segment, "dop853")
