"""Time integration of the equations of motion (the differential-algebraic equations)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    Phi(q) = 0,   A(q) qd + b(q) = 0

The layout follows ``scipy.integrate`` and diffrax: a :class:`MultibodyProblem`
(the model, the time span, the initial state), a solver class per method (each
declares its formulation and order) and a :class:`Solution` of raw states are
separate types joined by one driver, :func:`simulate`, which also recomputes
the accelerations, multipliers, energies and constraint residuals at the output
times and returns a :class:`kronlag.Trajectory`.
"""

from __future__ import annotations

import ctypes
import time
import warnings
import weakref
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from contextlib import suppress
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from scipy.integrate import DOP853

from . import codegen
from .numeric import AssemblyError, SingularConfigurationError, least_norm, velocity_constraints
from .tolerances import APPROACH_RTOL, numerical_rank, rank_magnitudes, singular_ratio
from .trajectory import Result, SingularPassage, Trajectory

if TYPE_CHECKING:
    from .numeric import NumericModel

__all__ = [
    "simulate",
    "METHODS",
    "ProjectionError",
    "MultibodyProblem",
    "Solution",
    "SolverOptions",
    "Solver",
    "BaumgarteSolver",
    "ProjectionSolver",
    "GGLSolver",
    "CompiledSolver",
    "Index3Solver",
    "SwitchingSolver",
    "InitialStateWarning",
    "Result",
    "AUTO_PREFERENCE",
]


class ProjectionError(RuntimeError):
    """The projection onto the constraint manifold did not converge."""


_SUCCESS = Result.SUCCESS.value
#: Failures of the model evaluation that end an integration (partial results are returned).
_FAILURES = (SingularConfigurationError, ProjectionError, np.linalg.LinAlgError, FloatingPointError)
#: Most Gauss-Newton iterations of one position projection.
_MAX_PROJECTION_ITERATIONS = 8
#: A Gauss-Newton step below ``_STALL (1 + |q|)`` is at rounding level and ends the projection.
_STALL = 1e-15
#: Absolute tolerance given to the algebraic unknowns of the GGL formulation in IDA.
_ALGEBRAIC_ATOL = 1e3


@dataclass(frozen=True, eq=False)
class MultibodyProblem:
    """Initial-value problem for ``y = [q, qd]`` (length 2 m) on ``[t0, t1]``.

    Attributes
    ----------
    model : NumericModel
    t0, t1 : float
    q0, qd0 : (m,)
        Initial state (projected onto the constraints by :func:`simulate`).
    t_eval : (K,) or None
        Output times in ``[t0, t1]``, increasing; ``None``: every accepted step.
    alpha, beta : float
        Baumgarte parameters of :meth:`rhs`.
    """

    model: NumericModel
    t0: float
    t1: float
    q0: np.ndarray
    qd0: np.ndarray
    t_eval: np.ndarray | None
    alpha: float
    beta: float

    @property
    def m(self) -> int:
        return self.model.m

    @property
    def y0(self) -> np.ndarray:
        """``[q0, qd0]``, shape (2 m,)."""
        return np.concatenate([self.q0, self.qd0])

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """Index-1 right-hand side ``[qd, qdd]`` with Baumgarte stabilization, shape (2 m,).

        ``qdd`` solves ``[[M, Phi_q^T, A^T], [Phi_q, 0, 0], [A, 0, 0]] [qdd; lam; mu] =
        [f_Q - C qd - g; gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi; gamma_nh - alpha (A qd + b)]``.
        """
        q, qd = y[:self.m], y[self.m:]
        result = self.model.forward_dynamics(q, qd, t, alpha=self.alpha, beta=self.beta)
        return np.concatenate([qd, result.qdd])

    def project(self, t: float, y: np.ndarray, tol: float) -> np.ndarray:
        """Project ``y = [q, qd]`` onto the constraint manifold, shape (2 m,).

        Positions by Gauss-Newton steps on ``Phi(q) = 0`` (the smallest correction
        in the Euclidean norm, over the independent rows: :func:`kronlag.numeric.least_norm`),
        until ``max |Phi| <= tol`` or a step is at rounding
        level (``|dq| <= 1e-15 (1 + |q|)``)::

            q <- q - Phi_q^+ Phi(q)

        then velocities onto ``B qd + c = 0`` with ``B = [Phi_q; A]`` (r + s, m)
        and ``c = [Phi_t; b]`` in one step, ``qd <- qd - B^+ (B qd + c)``.  The
        pseudo-inverses (least squares, minimum norm) keep redundant
        constraints, a rank-deficient ``Phi_q``, working.

        Raises
        ------
        ProjectionError
            If the Gauss-Newton iteration does not converge.
        """
        model, m = self.model, self.m
        q, qd = y[:m].copy(), y[m:].copy()
        terms = model.dynamics_terms(q, qd, t)
        stalled = False
        for _ in range(_MAX_PROJECTION_ITERATIONS):
            if not model.r or stalled or np.max(np.abs(terms["Phi"])) <= tol:
                break
            jacobian = terms["Phi_q"]
            step = least_norm(jacobian, terms["Phi"], rank_rtol=model.rank_rtol)
            q -= step
            stalled = bool(np.all(np.abs(step) <= _STALL * (1 + np.abs(q))))
            terms = model.dynamics_terms(q, qd, t)
        else:
            raise ProjectionError(f"the position projection did not converge at t = {t!r}: "
                                  f"max |Phi| = {np.max(np.abs(terms['Phi'])):.3g}")
        if model.r + model.s:
            B, c = velocity_constraints(terms)
            qd -= least_norm(B, B @ qd + c, rank_rtol=model.rank_rtol)
        return np.concatenate([q, qd])


@dataclass(frozen=True, eq=False)
class Solution:
    """Raw solver output: states ``y = [q, qd]`` at the output times.

    Attributes
    ----------
    t : (N,)
    y : (N, 2 m)
    status : int
        0 success, -1 failure (``t``, ``y`` hold what was computed before it).
    message : str
    nfev, njev, steps : int
        Right-hand-side or residual evaluations, Jacobian evaluations, accepted steps.
    derived : dict or None
        ``qdd`` (N, m), ``lam`` (N, r), ``mu`` (N, s), ``kinetic_energy`` (N,),
        ``potential_energy`` (N,), ``position_residual`` (N, r), ``velocity_residual``
        (N, r + s) at the outputs, when the solver computed them (else :func:`simulate` does).
    events : tuple of SingularPassage
        Singular configurations passed.
    result : Result
        How it ended (``status`` is ``result.status``).
    """

    t: np.ndarray
    y: np.ndarray
    status: int
    message: str
    nfev: int
    njev: int
    steps: int
    derived: dict[str, np.ndarray] | None = None
    events: tuple[SingularPassage, ...] = ()
    result: Result = Result.SUCCESS


