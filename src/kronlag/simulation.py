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
from .numeric import SingularConfigurationError
from .trajectory import Trajectory

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
]


class ProjectionError(RuntimeError):
    """The projection onto the constraint manifold did not converge."""


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
        [f_Q - C qd - g; gamma - 2 alpha Phi_q qd - beta^2 Phi; gamma_nh - alpha (A qd + b)]``.
        """
        q, qd = y[:self.m], y[self.m:]
        result = self.model.forward_dynamics(q, qd, t, alpha=self.alpha, beta=self.beta)
        return np.concatenate([qd, result.qdd])

    def project(self, t: float, y: np.ndarray, tol: float) -> np.ndarray:
        """Project ``y = [q, qd]`` onto the constraint manifold, shape (2 m,).

        Positions by Gauss-Newton steps on ``Phi(q) = 0`` (the smallest correction
        in the Euclidean norm), until ``max |Phi| <= tol`` or a step is at rounding
        level (``|dq| <= 1e-15 (1 + |q|)``)::

            q <- q - Phi_q^+ Phi(q)

        then velocities onto ``B qd + c = 0`` with ``B = [Phi_q; A]`` (r + s, m)
        and ``c = [0; b]`` in one step, ``qd <- qd - B^+ (B qd + c)``.  The
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
            step = np.linalg.lstsq(jacobian, terms["Phi"], rcond=None)[0]
            q -= step
            stalled = bool(np.all(np.abs(step) <= _STALL * (1 + np.abs(q))))
            terms = model.dynamics_terms(q, qd, t)
        else:
            raise ProjectionError(f"the position projection did not converge at t = {t!r}: "
                                  f"max |Phi| = {np.max(np.abs(terms['Phi'])):.3g}")
        if model.r + model.s:
            B = np.vstack([terms["Phi_q"], terms["A"]])
            c = np.concatenate([np.zeros(model.r), terms["b"]])
            qd -= np.linalg.lstsq(B, B @ qd + c, rcond=None)[0]
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
        ``position_residual`` (N, r), ``velocity_residual`` (N, r + s) at the
        outputs, when the solver computed them (else :func:`simulate` does).
    """

    t: np.ndarray
    y: np.ndarray
    status: int
    message: str
    nfev: int
    njev: int
    steps: int
    derived: dict[str, np.ndarray] | None = None


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

    Subclasses declare ``name``, ``formulation`` (the equations integrated) and
    ``order`` and implement :meth:`solve`.
    """

    name: ClassVar[str]
    formulation: ClassVar[str]
    order: ClassVar[str]

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


