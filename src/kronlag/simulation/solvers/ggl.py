"""The GGL method: the stabilized index-2 formulation of Gear, Gupta & Leimkuhler, by SUNDIALS IDA."""

from __future__ import annotations

import numpy as np

from ...core.errors import NumericalError
from ...numeric.linalg import least_norm
from ...numeric.tolerances import numerical_rank, rank_magnitudes
from ..problem import MultibodyProblem, Solution, Solver, SolverOptions
from ..stepping import Stepper, march

__all__ = ["GGLSolver"]


#: Absolute tolerance given to the algebraic unknowns of the GGL formulation in IDA.
_ALGEBRAIC_ATOL = 1e3


class _IDAStepper(Stepper):
    """SUNDIALS IDA (scikit-sundae) on the GGL residual of :class:`GGLSolver`."""

    def __init__(self, problem: MultibodyProblem, options: SolverOptions):
        from sksundae.ida import IDA

        self.problem = problem
        model, m, s = problem.model, problem.m, problem.model.s
        self.m = m
        # Redundant constraints would make the DAE's Jacobian singular: only the rows that are
        # independent at the start (the rank policy, kronlag.tolerances) enter the residual.
        magnitudes, rows = rank_magnitudes(model.Phi_q(problem.q0, problem.t0))
        self.rows = np.sort(rows[:numerical_rank(magnitudes, model.rank_rtol)])
        r = self.r = len(self.rows)
        start = model.forward_dynamics(problem.q0, problem.qd0, problem.t0)
        lam0 = least_norm(model.Phi_q(problem.q0, problem.t0)[self.rows].T,
                          model.Phi_q(problem.q0, problem.t0).T @ start.lam, rank_rtol=model.rank_rtol)
        y0 = np.concatenate([problem.q0, problem.qd0, lam0, start.mu, np.zeros(r)])
        yp0 = np.concatenate([problem.qd0, start.qdd, np.zeros(2 * r + s)])
        algebraic = np.arange(2 * m, 2 * m + 2 * r + s)
        # scikit-sundae does not expose IDASetSuppressAlg: a large absolute
        # tolerance gives the multipliers and eta a negligible weight, which
        # removes them from the local error test (their values follow from q, v).
        atol = np.full(y0.size, options.atol)
        atol[algebraic] = _ALGEBRAIC_ATOL
        self.solver = IDA(self._residual, rtol=options.rtol, atol=atol, algebraic_idx=algebraic,
                          max_step=options.max_step if np.isfinite(options.max_step) else 0.0,
                          max_num_steps=options.max_steps + 1,
                          **({} if options.max_order is None else {"max_order": options.max_order}))
        self.solver.init_step(problem.t0, y0, yp0)
        self.t, self.y = problem.t0, problem.y0
        self.nfev = self.njev = 0

    def _residual(self, t: float, x: np.ndarray, xp: np.ndarray, res: np.ndarray) -> None:
        """GGL residual: ``x = [q, v, lam, mu, eta]`` (2 m + 2 r + s,) over the independent rows."""
        model, m, r, s = self.problem.model, self.m, self.r, self.problem.model.s
        q, v = x[:m], x[m:2 * m]
        lam, mu, eta = x[2 * m:2 * m + r], x[2 * m + r:2 * m + r + s], x[2 * m + r + s:]
        terms = model.dynamics_terms(q, v, t)  # M, h = f_Q - C v - g, Phi, Phi_q, Phi_t, A, b at (q, v)
        Phi_q, A = terms["Phi_q"][self.rows], terms["A"]
        res[:m] = xp[:m] - v + Phi_q.T @ eta
        res[m:2 * m] = terms["M"] @ xp[m:2 * m] - terms["h"] + Phi_q.T @ lam + A.T @ mu
        res[2 * m:2 * m + r] = terms["Phi"][self.rows]
        res[2 * m + r:2 * m + 2 * r] = Phi_q @ v + terms["Phi_t"][self.rows]
        res[2 * m + 2 * r:] = A @ v + terms["b"]

    def step(self) -> str | None:
        result = self.solver.step(self.problem.t1, method="onestep", tstop=self.problem.t1)
        self.nfev, self.njev = result.nfev, result.njev
        if not result.success:
            return result.message
        self.t, self.y = float(result.t), result.y[:2 * self.m]
        return None

    def interpolate(self, t: float) -> np.ndarray:
        result = self.solver.step(t, method="normal")  # t inside the last step: IDA only interpolates
        if not result.success:
            raise NumericalError(f"IDA could not interpolate at t = {t!r}: {result.message}")
        return result.y[:2 * self.m]

    def counters(self) -> tuple[int, int]:
        return self.nfev, self.njev


class GGLSolver(Solver):
    """Stabilized index-2 formulation of Gear, Gupta & Leimkuhler (1985), by SUNDIALS IDA.

    Unknowns ``x = [q, v, lam, mu, eta]`` (2 m + 2 r + s) with residual::

        q' - v + Phi_q^T eta                           = 0   (m)
        M v' + C(q, v) v + g + Phi_q^T lam + A^T mu - f_Q = 0   (m)
        Phi(q)                                         = 0   (r)
        Phi_q v                                        = 0   (r)
        A v + b                                        = 0   (s)

    ``eta`` vanishes on the exact solution and keeps ``q`` on ``Phi(q) = 0``
    while ``v`` satisfies the velocity constraints.  IDA (variable-order BDF,
    scikit-sundae ``sksundae.ida.IDA``, residual from one
    ``model.dynamics_terms`` call) integrates it with the multipliers and
    ``eta`` flagged algebraic (``algebraic_idx``) and kept out of the error
    test by an absolute tolerance of 1e3 (scikit-sundae does not expose
    ``IDASetSuppressAlg``); the consistent initial values are ``v0 = qd0``,
    ``eta0 = 0`` and ``(qdd0, lam0, mu0)`` from ``model.forward_dynamics(q0, qd0, t0)``.
    With redundant constraints only the rows independent at the start enter
    (the rank policy of :mod:`kronlag.tolerances`), so that the Jacobian stays
    regular; where the motion makes another set of rows dependent, IDA fails
    (status -1).  The residual is evaluated in Python, so this is the slowest method (about
    0.15 s per simulated second of the four-bar at rtol 1e-8).
    """

    name = "ggl"
    formulation = "stabilized index-2 DAE (Gear-Gupta-Leimkuhler)"
    integrator = "variable-order BDF, SUNDIALS IDA (scikit-sundae)"
    order = 5
    min_order = 1

    def solve(self, problem: MultibodyProblem) -> Solution:
        return march(lambda: _IDAStepper(problem, self.options), problem, self.options)
