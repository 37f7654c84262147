"""The driver: :func:`simulate` joins a :class:`~kronlag.simulation.problem.MultibodyProblem`, a solver
of :data:`~kronlag.simulation.solvers.METHODS` and the derived quantities into a
:class:`~kronlag.simulation.trajectory.Trajectory`."""

from __future__ import annotations

import inspect
import time
import warnings
from collections.abc import Callable, Sequence
from contextlib import suppress
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import AssemblyError, InitialStateWarning, InputError, SingularConfigurationError
from ..core.limits import MAX_OUTPUT_POINTS
from ..numeric.linalg import velocity_constraints
from .control import RunControl
from .controllers import ControlledModel, ControlLoop, Sampled, controlled, solve_sampled
from .impacts import has_events, solve_with_limits
from .problem import MultibodyProblem, Solution, Solver, SolverOptions, derived_shapes
from .solvers import AUTO_PREFERENCE, METHODS, SAMPLED_PREFERENCE
from .trajectory import MethodInterval, Trajectory

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel

__all__ = ["simulate"]


def _output_times(t_eval: Sequence[float] | np.ndarray | None, t0: float, t1: float) -> np.ndarray | None:
    if t_eval is None:
        return None
    times = np.asarray(t_eval, dtype=float).ravel()
    if times.size > MAX_OUTPUT_POINTS:
        raise InputError(f"t_eval has {times.size} output times, more than the limit of {MAX_OUTPUT_POINTS}")
    if times.size == 0:
        raise InputError("t_eval is empty: give at least one output time (or None for every step)")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0) or times[0] < t0 or times[-1] > t1:
        raise InputError(f"t_eval must increase strictly and lie in t_span = [{t0}, {t1}]")
    return times


def _derived(model: NumericModel, times: np.ndarray, states: np.ndarray,
             parameters: np.ndarray | None = None) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """The :attr:`Solution.derived` arrays at ``states`` (N, 2 m), by the model's Python interface
    (NaN accelerations and multipliers where the configuration is singular), and under a controller
    the parameters at the outputs (given held ones, ``parameters``; else those the controller sets)."""
    m = model.m
    derived = {name: np.full(shape, np.nan) for name, shape in derived_shapes(len(times), *model.shape).items()}
    loop = model.loop if isinstance(model, ControlledModel) else None
    recorded = None if loop is None else np.empty((len(times), len(model.parameter_names)))
    held = None if loop is None else loop.p.copy()  # a run with limits goes on with them after this
    for k, (t, y) in enumerate(zip(times, states)):
        q, qd = y[:m], y[m:]
        if loop is not None and parameters is not None:
            loop.p[:] = parameters[k]
        with suppress(SingularConfigurationError):  # the state a failed integration ended in
            result = model.forward_dynamics(q, qd, t)
            derived["qdd"][k], derived["lam"][k], derived["mu"][k] = result.qdd, result.lam, result.mu
        terms = model.dynamics_terms(q, qd, t)
        derived["kinetic_energy"][k] = 0.5 * qd @ terms["M"] @ qd
        derived["potential_energy"][k] = model.potential_energy(q, t)
        derived["position_residual"][k] = terms["Phi"]
        B, c = velocity_constraints(terms)
        derived["velocity_residual"][k] = B @ qd + c
        if recorded is not None:
            recorded[k] = loop.p
    if held is not None:
        loop.p[:] = held
    return derived, recorded


def _intervals(solution: Solution, method: str, t0: float) -> tuple[MethodInterval, ...]:
    """The solver's :attr:`Solution.intervals` with neighbours of the same method joined (a run with
    limits restarts at every event), or one interval of ``method`` over the run."""
    if not solution.intervals:
        t_end = float(solution.t[-1]) if len(solution.t) else t0
        return (MethodInterval(method, t0, t_end, solution.steps, f"method {method!r}"),)
    joined = [solution.intervals[0]]
    for interval in solution.intervals[1:]:
        if interval.method == joined[-1].method:
            joined[-1] = replace(joined[-1], t_end=interval.t_end, steps=joined[-1].steps + interval.steps)
        else:
            joined.append(interval)
    return tuple(joined)