@dataclass(frozen=True)
class SolverOptions:
    """Options common to every solver (see :func:`simulate`)."""

    rtol: float
    atol: float
    max_step: float
    max_steps: int
    progress: Callable[[float], object] | None

    @property
    def projection_tol(self) -> float:
        """Residual tolerance of the position projection: ``atol / 100``."""
        return self.atol / 100


class Solver(ABC):
    """A time-integration method for a :class:`MultibodyProblem`.

    Subclasses declare ``name``, ``formulation`` (the equations integrated),
    ``order`` and, where they need more than any model, ``requirements`` and
    :meth:`supports`, and implement :meth:`solve`.
    """

    name: ClassVar[str]
    formulation: ClassVar[str]
    order: ClassVar[str]
    #: What a model needs for this method (said when :meth:`supports` is False).
    requirements: ClassVar[str] = "nothing"
    #: Default Baumgarte ``alpha`` and ``beta`` of the index-1 ODE it integrates (0: none).
    stabilization: ClassVar[float] = 0.0

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """Whether the method can integrate ``model``."""
        return True

    def __init__(self, options: SolverOptions):
        self.options = options

    @abstractmethod
    def solve(self, problem: MultibodyProblem) -> Solution:
        """Integrate ``problem``; failures are reported in the solution, not raised."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(formulation={self.formulation!r}, order={self.order!r})"


# -- Python-driven integrators: one stepping loop ---------------------------------------------


class _Stepper(ABC):
    """One integrator advanced step by step from Python; ``y`` is ``[q, qd]`` (2 m,)."""

    t: float
    y: np.ndarray

    @abstractmethod
    def step(self) -> str | None:
        """Take one accepted step; return a failure message or ``None``."""

    @abstractmethod
    def interpolate(self, t: float) -> np.ndarray:
        """``[q, qd]`` at ``t`` inside the last step, shape (2 m,)."""

    @abstractmethod
    def counters(self) -> tuple[int, int]:
        """``(nfev, njev)`` so far."""

    def limit_step(self, max_step: float) -> None:
        """Bound the next step (where the integrator allows it; else nothing)."""


class _ApproachWatch:
    """The watch of ``src/kronlag/c/monitor.c`` for the Python-driven index-1 methods: the
    singular ratio of ``Phi_q`` (:func:`kronlag.tolerances.singular_ratio`) at every accepted step,
    the next step limited so that the ratio, extrapolated, keeps half its value, and the approach
    to a singular configuration (ratio below :data:`~kronlag.tolerances.APPROACH_RTOL`)."""

    def __init__(self, problem: MultibodyProblem):
        self.model = problem.model
        Phi_q = self.model.Phi_q(problem.q0, problem.t0)
        self.generic_rank = numerical_rank(rank_magnitudes(Phi_q)[0], self.model.rank_rtol)
        self.samples = [(problem.t0, singular_ratio(Phi_q, self.generic_rank)[0])]

    def observe(self, t: float, y: np.ndarray) -> SingularPassage | None:
        """The approach at the accepted state ``(t, y)``, or None."""
        q = y[:self.model.m]
        ratio, row = singular_ratio(self.model.Phi_q(q, t), self.generic_rank)
        self.samples = [self.samples[-1], (t, ratio)]
        if ratio >= APPROACH_RTOL:
            return None
        names = self.model.constraint_names
        return SingularPassage(t=t, t_enter=t, t_exit=t, q=q.copy(), ratio=ratio, constraints=(names[row],))

    def max_step(self) -> float:
        """The largest next step (inf: no limit)."""
        (t0, ratio0), (t1, ratio1) = self.samples[0], self.samples[-1]
        rate = (ratio0 - ratio1) / (t1 - t0) if t1 > t0 else 0.0
        return 0.5 * ratio1 / rate if rate > 0 else np.inf


def _approach_text(t: float, q: np.ndarray) -> str:
    return f"Stopped at t = {t:.6g}, q = {np.array2string(q, precision=6)}: {Result.APPROACH.value}"


def _march(make_stepper: Callable[[], _Stepper], problem: MultibodyProblem, options: SolverOptions) -> Solution:
    """Start ``make_stepper()`` and advance it to ``problem.t1``, collecting the outputs.

    Outputs are every accepted step (``t_eval is None``) or ``problem.t_eval``
    (interpolated inside each step).  A model failure, an integrator failure,
    ``options.max_steps`` steps or the approach to a singular configuration
    (:class:`_ApproachWatch`) end the loop with status -1.
    """
    every_step = problem.t_eval is None
    outputs = [] if every_step else [float(t) for t in problem.t_eval]
    times: list[float] = []
    states: list[np.ndarray] = []
    pending = 0
    while pending < len(outputs) and outputs[pending] <= problem.t0:
        pending += 1
    initial = 1 if every_step else pending  # outputs at t0 are the initial state
    times += [problem.t0] * initial
    states += [problem.y0] * initial
    steps, result, message, events = 0, Result.SUCCESS, _SUCCESS, ()
    stepper = None
    try:
        watch = _ApproachWatch(problem)
        stepper = make_stepper()
        while stepper.t < problem.t1:
            if steps >= options.max_steps:
                result, message = Result.MAX_STEPS, (f"Integration stopped at t = {stepper.t:.6g}: "
                                                     f"{Result.MAX_STEPS.value} ({options.max_steps})")
                break
            stepper.limit_step(min(options.max_step, watch.max_step()))
            failure = stepper.step()
            if failure is not None:
                result, message = Result.SOLVER_FAILED, f"Integration failed at t = {stepper.t:.6g}: {failure}"
                break
            steps += 1
            if every_step:
                times.append(stepper.t)
                states.append(stepper.y)
            while pending < len(outputs) and outputs[pending] <= stepper.t:
                state = stepper.interpolate(outputs[pending])  # first: it may fail
                times.append(outputs[pending])
                states.append(state)
                pending += 1
            if options.progress is not None:
                options.progress(stepper.t)
            approach = watch.observe(stepper.t, stepper.y)
            if approach is not None:
                result, message, events = Result.APPROACH, _approach_text(stepper.t, approach.q), (approach,)
                break
    except _FAILURES as error:
        where = stepper.t if stepper is not None else problem.t0
        result = Result.SINGULAR if isinstance(error, SingularConfigurationError) else Result.SOLVER_FAILED
        message = f"Integration failed at t = {where:.6g}: {type(error).__name__}: {error}"
    nfev, njev = stepper.counters() if stepper is not None else (0, 0)
    return Solution(t=np.asarray(times, dtype=float), y=np.reshape(states, (len(states), 2 * problem.m)),
                    status=result.status, message=message, nfev=nfev, njev=njev, steps=steps, events=events,
                    result=result)


class _ScipyStepper(_Stepper):
    """scipy's DOP853 on ``y' = problem.rhs(t, y)``; with ``project``, the state is
    projected onto the constraints after every accepted step (and at outputs)."""

    def __init__(self, problem: MultibodyProblem, options: SolverOptions, project: bool):
        self.problem, self.options, self.project = problem, options, project
        self.solver = DOP853(problem.rhs, problem.t0, problem.y0, problem.t1, rtol=options.rtol,
                             atol=options.atol, max_step=options.max_step)
        self.interpolant = None  # of the last step, built on the first output inside it

    @property
    def t(self) -> float:
        return self.solver.t

    @property
    def y(self) -> np.ndarray:
        return self.solver.y

    def step(self) -> str | None:
        solver = self.solver
        failure = solver.step()
        self.interpolant = None
        if solver.status == "failed":
            return failure
        if self.project:
            # The next step starts from the projected state; its first stage
            # (FSAL) is re-evaluated there, and the step's interpolant joins the
            # projected end points.
            solver.y = self.problem.project(solver.t, solver.y, self.options.projection_tol)
            solver.f = solver.fun(solver.t, solver.y)
        return None

    def interpolate(self, t: float) -> np.ndarray:
        if self.interpolant is None:
            self.interpolant = self.solver.dense_output()
        y = self.interpolant(t)
        return self.problem.project(t, y, self.options.projection_tol) if self.project else y

    def counters(self) -> tuple[int, int]:
        return self.solver.nfev, self.solver.njev

    def limit_step(self, max_step: float) -> None:
        self.solver.max_step = max_step
        self.solver.h_abs = min(self.solver.h_abs, max_step)


class BaumgarteSolver(Solver):
    """Acceleration-level index-1 ODE with Baumgarte stabilization, by DOP853.

    Integrates ``y = [q, qd]``, ``y' = [qd, qdd]`` with ``qdd`` from
    ``Phi_q qdd = gamma - 2 alpha Phi_q qd - beta^2 Phi`` and
    ``A qdd = gamma_nh - alpha (A qd + b)`` (:meth:`MultibodyProblem.rhs`): the
    constraint violations obey ``e'' + 2 alpha e' + beta^2 e = 0`` and decay
    instead of growing, but are not removed.

    DOP853 was chosen by measurement (four-bar, 10 s, rtol 1e-8, atol 1e-10,
    alpha = beta = 10): it alone kept the drift below 1e-9 (LSODA 4e-9, CVODE
    Adams 1e-8, BDF 3e-8) with the smallest error in ``q`` (1e-7; LSODA 1e-6,
    CVODE 6e-6 to 1e-5), at 1.5 times the run time of LSODA or CVODE.
    """

    name = "baumgarte"
    formulation = "index-1 ODE, Baumgarte stabilization"
    stabilization = 10.0
    order = "8 (Dormand-Prince 8(5,3), scipy DOP853)"

    def solve(self, problem: MultibodyProblem) -> Solution:
        return _march(lambda: _ScipyStepper(problem, self.options, project=False), problem, self.options)


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
    order = "8 (Dormand-Prince 8(5,3), scipy DOP853)"

    def solve(self, problem: MultibodyProblem) -> Solution:
        return _march(lambda: _ScipyStepper(problem, self.options, project=True), problem, self.options)


class _IDAStepper(_Stepper):
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
                          max_num_steps=options.max_steps + 1)
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
            raise RuntimeError(f"IDA could not interpolate at t = {t!r}: {result.message}")
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
    order = "1-5 (variable-order BDF, SUNDIALS IDA)"

    def solve(self, problem: MultibodyProblem) -> Solution:
        return _march(lambda: _IDAStepper(problem, self.options), problem, self.options)


# -- compiled methods: CVODE, ALI3-P and the switch between them, in C ------------------------------

_SUNDIALS_LIBRARIES = ("sundials_core", "sundials_nvecserial", "sundials_sunmatrixdense",
                       "sundials_sunlinsoldense", "sundials_cvode")
_PROGRESS = ctypes.CFUNCTYPE(None, ctypes.c_double)
#: Most singular passages stored per run segment (more are counted).
_MAX_EVENTS = 1000
#: Most rows allocated for outputs at every step (``t_eval`` None): a longer run needs ``t_eval``.
_MAX_STEP_ROWS = 1_000_000


def _load_sundials() -> None:
    """Load the SUNDIALS shared libraries of the scikit-sundae wheel (``scikit_sundae.libs``)
    with global symbols, so that the driver library resolves its SUNDIALS calls against them."""
    import sksundae

    directory = Path(sksundae.__file__).resolve().parent.parent / "scikit_sundae.libs"
    for name in _SUNDIALS_LIBRARIES:
        matches = sorted(directory.glob(f"lib{name}-*.so*")) or sorted(directory.glob(f"lib{name}.so*"))
        if not matches:
            raise RuntimeError(f"the compiled method needs lib{name} from scikit-sundae, not found in {directory}")
        ctypes.CDLL(str(matches[0]), mode=ctypes.RTLD_GLOBAL)


@lru_cache(maxsize=None)
def _driver_library(source: str) -> ctypes.CDLL:
    """``source`` (a model's C source with kernels and a driver appended) compiled once (cached on
    disk by :func:`codegen.compile_shared_library`, keyed by a hash of the source) and loaded."""
    return ctypes.CDLL(str(codegen.compile_shared_library(source)))


#: The drivers of the compiled methods: the kernels each appends to ``model.c_source`` (after the
#: monitor), its C file, its entry point and the argument types of the entry point.
_P, _D, _I, _L = ctypes.c_void_p, ctypes.c_double, ctypes.c_int, ctypes.c_long
_DRIVERS = {
    "cvode": (("potential_energy", "Phi_q"), "cvode.c", "kronlag_cvode",
              [_P, _D, _D, _P, _I, _P, _D, _D, _D, _D, _D, _L, _I, _P, _P, _P, _P, _P, _I, _P, _P, _P, _PROGRESS]),
    "index3": (("tangent", "potential_energy"), "index3.c", "kronlag_index3",
               [_P, _I, _D, _D, _P, _P, _P, _I, _P, _D, _D, _D, _D, _L, _I, _I] + [_P] * 10
               + [_I, _P, _P, _P, _PROGRESS]),
}
#: Loaded driver libraries per model (a model's are built once, on first use).
_LOADED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _driver(model: NumericModel, kind: str) -> ctypes.CDLL:
    """The shared library of ``model`` with the driver ``kind`` of :data:`_DRIVERS`."""
    libraries = _LOADED.setdefault(model, {})
    if kind not in libraries:
        kernels, file, entry, argtypes = _DRIVERS[kind]
        if kind == "cvode":
            _load_sundials()
        library = _driver_library(model.c_source + model.c_kernels(*kernels) + codegen.c_file("monitor.c")
                                  + codegen.c_file(file))
        function = getattr(library, entry)
        function.argtypes, function.restype = argtypes, ctypes.c_int
        if kind == "cvode":
            library.kronlag_outputs.argtypes = [_P, _I] + [_P] * 9
            library.kronlag_outputs.restype = None
            library.kronlag_cvode_flag_name.argtypes = [_I]
            library.kronlag_cvode_flag_name.restype = ctypes.c_char_p
        libraries[kind] = library
    return libraries[kind]


def _passage(model: NumericModel, record: np.ndarray) -> SingularPassage:
    """A :class:`SingularPassage` from a record ``[t_enter, t_exit, t, ratio, row, q (m)]`` of
    ``src/kronlag/c/monitor.c``; the constraints involved are read off the left singular vector of
    ``Phi_q`` that belongs to the singular value that (nearly) vanished, the one at the start's rank."""
    t_enter, t_exit, t, ratio, row = record[:5]
    q = np.array(record[5:5 + model.m])
    names = model.constraint_names
    U, S, _ = np.linalg.svd(model.Phi_q(q, t))
    # the smallest singular value above the rank tolerance is the one that (nearly) vanishes
    direction = np.abs(U[:, max(numerical_rank(S, model.rank_rtol), 1) - 1])
    involved = tuple(names[i] for i in np.flatnonzero(direction >= 0.1 * direction.max()))
    return SingularPassage(t=float(t), t_enter=float(t_enter), t_exit=float(t_exit), q=q, ratio=float(ratio),
                           constraints=involved or (names[int(row)],))


