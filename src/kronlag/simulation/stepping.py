"""The Python stepping loop of the Python-driven integrators: an integrator advanced step by step,
outputs collected, failures and the approach to singular configurations turned into a :class:`Result`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np

from ..core.errors import NumericalError, SingularConfigurationError
from ..numeric.tolerances import APPROACH_RTOL, numerical_rank, rank_magnitudes, row_scales, singular_ratio
from .problem import MultibodyProblem, Solution, SolverOptions
from .trajectory import Result, SingularPassage
from .watch import LimitStop, locate

__all__ = ["Stepper", "ApproachWatch", "approach_scales", "march", "approach_text", "stopped_text", "SUCCESS"]


SUCCESS = Result.SUCCESS.value


#: Failures of the model evaluation that end an integration (partial results are returned).
_FAILURES = (NumericalError, np.linalg.LinAlgError, FloatingPointError)


class Stepper(ABC):
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


def approach_scales(problem: MultibodyProblem) -> np.ndarray:
    """The constraint rows' units in the approach test of a run of ``problem``, the same in every
    segment of it (:func:`kronlag.tolerances.row_scales` at its start; the compiled drivers'
    ``row_scale``)."""
    return row_scales(problem.model.Phi_q(problem.q0, problem.t0), problem.model.rank_rtol)


class ApproachWatch:
    """The watch of ``src/kronlag/simulation/c/monitor.c`` for the Python-driven index-1 methods: the
    singular ratio of ``Phi_q`` (:func:`kronlag.tolerances.singular_ratio`) at every accepted step,
    the next step limited so that the ratio, extrapolated, keeps half its value, and the approach
    to a singular configuration (ratio below :data:`~kronlag.tolerances.APPROACH_RTOL`)."""

    def __init__(self, problem: MultibodyProblem):
        self.model = problem.model
        Phi_q = self.model.Phi_q(problem.q0, problem.t0)
        self.generic_rank = numerical_rank(rank_magnitudes(Phi_q)[0], self.model.rank_rtol)
        self.scales = approach_scales(problem)
        self.samples = [(problem.t0, singular_ratio(Phi_q, self.generic_rank, self.scales)[0])]

    def observe(self, t: float, y: np.ndarray) -> SingularPassage | None:
        """The approach at the accepted state ``(t, y)``, or None."""
        q = y[:self.model.m]
        ratio, row = singular_ratio(self.model.Phi_q(q, t), self.generic_rank, self.scales)
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


def approach_text(t: float, q: np.ndarray) -> str:
    return f"Stopped at t = {t:.6g}, q = {np.array2string(q, precision=6)}: {Result.APPROACH.value}"


def stopped_text(t: float, result: Result) -> str:
    """The message of a run ended by Ctrl-C or a callback's exception (``result``) after the step to ``t``."""
    return f"Integration stopped at t = {t:.6g}: {result.value}"


def march(make_stepper: Callable[[], Stepper], problem: MultibodyProblem, options: SolverOptions) -> Solution:
    """Start ``make_stepper()`` and advance it to ``problem.t1``, collecting the outputs.

    Outputs are every accepted step (``t_eval is None``) or ``problem.t_eval``
    (interpolated inside each step).  A model failure, an integrator failure,
    ``options.max_steps`` steps or the approach to a singular configuration
    (:class:`ApproachWatch`) end the loop with status -1; so do Ctrl-C and any other exception
    (:attr:`Result.INTERRUPTED`, :attr:`Result.RAISED`: ``options.control`` holds it for
    :func:`~kronlag.simulation.simulate` to raise).
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
    steps, result, message, events, stop = 0, Result.SUCCESS, SUCCESS, (), None
    stepper = None
    limits = problem.watch
    try:
        watch = ApproachWatch(problem)
        before = limits.values(problem.model, problem.t0, problem.y0) if limits else None
        stepper = make_stepper()
        while stepper.t < problem.t1:
            t_before = stepper.t
            if steps >= options.max_steps:
                result, message = Result.MAX_STEPS, (f"Integration stopped at t = {stepper.t:.6g}: "
                                                     f"{Result.MAX_STEPS.value} ({options.max_steps})")
                break
            largest = min(options.max_step, watch.max_step())
            if limits is not None and limits.first_step > 0 and steps == 0:  # a rebound: end inside its flight
                largest = min(largest, limits.first_step)
            stepper.limit_step(largest)
            failure = stepper.step()
            if failure is not None:
                result, message = Result.SOLVER_FAILED, f"Integration failed at t = {stepper.t:.6g}: {failure}"
                break
            steps += 1
            end, y_end = stepper.t, stepper.y
            if limits is not None:  # a watched function through zero: the step ends there
                stop, before = _limit_stop(limits, problem, stepper, t_before, before)
                if stop is not None:
                    end, y_end = stop.t, stop.y
            if every_step:
                times.append(end)
                states.append(y_end)
            while pending < len(outputs) and outputs[pending] <= end:
                state = stepper.interpolate(outputs[pending])  # first: it may fail
                times.append(outputs[pending])
                states.append(state)
                pending += 1
            if stop is not None:
                result, message = Result.LIMIT, f"Stopped at t = {end:.6g}: {Result.LIMIT.value}"
                break
            stopped = options.control.report(options.progress, stepper.t)
            if stopped is not None:
                result, message = stopped, stopped_text(stepper.t, stopped)
                break
            approach = watch.observe(stepper.t, stepper.y)
            if approach is not None:
                result, message, events = Result.APPROACH, approach_text(stepper.t, approach.q), (approach,)
                break
    except _FAILURES as error:
        where = stepper.t if stepper is not None else problem.t0
        result = Result.SINGULAR if isinstance(error, SingularConfigurationError) else Result.SOLVER_FAILED
        message = f"Integration failed at t = {where:.6g}: {type(error).__name__}: {error}"
    except (Exception, KeyboardInterrupt) as error:  # noqa: BLE001 - simulate raises it with the partial result
        options.control.record(error)
        result = options.control.stop()
        message = stopped_text(stepper.t if stepper is not None else problem.t0, result)
    nfev, njev = stepper.counters() if stepper is not None else (0, 0)
    return Solution(t=np.asarray(times, dtype=float), y=np.reshape(states, (len(states), 2 * problem.m)),
                    result=result, message=message, nfev=nfev, njev=njev, steps=steps, events=events, stop=stop)


def _limit_stop(limits, problem: MultibodyProblem, stepper: Stepper, t_before: float,
                before: np.ndarray) -> tuple[LimitStop | None, np.ndarray]:
    """Limits: the event inside the step just taken from ``t_before`` (the watched functions
    ``before`` there), located on the stepper's dense output, and the functions at the step's end."""
    model = problem.model
    after = limits.values(model, stepper.t, stepper.y)
    found = locate(lambda t: limits.values(model, t, stepper.interpolate(t)), t_before, stepper.t, before, after)
    if found is None:
        return None, after
    t, triggered = found
    return LimitStop(t, stepper.interpolate(t), triggered), after