def _trajectory(solution: Solution, problem: MultibodyProblem, method: str, started: float,
                model: NumericModel, loop: ControlLoop | None) -> Trajectory:
    """The :class:`Trajectory` of ``solution`` (of ``model``, under ``loop``'s controller if any), with the
    derived quantities at its output times."""
    m, derived, parameters = problem.m, solution.derived, solution.parameters
    if derived is None:
        derived, parameters = _derived(problem.model, solution.t, solution.y, parameters)
    return Trajectory(t=solution.t, q=solution.y[:, :m], qd=solution.y[:, m:], **derived,
                      coordinate_names=tuple(model.coordinate_names), model=model,
                      method=method, message=solution.message, nfev=solution.nfev,
                      njev=solution.njev, steps=solution.steps, wall_time=time.perf_counter() - started,
                      events=solution.events, result=solution.result,
                      inputs=loop.inputs(parameters) if loop is not None else {},
                      intervals=_intervals(solution, method, problem.t0), segments=solution.segments,
                      sample_times=(loop.t0 + loop.sampled.period * np.arange(loop.samples)
                                    if loop is not None and loop.sampled else None))


def simulate(model: NumericModel, t_span: tuple[float, float], q0, qd0, *, method: str | type[Solver] = "auto",
             rtol: float = 1e-8, atol: float = 1e-10, t_eval=None, alpha: float | None = None,
             beta: float | None = None, max_step: float | None = None, max_steps: int | None = None,
             progress: Callable[[float], object] | None = None,
             controller: Callable | Sampled | None = None) -> Trajectory:
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
    method : {'auto', 'switching', 'ali3p', 'compiled', 'baumgarte', 'projection', 'ggl'} or Solver subclass
        Formulation and integrator (a :class:`~kronlag.simulation.Solver` subclass: that one,
        as scipy's ``solve_ivp`` takes an ``OdeSolver`` subclass):

        ``'switching'``
            ``'compiled'`` away from singular configurations, ``'ali3p'``
            through them, redundant constraints included (:class:`SwitchingSolver`);
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
            ``'compiled'``, ``'projection'``) that the model allows; under a
            :class:`~kronlag.Sampled` controller the first of :data:`SAMPLED_PREFERENCE`
            (``'ali3p'``, ``'compiled'``, ``'projection'``): a one-step method restarts at
            the samples without cost.

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
        Called as ``progress(t)`` after every accepted step.  An exception it raises ends the
        run like one raised by a time-varying parameter (see Raises).
    controller : callable or Sampled, optional
        Inputs set from the state while the integrator runs (``docs/control.md``):
        ``controller(t, q, qd) -> {parameter name: value}``, called by every method at every
        evaluation of the equations of motion (right-hand side, Newton iteration, output), or
        :class:`~kronlag.Sampled` ``(f, period=..., state=...)``, a digital controller whose
        inputs are held between its samples (every method restarts exactly at the sample
        instants).  The keys must be parameters of the model entering only the forces, the same
        at every call, the values finite (:class:`InputError` naming the key, or ``t`` and ``q``).
        The values used are in ``trajectory.inputs``.  Not with time-varying parameters.

    Returns
    -------
    Trajectory
        ``t`` (N,), ``q``, ``qd``, ``qdd`` (N, m), ``lam`` (N, r), ``mu`` (N, s),
        energies, residuals ``Phi(q)`` (N, r) and ``[Phi_q qd; A qd + b]``
        (N, r + s), counters, wall time and ``events`` (the singular
        configurations passed), ``intervals`` (which integrator ran where, and why: under
        ``'switching'`` CVODE, with the minimum-norm multipliers for redundant constraints, and ALI3-P
        near singular configurations).  On failure (a singular
        configuration, an integrator error, ``max_steps``) ``status`` is -1,
        ``message`` says why, and the arrays hold the solution up to the failure.

    Raises
    ------
    KeyboardInterrupt
        On Ctrl-C (SIGINT), within a fraction of a second for every method, raised once the
        integration has stopped, with the run up to the last accepted step as its attribute
        ``trajectory`` (``result`` :attr:`Result.INTERRUPTED`).  This holds when SIGINT has Python's
        default handler and ``simulate`` runs on the main thread (else the signal is left to the
        program's own handler); a second Ctrl-C raises at once, without the trajectory.
    Exception
        An exception raised by the controller, a time-varying parameter's function or ``progress`` ends the run
        at the last accepted step and propagates with the partial trajectory as its attribute
        ``trajectory`` (``result`` :attr:`Result.RAISED`, the exception in ``message``).

    Examples
    --------
    >>> model = kronlag.derive(kronlag.models.four_bar()).numeric(parameters)  # doctest: +SKIP
    >>> q0, qd0 = model.assemble([0.5, 1.0, 2.0], fixed={"q1": 0.5})          # doctest: +SKIP
    >>> trajectory = kronlag.simulate(model, (0, 10), q0, qd0)                # doctest: +SKIP
    """
    started = time.perf_counter()
    t0, t1 = (float(value) for value in t_span)
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise InputError(f"t_span must be finite with t1 > t0, got {t_span!r}")
    for label, value in (("rtol", rtol), ("atol", atol)):
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"{label} must be a positive number, got {value!r}")
    if max_step is not None and not float(max_step) > 0:
        raise InputError(f"max_step must be positive, got {max_step!r}")
    span_steps = max(100_000, int(np.ceil(_STEPS_PER_TIME * (t1 - t0))))
    if max_steps is None:
        max_steps = span_steps
    if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 1):
        raise InputError(f"max_steps must be an integer >= 1, got {max_steps!r}")
    solver = _resolve_method(method, model, sampled=isinstance(controller, Sampled))
    default_stabilization = solver.stabilization
    control = RunControl()
    options = SolverOptions(rtol=rtol, atol=atol, max_step=np.inf if max_step is None else float(max_step),
                            max_steps=int(max_steps), progress=progress, control=control)
    start = MultibodyProblem(model=model, t0=t0, t1=t1, q0=np.asarray(q0, dtype=float).ravel(),
                             qd0=np.asarray(qd0, dtype=float).ravel(), t_eval=_output_times(t_eval, t0, t1),
                             alpha=default_stabilization if alpha is None else float(alpha),
                             beta=default_stabilization if beta is None else float(beta))
    for label, value in (("q0", start.q0), ("qd0", start.qd0)):
        if value.shape != (model.m,):
            raise InputError(f"{label} must have {model.m} entries ({', '.join(model.coordinate_names)}), "
                             f"got {value.size}")
        bad = [model.coordinate_names[i] for i in np.flatnonzero(~np.isfinite(value))]
        if bad:
            raise InputError(f"{label} is not finite for {', '.join(bad)}")
    problem = replace(start, **dict(zip(("q0", "qd0"), _consistent_start(start, options))))
    loop = None
    if controller is not None:  # its first call, at the start, checks what it returns
        loop = ControlLoop(controller, model, control, t0)
        loop.start(t0, problem.y0)
        problem = controlled(problem, loop)
    with control.catching_sigint():
        if has_events(model):  # limits: segments between the impacts and contact changes
            solution = solve_with_limits(solver(options), problem, _derived)
        elif loop is not None and loop.sampled and not solver.samples_inside:
            solution = solve_sampled(solver(options), problem, loop)
        else:
            solution = solver(options).solve(problem)
        if control.error is not None:
            error = control.error
            solution = replace(solution, message=f"{solution.message}: {type(error).__name__}: {error}")
        trajectory = _trajectory(solution, problem, solver.name, started, model, loop)
    control.raise_if_stopped(trajectory)
    return trajectory


#: The default ``max_steps``: this many per unit of simulated time, at least 100 000.
_STEPS_PER_TIME = 1000


#: An initial state whose projection onto the constraints moves ``q`` by more than this (relative to
#: ``1 + |q0|``) is refused: the projection may have jumped to another assembly branch.
_MAX_START_CORRECTION = 1e-3


#: Corrections of the initial state below this (relative) are the rounding of its assembly: no warning.
_ROUNDING = 1e-9


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


def _resolve_method(method: str | type[Solver], model: NumericModel, *, sampled: bool = False) -> type[Solver]:
    """The solver class ``method`` names (``"auto"``: the first of :data:`AUTO_PREFERENCE`, or of
    :data:`SAMPLED_PREFERENCE` under a sampled controller, that supports ``model``), or ``method``
    itself if it is a concrete :class:`Solver` subclass."""
    if isinstance(method, type) and issubclass(method, Solver):
        if inspect.isabstract(method) or not isinstance(getattr(method, "name", None), str):
            raise InputError(f"method={method.__name__} is not a complete Solver: it must define name and solve()")
        return method
    if isinstance(method, str) and method == "auto":
        preference = SAMPLED_PREFERENCE if sampled else AUTO_PREFERENCE
        return next(METHODS[name] for name in preference if METHODS[name].supports(model))
    if isinstance(method, str) and method in METHODS:
        return METHODS[method]
    raise InputError(f"unknown method {method!r}; choose from 'auto', {', '.join(map(repr, METHODS))} "
                     "or pass a Solver subclass")