@dataclass(eq=False)
class _Segment:
    """What one call of a compiled driver produced: outputs, counters, events and where it ended
    (``flag``: 0 at ``t1``, positive for a hand-over, negative for a failure)."""

    t: np.ndarray
    y: np.ndarray
    derived: dict[str, np.ndarray]
    events: tuple[SingularPassage, ...]
    flag: int
    t_end: float
    y_end: np.ndarray
    steps: int
    nfev: int
    njev: int

    def without_first_row(self) -> _Segment:
        """The segment without its first output (the hand-over state, already output)."""
        return replace(self, t=self.t[1:], y=self.y[1:], derived={key: value[1:] for key, value in self.derived.items()})


def _output_rows(problem: MultibodyProblem, t0: float, options: SolverOptions) -> tuple[np.ndarray, int]:
    """The output times left after ``t0`` (``t_eval`` strictly after it, or an empty array for
    every step) and the number of rows to allocate."""
    if problem.t_eval is None:
        return np.empty(0), min(options.max_steps + 1, _MAX_STEP_ROWS)
    times = np.ascontiguousarray(problem.t_eval[problem.t_eval > t0] if t0 > problem.t0 else problem.t_eval)
    return times, len(times)


def _cvode_segment(problem: MultibodyProblem, options: SolverOptions, t0: float, y0: np.ndarray) -> _Segment:
    """CVODE (Adams) on the Baumgarte ODE from ``(t0, y0)`` until ``t1`` or the approach to a
    singular configuration (``flag`` 2)."""
    model = problem.model
    library = _driver(model, "cvode")
    times, rows = _output_rows(problem, t0, options)
    t_out, y_out = np.empty(rows), np.empty((rows, 2 * problem.m))
    written, event_count, t_end = ctypes.c_int(0), ctypes.c_int(0), ctypes.c_double(t0)
    stats, events, y_end = np.zeros(4, dtype=np.int64), np.empty((_MAX_EVENTS, 5 + model.m)), np.empty(2 * model.m)
    p, y0 = model.parameter_vector(t0), np.ascontiguousarray(y0, dtype=float)
    callback = _PROGRESS(options.progress) if options.progress is not None else _PROGRESS()
    flag = library.kronlag_cvode(
        p.ctypes.data, t0, problem.t1, y0.ctypes.data, len(times), times.ctypes.data,
        options.rtol / CompiledSolver.TOLERANCE_SCALE, options.atol / CompiledSolver.TOLERANCE_SCALE, problem.alpha,
        problem.beta, options.max_step if np.isfinite(options.max_step) else 0.0, options.max_steps, len(t_out),
        t_out.ctypes.data, y_out.ctypes.data, ctypes.byref(written), stats.ctypes.data, events.ctypes.data,
        _MAX_EVENTS, ctypes.byref(event_count), ctypes.byref(t_end), y_end.ctypes.data, callback)
    n = written.value
    t_out, y_out = t_out[:n].copy(), y_out[:n].copy()
    derived = {"qdd": np.empty((n, model.m)), "lam": np.empty((n, model.r)), "mu": np.empty((n, model.s)),
               "kinetic_energy": np.empty(n), "potential_energy": np.empty(n),
               "position_residual": np.empty((n, model.r)), "velocity_residual": np.empty((n, model.r + model.s))}
    library.kronlag_outputs(p.ctypes.data, n, t_out.ctypes.data, y_out.ctypes.data,
                            *(derived[key].ctypes.data for key in derived))
    passages = tuple(_passage(model, record) for record in events[:min(event_count.value, _MAX_EVENTS)])
    return _Segment(t=t_out, y=y_out, derived=derived, events=passages, flag=flag, t_end=t_end.value, y_end=y_end,
                    steps=int(stats[0]), nfev=int(stats[1]), njev=int(stats[2]))