def _march(make_stepper: Callable[[], _Stepper], problem: MultibodyProblem, options: SolverOptions) -> Solution:
    """Start ``make_stepper()`` and advance it to ``problem.t1``, collecting the outputs.

    Outputs are every accepted step (``t_eval is None``) or ``problem.t_eval``
    (interpolated inside each step).  A model failure, an integrator failure or
    ``options.max_steps`` steps end the loop with status -1.
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
    steps, status, message = 0, 0, "The integration reached the end of the time span."
    stepper = None
    try:
        stepper = make_stepper()
        while stepper.t < problem.t1:
            if steps >= options.max_steps:
                status, message = -1, (f"Reached the maximum number of steps ({options.max_steps}) "
                                       f"at t = {stepper.t:.6g}.")
                break
            failure = stepper.step()
            if failure is not None:
                status, message = -1, f"Integration failed at t = {stepper.t:.6g}: {failure}"
                break
            steps += 1
            if every_step:
                times.append(stepper.t)
                states.append(stepper.y)
            while pending < len(outputs) and outputs[pending] <= stepper.t:
                times.append(outputs[pending])
                states.append(stepper.interpolate(outputs[pending]))
                pending += 1
            if options.progress is not None:
                options.progress(stepper.t)
    except _FAILURES as error:
        where = stepper.t if stepper is not None else problem.t0
        status, message = -1, f"Integration failed at t = {where:.6g}: {type(error).__name__}: {error}"
    nfev, njev = stepper.counters() if stepper is not None else (0, 0)
    return Solution(t=np.asarray(times, dtype=float), y=np.reshape(states, (len(states), 2 * problem.m)),
                    status=status, message=message, nfev=nfev, njev=njev, steps=steps)


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
    order = "8 (Dormand-Prince 8(5,3), scipy DOP853)"

    def solve(self, problem: MultibodyProblem) -> Solution:
        return _march(lambda: _ScipyStepper(problem, self.options, project=False), problem, self.options)


class ProjectionSolver(Solver):
    """Index-1 ODE with coordinate projection after every accepted step, by DOP853.

    Each accepted step of the explicit Runge-Kutta method is followed by
    :meth:`MultibodyProblem.project`: Gauss-Newton onto ``Phi(q) = 0``, then the
    velocities onto ``Phi_q qd = 0``, ``A qd + b = 0``.  The method is one-step,
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
        model, m, r, s = problem.model, problem.m, problem.model.r, problem.model.s
        self.m = m
        start = model.forward_dynamics(problem.q0, problem.qd0, problem.t0)
        y0 = np.concatenate([problem.q0, problem.qd0, start.lam, start.mu, np.zeros(r)])
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
        """GGL residual: ``x = [q, v, lam, mu, eta]`` (2 m + 2 r + s,)."""
        model, m = self.problem.model, self.m
        r, s = model.r, model.s
        q, v = x[:m], x[m:2 * m]
        lam, mu, eta = x[2 * m:2 * m + r], x[2 * m + r:2 * m + r + s], x[2 * m + r + s:]
        terms = model.dynamics_terms(q, v, t)  # M, h = f_Q - C v - g, Phi, Phi_q, A, b at (q, v)
        Phi_q, A = terms["Phi_q"], terms["A"]
        res[:m] = xp[:m] - v + Phi_q.T @ eta
        res[m:2 * m] = terms["M"] @ xp[m:2 * m] - terms["h"] + Phi_q.T @ lam + A.T @ mu
        res[2 * m:2 * m + r] = terms["Phi"]
        res[2 * m + r:2 * m + 2 * r] = Phi_q @ v
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
    The residual is evaluated in Python, so this is the slowest method (about
    0.15 s per simulated second of the four-bar at rtol 1e-8).
    """

    name = "ggl"
    formulation = "stabilized index-2 DAE (Gear-Gupta-Leimkuhler)"
    order = "1-5 (variable-order BDF, SUNDIALS IDA)"

    def solve(self, problem: MultibodyProblem) -> Solution:
        return _march(lambda: _IDAStepper(problem, self.options), problem, self.options)


# -- compiled path: SUNDIALS CVODE in C -----------------------------------------------------------

_DRIVER = Path(__file__).with_name("_cvode_driver.c")
_SUNDIALS_LIBRARIES = ("sundials_core", "sundials_nvecserial", "sundials_sunmatrixdense",
                       "sundials_sunlinsoldense", "sundials_cvode")


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
def _cvode_library(model_source: str) -> ctypes.CDLL:
    """``model_source`` + the CVODE driver, compiled once (cached on disk by
    :func:`codegen.compile_shared_library`, keyed by a hash of the source) and loaded."""
    _load_sundials()
    target = codegen.compile_shared_library(model_source + "\n" + _DRIVER.read_text())
    library = ctypes.CDLL(str(target))
    pointer, c_double = ctypes.c_void_p, ctypes.c_double
    library.kronlag_cvode.argtypes = [pointer, c_double, c_double, pointer, ctypes.c_int, pointer,
                                      c_double, c_double, c_double, c_double, c_double, ctypes.c_long,
                                      pointer, pointer, pointer, pointer, _PROGRESS]
    library.kronlag_cvode.restype = ctypes.c_int
    library.kronlag_outputs.argtypes = [pointer, ctypes.c_int] + [pointer] * 8
    library.kronlag_outputs.restype = None
    library.kronlag_cvode_flag_name.argtypes = [ctypes.c_int]
    library.kronlag_cvode_flag_name.restype = ctypes.c_char_p
    return library


_PROGRESS = ctypes.CFUNCTYPE(None, ctypes.c_double)


class CompiledSolver(Solver):
    """The Baumgarte index-1 ODE integrated entirely in compiled code, outputs projected.

    The model's C source (``model.c_source``) and a small SUNDIALS driver
    (``_cvode_driver.c``) are compiled once per model into a shared library
    (cached by hash) that calls the CVODE libraries of scikit-sundae.  CVODE
    (variable-order Adams-Moulton, Newton iteration with a dense
    difference-quotient Jacobian) integrates the Baumgarte-stabilized
    ``y = [q, qd]``, ``y' = [qd, qdd]`` of :class:`BaumgarteSolver`; every
    output is projected onto the constraints by the projection of
    :meth:`MultibodyProblem.project` written in C.  Python is called only at
    the start and the end (and for ``progress``).  Needs the C backend and
    constant parameters.

    CVODE bounds a weighted RMS norm of the local error of a multistep method,
    and its global error at a given ``rtol`` is far larger than DOP853's
    (four-bar, 10 s, rtol 1e-8: 1.4e-4 against 4.7e-6 in q).  CVODE is
    therefore called with ``rtol / TOLERANCE_SCALE`` and ``atol /
    TOLERANCE_SCALE``; then its error (2.3e-6) is below that of the DOP853
    methods at the requested tolerance, and the drift of the unprojected state
    stays below 1e-9 (3e-10) with the default ``alpha = beta = 10``.
    Measured against BDF with CVODE's own projection (``CVodeSetProjFn``,
    BDF only): Adams took fewer steps and was ten times more accurate.
    """

    name = "compiled"
    formulation = "index-1 ODE with Baumgarte stabilization, compiled; outputs projected"
    order = "1-12 (variable-order Adams-Moulton, SUNDIALS CVODE)"
    #: CVODE's tolerances are the requested ones divided by this (see above).
    TOLERANCE_SCALE = 100.0

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """Whether ``model`` can run compiled: C backend, no time-varying parameter."""
        return model.backend == "c" and not model.time_varying and codegen.c_compiler() is not None

    def solve(self, problem: MultibodyProblem) -> Solution:
        model, options = problem.model, self.options
        if not self.supports(model):
            raise ValueError("method='compiled' needs a model with backend='c', constant parameters "
                             "and a C compiler")
        library = _cvode_library(model.c_source)
        t_eval = problem.t_eval
        rows = len(t_eval) if t_eval is not None else options.max_steps + 1
        t_out, y_out = np.empty(rows), np.empty((rows, 2 * problem.m))
        written, stats = ctypes.c_int(0), np.zeros(4, dtype=np.int64)
        p, y0 = model.parameter_vector(problem.t0), problem.y0
        times = np.ascontiguousarray(t_eval if t_eval is not None else np.empty(0))
        callback = _PROGRESS(options.progress) if options.progress is not None else _PROGRESS()
        flag = library.kronlag_cvode(
            p.ctypes.data, problem.t0, problem.t1, y0.ctypes.data, len(times), times.ctypes.data,
            options.rtol / self.TOLERANCE_SCALE, options.atol / self.TOLERANCE_SCALE, problem.alpha, problem.beta,
            options.max_step if np.isfinite(options.max_step) else 0.0, options.max_steps,
            t_out.ctypes.data, y_out.ctypes.data, ctypes.byref(written), stats.ctypes.data, callback)
        n = written.value
        t_out, y_out = t_out[:n].copy(), y_out[:n].copy()
        derived = {"qdd": np.empty((n, problem.m)), "lam": np.empty((n, model.r)), "mu": np.empty((n, model.s)),
                   "kinetic_energy": np.empty(n), "position_residual": np.empty((n, model.r)),
                   "velocity_residual": np.empty((n, model.r + model.s))}
        library.kronlag_outputs(p.ctypes.data, n, t_out.ctypes.data, y_out.ctypes.data,
                                *(derived[key].ctypes.data for key in derived))
        if flag == 0:
            status, message = 0, "The integration reached the end of the time span."
        else:
            name = library.kronlag_cvode_flag_name(flag).decode()
            end = t_out[n - 1] if n else problem.t0
            status, message = -1, f"Integration failed after t = {end:.6g}: CVODE {name} ({flag})"
        return Solution(t=t_out, y=y_out, status=status, message=message, nfev=int(stats[1]),
                        njev=int(stats[2]), steps=int(stats[0]), derived=derived)


#: Methods by name (``"auto"`` picks among them in :func:`simulate`).
METHODS: dict[str, type[Solver]] = {
    BaumgarteSolver.name: BaumgarteSolver,
    ProjectionSolver.name: ProjectionSolver,
    GGLSolver.name: GGLSolver,
    CompiledSolver.name: CompiledSolver,
}


def _output_times(t_eval: Sequence[float] | np.ndarray | None, t0: float, t1: float) -> np.ndarray | None:
    if t_eval is None:
        return None
    times = np.asarray(t_eval, dtype=float).ravel()
    if times.size and (np.any(np.diff(times) <= 0) or times[0] < t0 or times[-1] > t1):
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
        derived["velocity_residual"][k] = np.concatenate([terms["Phi_q"] @ qd, terms["A"] @ qd + terms["b"]])
    return derived


def _trajectory(solution: Solution, problem: MultibodyProblem, method: str, started: float) -> Trajectory:
    """The :class:`Trajectory` of ``solution``, with the derived quantities at its output times."""
    model, m = problem.model, problem.m
    derived = solution.derived if solution.derived is not None else _derived(model, solution.t, solution.y)
    potential = np.array([model.potential_energy(y[:m], t) for t, y in zip(solution.t, solution.y)])
    return Trajectory(t=solution.t, q=solution.y[:, :m], qd=solution.y[:, m:], **derived,
                      potential_energy=potential, coordinate_names=tuple(model.coordinate_names), model=model,
                      method=method, status=solution.status, message=solution.message, nfev=solution.nfev,
                      njev=solution.njev, steps=solution.steps, wall_time=time.perf_counter() - started)


def simulate(model: NumericModel, t_span: tuple[float, float], q0, qd0, *, method: str = "auto",
             rtol: float = 1e-8, atol: float = 1e-10, t_eval=None, alpha: float | None = None,
             beta: float | None = None, max_step: float | None = None, max_steps: int = 100_000,
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
        onto ``Phi(q) = 0``, ``Phi_q qd = 0``, ``A qd + b = 0`` before starting.
    method : {'auto', 'baumgarte', 'projection', 'ggl', 'compiled'}
        Formulation and integrator:

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
            ``'compiled'`` when the model allows it, else ``'projection'``.
    rtol, atol : float
        Relative and absolute local error tolerances.
    t_eval : array_like, shape (K,), optional
        Increasing output times within ``t_span``; by default every accepted step.
    alpha, beta : float, optional
        Baumgarte parameters (units 1/time).  Default 10 for ``'baumgarte'`` and
        ``'compiled'``, 0 for ``'projection'`` (projection removes the drift);
        unused by ``'ggl'``.
    max_step : float, optional
        Largest step size (unbounded by default).
    max_steps : int
        Most accepted steps; reaching it ends the integration with status -1.
    progress : callable, optional
        Called as ``progress(t)`` after every accepted step.

    Returns
    -------
    Trajectory
        ``t`` (N,), ``q``, ``qd``, ``qdd`` (N, m), ``lam`` (N, r), ``mu`` (N, s),
        energies, residuals ``Phi(q)`` (N, r) and ``[Phi_q qd; A qd + b]``
        (N, r + s), counters and wall time.  On failure (a singular
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
    if not t1 > t0:
        raise ValueError(f"t_span must have t1 > t0, got {t_span!r}")
    name = _resolve_method(method, model)
    default_stabilization = 10.0 if name in (BaumgarteSolver.name, CompiledSolver.name) else 0.0
    options = SolverOptions(rtol=rtol, atol=atol, max_step=np.inf if max_step is None else float(max_step),
                            max_steps=max_steps, progress=progress)
    start = MultibodyProblem(model=model, t0=t0, t1=t1, q0=np.asarray(q0, dtype=float).ravel(),
                             qd0=np.asarray(qd0, dtype=float).ravel(), t_eval=_output_times(t_eval, t0, t1),
                             alpha=default_stabilization if alpha is None else float(alpha),
                             beta=default_stabilization if beta is None else float(beta))
    if start.q0.shape != (model.m,) or start.qd0.shape != (model.m,):
        raise ValueError(f"q0 and qd0 must have {model.m} entries, got {start.q0.size} and {start.qd0.size}")
    y0 = start.project(t0, start.y0, options.projection_tol)
    problem = replace(start, q0=y0[:model.m], qd0=y0[model.m:])
    solution = METHODS[name](options).solve(problem)
    return _trajectory(solution, problem, name, started)


def _resolve_method(method: str, model: NumericModel) -> str:
    if method == "auto":
        return CompiledSolver.name if CompiledSolver.supports(model) else ProjectionSolver.name
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose from 'auto', {', '.join(map(repr, METHODS))}")
    return method
