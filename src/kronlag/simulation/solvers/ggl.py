"""The GGL method: the stabilized index-2 formulation of Gear, Gupta & Leimkuhler, by SUNDIALS IDA."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...core.errors import NumericalError
from ...numeric.friction import friction_joints
from ...numeric.linalg import least_norm
from ...numeric.tolerances import APPROACH_RTOL, numerical_rank, rank_magnitudes, singular_ratio
from ..drivers import require
from ..problem import MultibodyProblem, Solution, Solver, SolverOptions
from ..stepping import Stepper, approach_scales, march

if TYPE_CHECKING:
    from ...numeric.numeric_model import NumericModel

__all__ = ["GGLSolver"]


#: Absolute tolerance given to the algebraic unknowns of the GGL formulation in IDA.
_ALGEBRAIC_ATOL = 1e3


class _IDAStepper(Stepper):
    """SUNDIALS IDA (scikit-sundae) on the GGL residual of :class:`GGLSolver`."""

    def __init__(self, problem: MultibodyProblem, options: SolverOptions):
        self.problem, self.options, self.m = problem, options, problem.m
        self.nfev = self.njev = 0
        self.scales = approach_scales(problem)
        self._start(problem.t0, problem.y0)

    def _start(self, t: float, y: np.ndarray) -> None:
        """(Re)start IDA at the consistent state ``(t, y = [q, qd])``."""
        from sksundae.ida import IDA

        problem, options = self.problem, self.options
        model, m, s = problem.model, problem.m, problem.model.s
        q, qd = y[:m], y[m:]
        # Redundant constraints would make the DAE's Jacobian singular: only rows independent here
        # (the rank policy, kronlag.tolerances) enter the residual; step() chooses them again where
        # the motion makes them dependent while the whole set keeps its rank.
        Phi_q = model.Phi_q(q, t)
        magnitudes, rows = rank_magnitudes(Phi_q)
        self.rows = np.sort(rows[:numerical_rank(magnitudes, model.rank_rtol)])
        r = self.r = len(self.rows)
        start = model.forward_dynamics(q, qd, t)
        lam0 = least_norm(Phi_q[self.rows].T, Phi_q.T @ start.lam, rank_rtol=model.rank_rtol)
        y0 = np.concatenate([q, qd, lam0, start.mu, np.zeros(r)])
        yp0 = np.concatenate([qd, start.qdd, np.zeros(2 * r + s)])
        algebraic = np.arange(2 * m, 2 * m + 2 * r + s)
        # scikit-sundae does not expose IDASetSuppressAlg: a large absolute
        # tolerance gives the multipliers and eta a negligible weight, which
        # removes them from the local error test (their values follow from q, v).
        atol = np.full(y0.size, options.atol)
        atol[algebraic] = _ALGEBRAIC_ATOL
        if hasattr(self, "solver"):
            self.nfev, self.njev = self.counters()
        self.solver = IDA(self._residual, rtol=options.rtol, atol=atol, algebraic_idx=algebraic,
                          max_step=options.max_step if np.isfinite(options.max_step) else 0.0,
                          max_num_steps=options.max_steps + 1,
                          **({} if options.max_order is None else {"max_order": options.max_order}))
        self.solver.init_step(t, y0, yp0)
        self.t, self.y = t, y
        self.offsets = (self.nfev, self.njev)

    def _rows_dependent(self) -> bool:
        """The rows in the residual approach a rank loss (:data:`~kronlag.tolerances.APPROACH_RTOL`)
        that the whole ``Phi_q`` does not have: another choice of rows is needed."""
        model, r = self.problem.model, self.r
        if r == model.r:
            return False
        Phi_q = model.Phi_q(self.y[:self.m], self.t)
        return (singular_ratio(Phi_q[self.rows], r, self.scales[self.rows])[0] < APPROACH_RTOL
                <= singular_ratio(Phi_q, r, self.scales)[0])

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
        if self._rows_dependent():  # here, not at the end of the last step: its outputs need its solver
            self._start(self.t, self.y)
        result = self.solver.step(self.problem.t1, method="onestep", tstop=self.problem.t1)
        self.nfev, self.njev = self.offsets[0] + result.nfev, self.offsets[1] + result.njev
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
    regular; where the motion makes the chosen rows dependent while the whole set
    keeps its rank (:data:`~kronlag.tolerances.APPROACH_RTOL`; IFToMM A04 at t = 1.25 s),
    IDA restarts from the current state with rows chosen there.  The residual is evaluated in Python, so this is the slowest method (about
    0.15 s per simulated second of the four-bar at rtol 1e-8).
    """

    name = "ggl"
    formulation = "stabilized index-2 DAE (Gear-Gupta-Leimkuhler)"
    integrator = "variable-order BDF, SUNDIALS IDA (scikit-sundae)"
    order = 5
    min_order = 1
    requirements = "a model without joint friction (its residual does not include it)"

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """No joint friction."""
        return not friction_joints(model.equations.system)

    def solve(self, problem: MultibodyProblem) -> Solution:
        require(self, problem.model)
        return march(lambda: _IDAStepper(problem, self.options), problem, self.options)