def _index3_segment(problem: MultibodyProblem, options: SolverOptions, t0: float, y0: np.ndarray,
                    handback: bool) -> _Segment:
    """ALI3-P from the consistent state ``(t0, y0)`` until ``t1`` or, with ``handback``, until the
    motion has left the neighbourhood of a singular configuration (``flag`` 1)."""
    model, m, r = problem.model, problem.m, problem.model.r
    library = _driver(model, "index3")
    q0, qd0 = y0[:m], y0[m:]
    try:
        start = model.forward_dynamics(q0, qd0, t0)
    except SingularConfigurationError:
        # exactly at a singular configuration: the least-squares accelerations of the
        # augmented Lagrangian start (the first step's Newton iteration corrects them)
        start = None
    a0 = np.zeros(m) if start is None else start.qdd
    lam0 = np.zeros(r) if start is None else start.lam
    times, rows = _output_rows(problem, t0, options)
    t_out, y_out = np.empty(rows), np.empty((rows, 2 * m))
    qdd, lam = np.empty((rows, m)), np.empty((rows, r))
    energies, phi, velocity = np.empty((rows, 2)), np.empty((rows, r)), np.empty((rows, r))
    events, y_end = np.empty((_MAX_EVENTS, 5 + m)), np.empty(2 * m)
    written, event_count, t_end = ctypes.c_int(0), ctypes.c_int(0), ctypes.c_double(t0)
    stats = np.zeros(4, dtype=np.int64)
    callback = _PROGRESS(options.progress) if options.progress is not None else _PROGRESS()
    p = model.parameter_vector(t0)
    y0, a0, lam0 = (np.ascontiguousarray(x, dtype=float) for x in (y0, a0, lam0))
    flag = library.kronlag_index3(
        p.ctypes.data, len(p), t0, problem.t1, y0.ctypes.data, a0.ctypes.data, lam0.ctypes.data, len(times),
        times.ctypes.data, options.rtol / Index3Solver.TOLERANCE_SCALE, options.atol,
        0.0, options.max_step if np.isfinite(options.max_step) else 0.0,
        options.max_steps, rows, int(handback), t_out.ctypes.data, y_out.ctypes.data, qdd.ctypes.data,
        lam.ctypes.data, energies.ctypes.data, phi.ctypes.data, velocity.ctypes.data, ctypes.byref(written),
        stats.ctypes.data, events.ctypes.data, _MAX_EVENTS, ctypes.byref(event_count), ctypes.byref(t_end),
        y_end.ctypes.data, callback)
    n = written.value
    derived = {"qdd": qdd[:n].copy(), "lam": lam[:n].copy(), "mu": np.empty((n, 0)),
               "kinetic_energy": energies[:n, 0].copy(), "potential_energy": energies[:n, 1].copy(),
               "position_residual": phi[:n].copy(), "velocity_residual": velocity[:n].copy()}
    passages = tuple(_passage(model, record) for record in events[:min(event_count.value, _MAX_EVENTS)])
    return _Segment(t=t_out[:n].copy(), y=y_out[:n].copy(), derived=derived, events=passages, flag=flag,
                    t_end=t_end.value, y_end=y_end, steps=int(stats[0]), nfev=int(stats[2]), njev=int(stats[3]))


