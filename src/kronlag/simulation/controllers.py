"""Controllers in the loop of :func:`kronlag.simulate`: parameter values (inputs such as a force ``u``
or a torque ``tau``) set by Python code from the state while the integrator runs.

Two forms:

- a callable ``controller(t, q, qd) -> {parameter name: value}``, called at every evaluation of the
  equations of motion (every right-hand side, Newton iteration and output);
- :class:`Sampled`, a digital controller with a zero-order hold: called once at each sample instant
  ``t0 + k period`` with a state carried from sample to sample; the integrator stops exactly there
  and restarts with the new inputs (inside the compiled drivers, without leaving C between samples).

Both write the parameter vector that the kernels read: one buffer, :attr:`ControlLoop.p`, shared by
the compiled drivers (``kronlag_options.p_control``, written by the C callback
:meth:`ControlLoop.c_callback`) and the Python methods (a :class:`ControlledModel`, whose
evaluations read it).  An exception raised by the controller ends the run like one raised by
``progress`` (:class:`~.control.RunControl`): :func:`kronlag.simulate` raises it with the partial
trajectory as its ``trajectory``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.errors import InputError
from ..model.modelfile.controller import PID, StateFeedback
from ..numeric.numeric_model import NumericModel
from .control import RunControl
from .interface import Controller
from .problem import MultibodyProblem, Solution, Solver
from .stepping import stopped_text
from .trajectory import Result

if TYPE_CHECKING:
    from _ctypes import CFuncPtr

__all__ = ["Sampled", "ControlLoop", "ControlledModel", "controlled", "solve_sampled", "file_controller", "CONTINUOUS",
           "SAMPLED"]


#: ``kronlag_options.control_mode``: the controller is called at every evaluation ...
CONTINUOUS = 1
#: ... or at the sample instants only (its values held in between).
SAMPLED = 2

#: The matrices an input set by a controller must not enter (as for time-varying parameters: the
#: constraints and ``M`` are differentiated or factored as functions of ``q`` alone).
_CONSTANT_IN = ("M", "Phi", "A", "b")

_NO_STATE: Any = object()


class Sampled:
    """A sampled-data (digital) controller with a zero-order hold, for ``simulate(controller=...)``.

    ``f`` is called at ``t0, t0 + period, t0 + 2 period, ...`` (``k * period`` from the start, without
    accumulated rounding) with the state there; the inputs it returns are held constant until the
    next sample.  The integrator stops exactly at every sample instant and restarts with the new
    inputs (the accelerations jump there).

    Parameters
    ----------
    f : callable
        Without ``state``: ``f(t, q, qd) -> {name: value}``.  With ``state``:
        ``f(t, q, qd, state) -> ({name: value}, new_state)``; ``new_state`` is passed to the next
        sample (an integrator, an observer's estimate, the previous error ...: any object).
    period : float
        Sample period, positive (units of time).
    state : object, optional
        The controller's state at the first sample.

    Attributes
    ----------
    final_state : object
        The state after the last sample of the last run (``state`` before any run).

    Examples
    --------
    A PI controller of ``x`` at 1 kHz (``e`` integrated by the forward Euler rule)::

        def pi(t, q, qd, integral):
            error = 0.5 - q[0]
            return {"u": 40 * error + 10 * integral}, integral + 1e-3 * error

        controller = kronlag.Sampled(pi, period=1e-3, state=0.0)
    """

    def __init__(self, f: Callable, *, period: float, state: Any = _NO_STATE):
        if not callable(f):
            raise InputError(f"Sampled: f must be callable, got {type(f).__name__}")
        try:
            period = float(period)
        except (TypeError, ValueError) as error:
            raise InputError(f"Sampled: period must be a positive number, got {period!r}") from error
        if not (math.isfinite(period) and period > 0):
            raise InputError(f"Sampled: period must be a positive number, got {period!r}")
        self.f, self.period = f, period
        self.stateful = state is not _NO_STATE
        self.initial_state = state if self.stateful else None
        self.final_state = self.initial_state

    def __repr__(self) -> str:
        return f"Sampled({getattr(self.f, '__name__', self.f)!r}, period={self.period!r})"


class ControlLoop:
    """One run's controller: the parameter buffer :attr:`p` it writes, the state buffer the compiled
    drivers fill, the sample schedule of a :class:`Sampled` controller, and the checks of what the
    controller returns.

    Parameters
    ----------
    controller : callable or Sampled
    model : NumericModel
        The model without controller (constant parameters).
    control : RunControl
        Records an exception raised by the controller (the run then ends, :func:`simulate` raises it).
    t0 : float
        Start of the run (the first sample of a :class:`Sampled`).
    """

    def __init__(self, controller: Callable | Sampled, model: NumericModel, control: RunControl, t0: float):
        if not (callable(controller) or isinstance(controller, Sampled)):
            raise InputError(f"controller must be a callable controller(t, q, qd) or kronlag.Sampled, "
                             f"got {type(controller).__name__}")
        if model.time_varying:
            raise InputError("controller= with time-varying parameters is not supported: compute their time "
                             "dependence in the controller (it receives t)")
        self.model, self.control, self.t0 = model, control, t0
        self.sampled: Sampled | None = None
        self.function: Callable[..., Any]
        if isinstance(controller, Sampled):
            self.sampled, self.function = controller, controller.f
        else:
            self.function = controller
        self.mode = SAMPLED if self.sampled else CONTINUOUS
        self.m = model.m
        #: The parameter vector the kernels read (kronlag_options.p_control; ControlledModel._constants).
        self.p = np.array(model.parameter_vector(t0), dtype=float)
        #: ``[q, qd, next sample time]``: filled by the compiled drivers before they call back.
        self.buffer = np.zeros(2 * self.m + 1)
        self.index = {name: i for i, name in enumerate(model.parameter_names)}
        self.keys: frozenset[str] | None = None
        self.samples = 0
        self.state = self.sampled.initial_state if self.sampled else None
        self._callback: CFuncPtr | None = None  # an interface.Controller

    # -- the values -----------------------------------------------------------------------

    def _refuse(self, values, t: float, q: np.ndarray) -> None:
        """InputError for what the controller returned at ``(t, q)``: not a mapping, an unknown key,
        a parameter that cannot be an input, another set of keys than before, or a value not finite."""
        where = f"at t = {t:.6g}, q = {np.array2string(np.asarray(q), precision=6, max_line_width=10**9)}"
        if not isinstance(values, Mapping):
            raise InputError(f"the controller must return a dict {{parameter name: value}}, got "
                             f"{type(values).__name__} {where}")
        unknown = [name for name in values if name not in self.index]
        if unknown:
            raise InputError(f"the controller returned {unknown[0]!r}, which is not a parameter of the model "
                             f"(its parameters: {', '.join(self.model.parameter_names)})")
        equations = self.model.equations
        frozen = [name for name in values if any(getattr(equations, matrix).has(equations.parameters[self.index[name]])
                                                 for matrix in _CONSTANT_IN)]
        if frozen:
            raise InputError(f"the controller sets {frozen[0]!r}, which enters M or the constraints: an input "
                             "must enter only the forces (f_Q, g, potentials)")
        if self.keys is not None and frozenset(values) != self.keys:
            raise InputError(f"the controller returned the keys {sorted(values)} {where}, but "
                             f"{sorted(self.keys)} before: it must set the same inputs at every call")
        for name, value in values.items():
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if not math.isfinite(number):
                raise InputError(f"the controller returned {name} = {value!r} {where}: expected a finite number")

    def write(self, values, t: float, q: np.ndarray) -> None:
        """Write the controller's ``values`` (checked) into :attr:`p`."""
        p, index = self.p, self.index
        if self.keys is None:
            self._refuse(values, t, q)
            self.keys = frozenset(values)
        elif type(values) is not dict or values.keys() != self.keys:
            self._refuse(values, t, q)
        try:
            for name, value in values.items():
                number = float(value)
                if number - number != 0.0:  # inf or nan
                    raise ValueError
                p[index[name]] = number
        except (TypeError, ValueError):
            self._refuse(values, t, q)

    def evaluate(self, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        """Call a continuous controller at ``(t, q, qd)`` and write its values."""
        self.write(self.function(t, q, qd), t, q)

    def sample(self, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        """Call a :class:`Sampled` controller at the sample instant ``t`` and write its values; the next
        sample time goes to the last entry of :attr:`buffer`."""
        sampled = self.sampled
        assert sampled is not None  # called for a Sampled controller only
        if sampled.stateful:
            result = self.function(t, q, qd, self.state)
            if not (isinstance(result, tuple) and len(result) == 2):
                raise InputError(f"Sampled with a state: f(t, q, qd, state) must return (inputs, new_state), got "
                                 f"{type(result).__name__} at t = {t:.6g}")
            values, self.state = result
            sampled.final_state = self.state
        else:
            values = self.function(t, q, qd)
        self.write(values, t, q)
        self.samples += 1
        self.buffer[2 * self.m] = self.next_sample()

    def next_sample(self) -> float:
        """The instant of the next sample (``inf`` for a continuous controller)."""
        return self.t0 + self.samples * self.sampled.period if self.sampled else math.inf

    def start(self, t: float, y: np.ndarray) -> None:
        """The first call, at the consistent start ``(t, y)``: checks the keys before the integration."""
        q, qd = y[:self.m].copy(), y[self.m:].copy()
        if self.sampled:
            self.sample(t, q, qd)
        else:
            self.evaluate(t, q, qd)

    # -- the compiled drivers -------------------------------------------------------------------

    def c_callback(self) -> CFuncPtr:
        """The ``controller`` of :class:`~.interface.DriverOptions`: reads ``[q, qd]`` from
        :attr:`buffer` (copies: the controller may keep them), calls the controller (or samples),
        writes :attr:`p`; returns 0, or the ``KRONLAG_RESULT_*`` code to end the run with (an
        exception recorded in the run control, or Ctrl-C).

        A continuous controller is called at every evaluation, so its call is written out here (the
        checks of :meth:`write` on the first call and whenever the keys differ, then only the
        finiteness of each value): about 1 us of Python besides the controller's own code and ctypes'
        callback (measured by ``bench/bench_controllers.py``)."""
        if self._callback is None:
            control, q, qd = self.control, self.buffer[:self.m], self.buffer[self.m:2 * self.m]
            function, p, index, write = self.function, self.p, self.index, self.write
            interrupted, raised = Result.INTERRUPTED.code, Result.RAISED.code

            def continuous(t: float) -> int:
                values = None
                try:
                    values = function(t, q.copy(), qd.copy())
                    if type(values) is not dict or values.keys() != self.keys:
                        write(values, t, q)  # the checks: an InputError saying what is wrong
                    else:
                        for name, value in values.items():
                            number = float(value)
                            if number - number != 0.0:  # inf or nan
                                write(values, t, q)  # raises, naming the value
                            p[index[name]] = number
                except (Exception, KeyboardInterrupt) as error:  # noqa: BLE001 - simulate raises it
                    # float() of a value that is no number: located by write(); the controller's own
                    # exceptions as they are
                    control.record(_located(write, values, t, q) if _bad_value(error, values) else error)
                return interrupted if control.interrupted else (raised if control.error else 0)  # control.stop()

            def sampled(t: float) -> int:
                try:
                    self.sample(t, q.copy(), qd.copy())
                except (Exception, KeyboardInterrupt) as error:  # noqa: BLE001 - simulate raises it
                    control.record(error)
                stop = control.stop()
                return 0 if stop is None else stop.code

            self._callback = Controller(sampled if self.sampled else continuous)
        return self._callback

    def driver_fields(self, rows: int) -> dict[str, Any]:
        """The fields of :class:`~.interface.DriverOptions` for a controlled run (``p_out``: the
        recorded parameters, (rows, P))."""
        self.buffer[2 * self.m] = self.next_sample()
        return {"controller": self.c_callback(), "control_mode": self.mode, "p_control": self.p,
                "control_buffer": self.buffer}

    # -- results ---------------------------------------------------------------------------

    def inputs(self, parameters: np.ndarray | None) -> dict[str, np.ndarray]:
        """The recorded inputs by name from the parameters at the outputs (N, P)."""
        if parameters is None or self.keys is None:
            return {}
        return {name: parameters[:, self.index[name]].copy() for name in self.model.parameter_names
                if name in self.keys}


def _bad_value(error: BaseException, values) -> bool:
    """``error`` came from converting one of the controller's ``values`` (it returned them)."""
    return isinstance(error, TypeError | ValueError) and values is not None


def _located(write: Callable, values, t: float, q: np.ndarray) -> BaseException:
    """The :class:`InputError` that ``write`` raises for ``values``."""
    try:
        write(values, t, q)
    except InputError as error:
        return error
    return InputError(f"the controller returned {values!r} at t = {t:.6g}: not finite numbers")


class ControlledModel(NumericModel):
    """The model as the Python methods see it under a controller: its parameter vector is the
    loop's buffer :attr:`ControlLoop.p`, and with a continuous controller :meth:`forward_dynamics`
    and :meth:`dynamics_terms` (everything the Python methods evaluate at a state ``(q, qd)``)
    first call the controller there.  Shares the compiled code of the model."""

    loop: ControlLoop
    #: The model viewed (the run's model, or under limits a contact variant of it): its libraries.
    uncontrolled: NumericModel

    @classmethod
    def of(cls, model: NumericModel, loop: ControlLoop) -> ControlledModel:
        if tuple(model.parameter_names) != tuple(loop.model.parameter_names):
            raise InputError("the controller's parameter vector does not fit this model: its parameters are "
                             f"{', '.join(model.parameter_names)}, not {', '.join(loop.model.parameter_names)}")
        variant = object.__new__(cls)  # as NumericModel.with_parameters: the code is shared
        variant.__dict__.update(model.__dict__)
        variant._constants = loop.p
        variant.loop = loop
        variant.uncontrolled = model
        return variant

    def parameter_vector(self, t: float = 0.0) -> np.ndarray:
        return self.loop.p.copy()

    def forward_dynamics(self, q, qd, t: float = 0.0, **options):
        if self.loop.mode == CONTINUOUS:
            self.loop.evaluate(t, np.array(q, dtype=float), np.array(qd, dtype=float))
        return super().forward_dynamics(q, qd, t, **options)

    def dynamics_terms(self, q, qd, t: float = 0.0) -> dict[str, np.ndarray]:
        if self.loop.mode == CONTINUOUS:
            self.loop.evaluate(t, np.array(q, dtype=float), np.array(qd, dtype=float))
        return super().dynamics_terms(q, qd, t)


def controlled(problem: MultibodyProblem, loop: ControlLoop) -> MultibodyProblem:
    """``problem`` with its model under ``loop``'s controller (:class:`ControlledModel`)."""
    return replace(problem, model=ControlledModel.of(problem.model, loop))


def solve_sampled(solver: Solver, problem: MultibodyProblem, loop: ControlLoop) -> Solution:
    """``problem`` under a :class:`Sampled` controller by a method that cannot stop at sample instants
    itself (the Python methods; :attr:`Solver.samples_inside` False): the method runs from one sample
    instant to the next, the controller is called there, and the method starts again from that state.

    Outputs at a sample instant are those of the interval it starts (with the new inputs).  Under
    limits (``problem.watch``) a piece that ends at an event ends the solution there (its ``stop``)."""
    options = solver.options
    pieces: list[Solution] = []
    parameters: list[np.ndarray] = []
    t, y = problem.t0, problem.y0
    while True:
        t_next = min(loop.next_sample(), problem.t1)
        final = t_next >= problem.t1
        t_eval = None
        if problem.t_eval is not None:  # else every step
            times = problem.t_eval
            inside = times[(times >= t) & ((times <= t_next) if final else (times < t_next))]
            t_eval = inside if final else np.append(inside, t_next)  # the end state: for the next interval
        budget = max(options.max_steps - sum(piece.steps for piece in pieces), 0)
        piece = type(solver)(replace(options, max_steps=budget)).solve(
            replace(problem, t0=t, t1=t_next, q0=y[:problem.m], qd0=y[problem.m:], t_eval=t_eval))
        ended = final or piece.result is not Result.SUCCESS or len(piece.t) == 0
        if not ended:
            t, y = t_next, piece.y[-1].copy()
            piece = _without_last_row(piece)
        pieces.append(piece)
        parameters.append(np.tile(loop.p, (len(piece.t), 1)))
        if ended:
            break
        try:
            loop.sample(t, y[:problem.m].copy(), y[problem.m:].copy())
        except (Exception, KeyboardInterrupt) as error:  # noqa: BLE001 - simulate raises it
            options.control.record(error)
            stop = options.control.stop()
            assert stop is not None  # the error just recorded
            pieces.append(replace(piece, t=piece.t[:0], y=piece.y[:0], result=stop, message=stopped_text(t, stop)))
            break
    last = pieces[-1]
    return Solution(t=np.concatenate([piece.t for piece in pieces]), y=np.concatenate([piece.y for piece in pieces]),
                    result=last.result, message=last.message, nfev=sum(piece.nfev for piece in pieces),
                    njev=sum(piece.njev for piece in pieces), steps=sum(piece.steps for piece in pieces),
                    events=tuple(event for piece in pieces for event in piece.events), stop=last.stop,
                    parameters=np.concatenate(parameters),
                    intervals=tuple(interval for piece in pieces for interval in piece.intervals))


def _without_last_row(solution: Solution) -> Solution:
    derived = None if solution.derived is None else {key: value[:-1] for key, value in solution.derived.items()}
    return replace(solution, t=solution.t[:-1], y=solution.y[:-1], derived=derived,
                   parameters=None if solution.parameters is None else solution.parameters[:-1])


def file_controller(spec: StateFeedback | PID, model: NumericModel) -> Callable | Sampled:
    """The controller of a model file's ``[controller]`` table (:mod:`kronlag.model.modelfile.controller`)
    for ``simulate(model, ..., controller=...)``: a function ``(t, q, qd) -> {input: value}``, or a
    :class:`Sampled` one (with a ``period``; a PID carries its integral as the state)."""
    m, index = model.m, {name: i for i, name in enumerate(model.coordinate_names)}
    index.update({f"{name}d": m + i for i, name in enumerate(model.coordinate_names)})
    name = spec.input
    if isinstance(spec, PID):
        i = index[spec.coordinate]
        setpoint, period = spec.setpoint, spec.period
        kp, ki, kd = spec.kp.value, spec.ki.value, spec.kd.value

        def pid(t: float, q: np.ndarray, qd: np.ndarray, integral: float):
            error = setpoint - q[i]
            integral = integral + period * error
            return {name: kp * error + ki * integral - kd * qd[i]}, integral

        return Sampled(pid, period=period, state=0.0)
    # plain floats: for four or so states a loop is several times faster than NumPy's calls
    terms = tuple((index[state], gain.value, reference) for state, gain, reference
                  in zip(spec.states, spec.gains, spec.reference))

    def state_feedback(t: float, q: np.ndarray, qd: np.ndarray) -> dict[str, float]:
        x = q.tolist() + qd.tolist()
        u = 0.0
        for i, gain, reference in terms:
            u -= gain * (x[i] - reference)
        return {name: u}

    return state_feedback if spec.period is None else Sampled(state_feedback, period=spec.period)