#: The flags of the C drivers (``src/kronlag/c/cvode.c``, ``index3.c``) that are not CVODE's own:
#: what each means.
_DRIVER_RESULTS = {
    "cvode": {-1: Result.MAX_STEPS, 2: Result.APPROACH, -1002: Result.PROJECTION_FAILED,
              -1003: Result.SINGULAR, -1004: Result.OUTPUTS_FULL},
    "index3": {-1: Result.MAX_STEPS, -2: Result.STEP_TOO_SMALL, -3: Result.NEWTON_FAILED,
               -6: Result.SINGULAR, -7: Result.OUTPUTS_FULL},
}



def _segment_status(segment: _Segment, model: NumericModel, kind: str) -> tuple[Result, str]:
    """The :class:`Result` of a driver's ``segment`` and the message: ``Integration failed at t = ...,
    q = ...: reason[; the last singular passage]``."""
    if segment.flag == 0:
        return Result.SUCCESS, _SUCCESS
    q = segment.y_end[:model.m]
    result = _DRIVER_RESULTS[kind].get(segment.flag, Result.SOLVER_FAILED)
    if result is Result.APPROACH:
        return result, _approach_text(segment.t_end, q)
    reason = result.value
    if result is Result.SOLVER_FAILED:
        reason = f"CVODE {_driver(model, 'cvode').kronlag_cvode_flag_name(segment.flag).decode()} ({segment.flag})"
    message = f"Integration failed at t = {segment.t_end:.6g}, q = {np.array2string(q, precision=6)}: {reason}"
    return result, message + (f"; last passage: {segment.events[-1]}" if segment.events else "")


def _solution(segments: Sequence[_Segment], result: Result, message: str) -> Solution:
    """The :class:`Solution` of consecutive segments."""
    derived = {key: np.concatenate([segment.derived[key] for segment in segments]) for key in segments[0].derived}
    return Solution(t=np.concatenate([segment.t for segment in segments]),
                    y=np.concatenate([segment.y for segment in segments]), status=result.status, message=message,
                    nfev=sum(segment.nfev for segment in segments), njev=sum(segment.njev for segment in segments),
                    steps=sum(segment.steps for segment in segments), derived=derived,
                    events=tuple(event for segment in segments for event in segment.events), result=result)


class CompiledSolver(Solver):
    """The Baumgarte index-1 ODE integrated entirely in compiled code, outputs projected.

    The model's C source (``model.c_source``) and a small SUNDIALS driver
    (``src/kronlag/c/cvode.c``) are compiled once per model into a shared library
    (cached by hash) that calls the CVODE libraries of scikit-sundae.  CVODE
    (variable-order Adams-Moulton, Newton iteration with a dense
    difference-quotient Jacobian) integrates the Baumgarte-stabilized
    ``y = [q, qd]``, ``y' = [qd, qdd]`` of :class:`BaumgarteSolver`; every
    output is projected onto the constraints (least-norm corrections over the
    independent rows, :mod:`kronlag.tolerances`).  Python is called only at the
    start and the end (and for ``progress``); the accelerations, multipliers,
    energies and residuals at the outputs are computed in C too.  Needs the C
    backend and constant parameters.

    At the approach to a singular configuration (:data:`kronlag.tolerances.APPROACH_RTOL`)
    an index-1 formulation cannot tell the branches of the motion apart (IFToMM A02): the
    integration ends there with status -1 and a message naming the configuration;
    :class:`SwitchingSolver` (the default) passes it with ALI3-P.

    CVODE bounds a weighted RMS norm of the local error of a multistep method,
    and its global error at a given ``rtol`` is far larger than DOP853's
    (four-bar, 10 s, rtol 1e-8: 1.4e-4 against 4.7e-6 in q).  CVODE is
    therefore called with ``rtol / TOLERANCE_SCALE`` and ``atol /
    TOLERANCE_SCALE``; then its error (2.3e-6) is below that of the DOP853
    methods at the requested tolerance, and the drift of the unprojected state
    stays below 1e-9 (3e-10) with the default ``alpha = beta = 10``.
    """

    name = "compiled"
    formulation = "index-1 ODE with Baumgarte stabilization, compiled; outputs projected"
    stabilization = 10.0
    order = "1-12 (variable-order Adams-Moulton, SUNDIALS CVODE)"
    requirements = "the C backend, constant parameters and a C compiler"
    #: CVODE's tolerances are the requested ones divided by this (see above).
    TOLERANCE_SCALE = 100.0

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """Whether ``model`` can run compiled: C backend, no time-varying parameter."""
        return model.backend == "c" and not model.time_varying and codegen.c_compiler() is not None

    def solve(self, problem: MultibodyProblem) -> Solution:
        _require(self, problem.model)
        segment = _cvode_segment(problem, self.options, problem.t0, problem.y0)
        if segment.flag == 2:  # the approach is an event too
            approach = _ApproachWatch(problem).observe(segment.t_end, segment.y_end)
            segment = replace(segment, events=segment.events + ((approach,) if approach else ()))
        return _solution([segment], *_segment_status(segment, problem.model, "cvode"))


def _require(solver: Solver, model: NumericModel) -> None:
    if not solver.supports(model):
        raise ValueError(f"method={solver.name!r} cannot run this model: {solver.requirements}")


class Index3Solver(Solver):
    """Index-3 augmented Lagrangian with mass-orthogonal projections (ALI3-P), compiled.

    Integrates ``M qdd + C qd + g - f_Q + Phi_q^T lambda = 0``, ``Phi(q) = 0`` in
    positions with the trapezoidal rule: Newton's method on ``q`` with the exact
    tangent matrix ``J = M + h/2 D + h^2/4 (K + alpha Phi_q^T Phi_q)`` (``K``, ``D``
    generated symbolically: the ``"tangent"`` kernel of :mod:`kronlag.codegen`),
    the augmented Lagrangian update ``lambda* <- lambda* + alpha Phi`` and
    projections of the velocities and accelerations in the metric of ``J`` (see
    ``src/kronlag/c/index3.c``).  No rank decision enters a step: ``J`` stays
    positive definite where ``Phi_q`` loses rank, so the method passes singular
    configurations on the branch it is on (IFToMM A02) and integrates
    mechanisms with redundant constraints (IFToMM A04).  It does not detect a
    branch switch by itself: that it keeps the branch is checked by the tests
    (the cranks of A02 stay parallel from rtol 1e-2 to 1e-8).  The local error
    ``h^2/12 (qdd_{n+1} - qdd_n)`` in ``q`` is kept below ``atol + rtol |q|``;
    outputs at ``t_eval`` are interpolated (cubic Hermite).  Second order: for
    tight tolerances on long runs :class:`SwitchingSolver` is much faster.
    """

    name = "ali3p"
    formulation = "index-3 augmented Lagrangian, mass-orthogonal projections (ALI3-P), compiled"
    order = "2 (trapezoidal rule), local error control"
    requirements = "the C backend, constant parameters, no nonholonomic constraints and a C compiler"
    #: The driver's relative tolerance is the requested one divided by this (``atol`` is kept),
    #: so that the global error at a given ``rtol`` is of the size the other methods give: the
    #: local error of a second-order method accumulates over ~1e4 steps (IFToMM A02 at rtol
    #: 1e-8: B0 within 1e-5 m for N = 2, 4, 8 with 3000; 1e-4 with 100).
    TOLERANCE_SCALE = 3000.0

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """C backend, constant parameters, no nonholonomic constraints, a C compiler."""
        return CompiledSolver.supports(model) and model.s == 0

    def solve(self, problem: MultibodyProblem) -> Solution:
        _require(self, problem.model)
        segment = _index3_segment(problem, self.options, problem.t0, problem.y0, handback=False)
        return _solution([segment], *_segment_status(segment, problem.model, "index3"))


class SwitchingSolver(Solver):
    """CVODE (:class:`CompiledSolver`) away from singular configurations, ALI3-P
    (:class:`Index3Solver`) through them; the default.

    The fast high-order method integrates while ``Phi_q`` is well conditioned; at
    the approach to a singular configuration (:data:`kronlag.tolerances.APPROACH_RTOL`)
    the index-3 method takes over from the projected state and passes it on the
    branch the motion is on; once the motion is clear of it
    (:data:`~kronlag.tolerances.LEAVE_RTOL`) CVODE continues.  A model whose
    constraints are redundant at the start (``Phi_q`` rank deficient) is integrated
    by ALI3-P throughout.  Smooth problems cost what :class:`CompiledSolver` costs.
    """

    name = "switching"
    formulation = "CVODE on the Baumgarte ODE; ALI3-P near singular configurations (both compiled)"
    order = "1-12 (Adams-Moulton) away from singular configurations, 2 (trapezoidal) near them"
    requirements = Index3Solver.requirements
    supports = staticmethod(Index3Solver.supports)
    stabilization = CompiledSolver.stabilization

    def solve(self, problem: MultibodyProblem) -> Solution:
        _require(self, problem.model)
        model, options = problem.model, self.options
        redundant = model.r and numerical_rank(np.linalg.svd(model.Phi_q(problem.q0, problem.t0),
                                                             compute_uv=False), model.rank_rtol) < model.r
        segments: list[_Segment] = []
        t, y, index3 = problem.t0, problem.y0, bool(redundant)
        while True:
            steps_left = options.max_steps - sum(segment.steps for segment in segments)
            budget = replace(options, max_steps=max(steps_left, 0))
            if index3:
                segment = _index3_segment(problem, budget, t, y, handback=not redundant)
            else:
                segment = _cvode_segment(problem, budget, t, y)
            segments.append(segment.without_first_row() if segments and problem.t_eval is None else segment)
            if segment.flag <= 0:
                return _solution(segments, *_segment_status(segment, model, "index3" if index3 else "cvode"))
            t, y, index3 = segment.t_end, segment.y_end, not index3


#: Methods by name (``"auto"`` picks among them in :func:`simulate`).
METHODS: dict[str, type[Solver]] = {
    BaumgarteSolver.name: BaumgarteSolver,
    ProjectionSolver.name: ProjectionSolver,
    GGLSolver.name: GGLSolver,
    CompiledSolver.name: CompiledSolver,
    Index3Solver.name: Index3Solver,
    SwitchingSolver.name: SwitchingSolver,
}


#: What ``method="auto"`` picks: the first of these that supports the model.
AUTO_PREFERENCE = (SwitchingSolver.name, CompiledSolver.name, ProjectionSolver.name)


def _output_times(t_eval: Sequence[float] | np.ndarray | None, t0: float, t1: float) -> np.ndarray | None:
    if t_eval is None:
        return None
    times = np.asarray(t_eval, dtype=float).ravel()
    if times.size == 0:
        raise ValueError("t_eval is empty: give at least one output time (or None for every step)")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0) or times[0] < t0 or times[-1] > t1:
        raise ValueError(f"t_eval must increase strictly and lie in t_span = [{t0}, {t1}]")
    return times


def _derived(model: NumericModel, times: np.ndarray, states: np.ndarray) -> dict[str, np.ndarray]:
    """The :attr:`Solution.derived` arrays at ``states`` (N, 2 m), by the model's Python interface
    (NaN accelerations and multipliers where the configuration is singular)."""
    m, r, s = model.m, model.r, model.s
    n = len(times)
    derived = {"qdd": np.full((n, m), np.nan), "lam": np.full((n, r), np.nan), "mu": np.full((n, s), np.nan),
               "kinetic_energy": np.empty(n), "position_residual": np.empty((n, r)),
               "velocity_residual": np.empty((n, r + s))}
    for k, (t, y) in enumerate(zip(times, states)):
        q, qd = y[:m], y[m:]
        with suppress(SingularConfigurationError):  # the state a failed integration ended in
            result = model.forward_dynamics(q, qd, t)
            derived["qdd"][k], derived["lam"][k], derived["mu"][k] = result.qdd, result.lam, result.mu
        terms = model.dynamics_terms(q, qd, t)
        derived["kinetic_energy"][k] = 0.5 * qd @ terms["M"] @ qd
        derived["position_residual"][k] = terms["Phi"]
        B, c = velocity_constraints(terms)
        derived["velocity_residual"][k] = B @ qd + c
    return derived


def _trajectory(solution: Solution, problem: MultibodyProblem, method: str, started: float) -> Trajectory:
    """The :class:`Trajectory` of ``solution``, with the derived quantities at its output times."""
    model, m = problem.model, problem.m
    derived = dict(solution.derived if solution.derived is not None else _derived(model, solution.t, solution.y))
    if "potential_energy" not in derived:
        derived["potential_energy"] = np.array([model.potential_energy(y[:m], t)
                                                for t, y in zip(solution.t, solution.y)])
    return Trajectory(t=solution.t, q=solution.y[:, :m], qd=solution.y[:, m:], **derived,
                      coordinate_names=tuple(model.coordinate_names), model=model,
                      method=method, status=solution.status, message=solution.message, nfev=solution.nfev,
                      njev=solution.njev, steps=solution.steps, wall_time=time.perf_counter() - started,
                      events=solution.events, result=solution.result)


def simulate(model: NumericModel, t_span: tuple[float, float], q0, qd0, *, method: str = "auto",
             rtol: float = 1e-8, atol: float = 1e-10, t_eval=None, alpha: float | None = None,
             beta: float | None = None, max_step: float | None = None, max_steps: int | None = None,
             progress: Callable[[float], object] | None = None) -> Trajectory:
    r"""Integrate the equations of motion of ``model`` over ``t_span``.

    The model is the differential-algebraic system (Van Khang 2011, Eq. 23)::

        M(q) qdd + C(q, qd) qd + Phi_q^T lam + A^T mu + g(q) = f_Q
        Phi(q) = 0,   A(q) qd + b(q) = 0

    with m coordinates ``q``, r holonomic and s nonholonomic constraints.

    Parameters
    ----------
    model : NumericModel
        From ``eom.numeric(parameters)``.
    t_span : (t0, t1)
        Time interval, ``t1 > t0``.
    q0, qd0 : array_like, shape (m,)
        Initial coordinates and velocities.  They should satisfy the
        constraints (``model.assemble`` finds such values); they are projected
        onto ``Phi(q, t0) = 0``, ``Phi_q qd + Phi_t = 0``, ``A qd + b = 0`` before starting.
    method : {'auto', 'switching', 'ali3p', 'compiled', 'baumgarte', 'projection', 'ggl'}
        Formulation and integrator:

        ``'switching'``
            ``'compiled'`` away from singular configurations, ``'ali3p'``
            through them (and throughout when the constraints are redundant at
            the start) (:class:`SwitchingSolver`);
        ``'ali3p'``
            index-3 augmented Lagrangian with mass-orthogonal projections,
            trapezoidal rule, compiled (:class:`Index3Solver`): passes singular
            configurations and handles redundant constraints;

        ``'baumgarte'``
            index-1 ODE ``[q, qd]' = [qd, qdd]`` with ``qdd`` from
            ``model.forward_dynamics(q, qd, t, alpha=alpha, beta=beta)``
            (constraint violations obey ``e'' + 2 alpha e' + beta^2 e = 0``),
            scipy's DOP853 (:class:`BaumgarteSolver`);
        ``'projection'``
            the same ODE without stabilization, projected onto the constraint
            manifold after every accepted DOP853 step (:class:`ProjectionSolver`);
        ``'ggl'``
            stabilized index-2 Gear-Gupta-Leimkuhler DAE by SUNDIALS IDA
            (:class:`GGLSolver`);
        ``'compiled'``
            the Baumgarte ODE by SUNDIALS CVODE (Adams) in compiled code,
            outputs projected (:class:`CompiledSolver`; needs a model with the
            C backend and no time-varying parameter);
        ``'auto'``
            the first of :data:`AUTO_PREFERENCE` (``'switching'``,
            ``'compiled'``, ``'projection'``) that the model allows.

        The index-1 methods stop with status -1 at the approach to a singular
        configuration, where they cannot tell the branches of the motion apart.
    rtol, atol : float
        Relative and absolute local error tolerances.
    t_eval : array_like, shape (K,), optional
        Increasing output times within ``t_span``; by default every accepted step.
    alpha, beta : float, optional
        Baumgarte parameters (units 1/time).  Default: the method's
        ``stabilization`` (10 for ``'baumgarte'``, ``'compiled'`` and the CVODE
        part of ``'switching'``, 0 for ``'projection'``, which removes the drift);
        unused by ``'ggl'`` and ``'ali3p'``.
    max_step : float, optional
        Largest step size (unbounded by default).
    max_steps : int, optional
        Most accepted steps; reaching it ends the integration with status -1.  By
        default 1000 per unit of simulated time, at least 100 000.
    progress : callable, optional
        Called as ``progress(t)`` after every accepted step.

    Returns
    -------
    Trajectory
        ``t`` (N,), ``q``, ``qd``, ``qdd`` (N, m), ``lam`` (N, r), ``mu`` (N, s),
        energies, residuals ``Phi(q)`` (N, r) and ``[Phi_q qd; A qd + b]``
        (N, r + s), counters, wall time and ``events`` (the singular
        configurations passed).  On failure (a singular
        configuration, an integrator error, ``max_steps``) ``status`` is -1,
        ``message`` says why, and the arrays hold the solution up to the failure.

    Examples
    --------
    >>> model = kronlag.derive(kronlag.models.four_bar()).numeric(parameters)  # doctest: +SKIP
    >>> q0, qd0 = model.assemble([0.5, 1.0, 2.0], fixed={"q1": 0.5})          # doctest: +SKIP
    >>> trajectory = kronlag.simulate(model, (0, 10), q0, qd0)                # doctest: +SKIP
    """
    started = time.perf_counter()
    t0, t1 = (float(value) for value in t_span)
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise ValueError(f"t_span must be finite with t1 > t0, got {t_span!r}")
    for label, value in (("rtol", rtol), ("atol", atol)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{label} must be a positive number, got {value!r}")
    if max_step is not None and not float(max_step) > 0:
        raise ValueError(f"max_step must be positive, got {max_step!r}")
    span_steps = max(100_000, int(np.ceil(_STEPS_PER_TIME * (t1 - t0))))
    if max_steps is None:
        max_steps = span_steps
    if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 1):
        raise ValueError(f"max_steps must be an integer >= 1, got {max_steps!r}")
    name = _resolve_method(method, model)
    default_stabilization = METHODS[name].stabilization
    options = SolverOptions(rtol=rtol, atol=atol, max_step=np.inf if max_step is None else float(max_step),
                            max_steps=int(max_steps), progress=progress)
    start = MultibodyProblem(model=model, t0=t0, t1=t1, q0=np.asarray(q0, dtype=float).ravel(),
                             qd0=np.asarray(qd0, dtype=float).ravel(), t_eval=_output_times(t_eval, t0, t1),
                             alpha=default_stabilization if alpha is None else float(alpha),
                             beta=default_stabilization if beta is None else float(beta))
    for label, value in (("q0", start.q0), ("qd0", start.qd0)):
        if value.shape != (model.m,):
            raise ValueError(f"{label} must have {model.m} entries ({', '.join(model.coordinate_names)}), "
                             f"got {value.size}")
        bad = [model.coordinate_names[i] for i in np.flatnonzero(~np.isfinite(value))]
        if bad:
            raise ValueError(f"{label} is not finite for {', '.join(bad)}")
    problem = replace(start, **dict(zip(("q0", "qd0"), _consistent_start(start, options))))
    solution = METHODS[name](options).solve(problem)
    return _trajectory(solution, problem, name, started)


#: The default ``max_steps``: this many per unit of simulated time, at least 100 000.
_STEPS_PER_TIME = 1000
#: An initial state whose projection onto the constraints moves ``q`` by more than this (relative to
#: ``1 + |q0|``) is refused: the projection may have jumped to another assembly branch.
_MAX_START_CORRECTION = 1e-3
#: Corrections of the initial state below this (relative) are the rounding of its assembly: no warning.
_ROUNDING = 1e-9


class InitialStateWarning(UserWarning):
    """The initial state violated the constraints and was projected onto them."""


def _consistent_start(problem: MultibodyProblem, options: SolverOptions) -> tuple[np.ndarray, np.ndarray]:
    """``(q0, qd0)`` projected onto the constraints; a warning states any correction above ``atol``,
    and a correction of ``q0`` above :data:`_MAX_START_CORRECTION` is an :class:`AssemblyError`."""
    m = problem.m
    y0 = problem.project(problem.t0, problem.y0, options.projection_tol)
    dq, dqd = (float(np.max(np.abs(x), initial=0.0)) for x in (y0[:m] - problem.q0, y0[m:] - problem.qd0))
    scale = 1.0 + float(np.max(np.abs(problem.q0), initial=0.0))
    if dq > _MAX_START_CORRECTION * scale:
        raise AssemblyError(f"the initial state violates the constraints (max |Phi| = "
                            f"{np.max(np.abs(problem.model.Phi(problem.q0, problem.t0)), initial=0.0):.3g}): "
                            f"projecting it would move q by {dq:.3g}, perhaps onto another assembly branch; "
                            "assemble it with model.assemble(q_guess, fixed=...)", dq)
    speed = 1.0 + float(np.max(np.abs(problem.qd0), initial=0.0))
    if dq > max(options.atol, _ROUNDING * scale) or dqd > max(options.atol, _ROUNDING * speed):
        warnings.warn(f"the initial state violated the constraints and was projected onto them: q moved by "
                      f"{dq:.3g}, qd by {dqd:.3g} (max abs)", InitialStateWarning, stacklevel=3)
    return y0[:m], y0[m:]


def _resolve_method(method: str, model: NumericModel) -> str:
    if method == "auto":
        return next(name for name in AUTO_PREFERENCE if METHODS[name].supports(model))
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose from 'auto', {', '.join(map(repr, METHODS))}")
    return method
