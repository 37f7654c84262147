"""Limits, stops and impacts during a run (:meth:`kronlag.System.add_limit`).

A run of a model with limits is a sequence of segments, each integrated by the chosen method with
a :class:`~.watch.LimitWatch`: the gaps of the free sides and the contact forces of the sides held
as constraints.  A segment ends where one of them falls through zero (root finding to the
integrator's tolerance), and there:

* **impact** (a gap closed): Newton's restitution law with a generalized impulse that keeps every
  bilateral constraint, from::

      [[M, B^T, J^T], [B, 0, 0], [J, 0, 0]] [qd+ - qd-; Lambda; P] = [0; 0; -(1 + e) J qd-]

  with ``B = [Phi_q; A]`` (the contacts held included) and ``J`` the rows of the impacting sides:
  ``B qd+ = B qd-`` (= ``-c``: the velocity constraints hold) and ``J qd+ = -e J qd-``;
* **contact** (the Zeno rule): an impact whose rebound would lift the gap by at most
  :data:`~kronlag.numeric.tolerances.RESTING_GAP` ``atol`` (``v+^2 <= 2 |a| RESTING_GAP atol``,
  ``a < 0`` the gap acceleration in free motion), or with ``e = 0``, ends with ``J qd+ = 0`` and the
  side held as a bilateral constraint (a row added to the augmented system: the model derived
  again with the gap as a constraint, once per set of contacts);
* **release**: a held side whose contact force ``-lambda`` falls through zero is free again.

Each is a :class:`~.trajectory.LimitEvent` in ``trajectory.events``; ``trajectory.limit_forces``
holds the contact forces.  The same loop drives exact stiction (:mod:`.stiction`): a segment's model
is the variant of the joints' friction modes, with the contacts held, and the joints' watched
functions follow the contacts'.
"""

from __future__ import annotations

import copy
import weakref
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..core.errors import InputError
from ..numeric.friction import friction_joints, has_stiction
from ..numeric.limit_kernels import LimitKernels, limit_kernels
from ..numeric.numeric_model import NumericModel
from ..numeric.projection import project_positions
from ..numeric.tolerances import AT_REST, CONTACT_GAP, RESTING_GAP, SAME_INSTANT
from ..symbolic.derivation import derive
from .controllers import ControlledModel, solve_sampled
from .energy import Segment
from .problem import MultibodyProblem, Solution, Solver, derived_shapes
from .stepping import stopped_text
from .stiction import after_impulse, check_not_stopped_by_contacts, held_forces, start_modes, stiction_model, transition
from .trajectory import LimitEvent, Result, StictionEvent
from .watch import LimitWatch

__all__ = ["contact_model", "has_events", "has_limits", "solve_with_limits"]


#: Most events at one instant (simultaneous impacts, a contact made and released) before the run
#: ends as failed: events that do not let time advance.
_MAX_EVENTS_AT_ONE_TIME = 20


def has_limits(model: NumericModel) -> bool:
    """Whether ``model``'s system has limits."""
    return bool(getattr(model.equations.system, "limits", ()))


def has_events(model: NumericModel) -> bool:
    """Whether a run of ``model`` goes segment by segment: limits or exact stiction."""
    return has_limits(model) or has_stiction(model.equations.system)


# -- the models with contacts held as constraints ------------------------------------------------

_CONTACT_EQUATIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_CONTACT_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def contact_model(model: NumericModel, active: tuple[int, ...]) -> NumericModel:
    """``model`` with the limit sides ``active`` (indices, increasing) held as constraints ``g_i(q) = 0``,
    appended after its own (named ``"contact <side>"``); derived and compiled once per set.  Under a
    controller (a :class:`~.controllers.ControlledModel`) the variant is under the same controller."""
    if not active:
        return model
    if isinstance(model, ControlledModel):
        return ControlledModel.of(contact_model(model.uncontrolled, active), model.loop)
    models = _CONTACT_MODELS.setdefault(model, {})
    if active not in models:
        system = model.equations.system
        by_set = _CONTACT_EQUATIONS.setdefault(model.equations, {})
        if active not in by_set:
            sides = limit_kernels(system).sides
            variant = copy.copy(system)
            variant.constraints = list(system.constraints)
            for i in active:
                variant.add_constraint(sides[i].gap, name=f"contact {sides[i].name}")
            by_set[active] = derive(variant)
        parameters = model.__getstate__()["parameters"]
        models[active] = NumericModel(by_set[active], parameters, backend=model.backend, rank_rtol=model.rank_rtol)
    return models[active]


# -- the run -----------------------------------------------------------------------------------------

def check_start(model: NumericModel, q0: np.ndarray, t0: float, atol: float) -> None:
    """InputError naming the limit, its value and the bound for a limit violated at the start."""
    kernels = limit_kernels(model.equations.system)
    values = kernels.evaluate(q0, np.zeros_like(q0), model.parameter_vector(t0))
    for side, gap, bound in zip(kernels.sides, values["gap"], values["bound"]):
        if gap < -CONTACT_GAP * atol:
            lower = side.name.endswith("lower")
            value = bound + gap if lower else bound - gap
            where = "below the lower" if lower else "above the upper"
            raise InputError(f"limit {side.limit!r}: its value {value:.9g} is {where} bound {bound:.9g} at the "
                             "initial state")


def solve_with_limits(solver: Solver, problem: MultibodyProblem, derived_of: Callable) -> Solution:
    """Integrate ``problem`` with ``solver``, segment by segment, through the limits' events (see the
    module docstring); ``derived_of(model, t, y, parameters)`` computes the derived outputs a solver
    leaves out, and the parameters at the outputs under a controller: ``(derived, parameters)``.

    Under a controller (``problem.model`` a :class:`~.controllers.ControlledModel`) every segment's
    model, a contact variant included, is under it; a :class:`~.controllers.Sampled` one keeps its
    schedule, held inputs and state across the segments, and a sample instant that coincides with an
    event (within :data:`~kronlag.numeric.tolerances.SAME_INSTANT`) is taken with the state before
    the event (the impulse follows it)."""
    model, options = problem.model, solver.options
    if has_stiction(model.equations.system) and solver.name not in ("compiled", "projection", "baumgarte"):
        raise InputError(f"method={solver.name!r} does not support exact stiction (friction law 'exact'); use "
                         "'compiled' (the default with friction), 'projection' or 'baumgarte'")
    if solver.name in ("ggl", "dop853"):
        raise InputError(f"method={solver.name!r} does not watch limits; use 'switching' (the default), 'compiled', "
                         "'ali3p', 'baumgarte' or 'projection'")
    check_start(model, problem.q0, problem.t0, options.atol)
    run = _LimitRun(solver, problem, derived_of)
    return run.solve()


class _LimitRun:
    """The state of one run with limits: the sides held, the segments and the events so far."""

    def __init__(self, solver: Solver, problem: MultibodyProblem, derived_of):
        self.solver, self.problem, self.derived_of = solver, problem, derived_of
        self.model, self.options = problem.model, solver.options
        self.kernels: LimitKernels = limit_kernels(self.model.equations.system)
        self.active: tuple[int, ...] = ()
        self.events: list = []
        self.intervals: list = []
        self.pieces: list[dict[str, np.ndarray]] = []
        self.segments: list[Segment] = []
        self._last_impulses: dict[int, float] = {}
        self.first_step = 0.0
        self.loop = self.model.loop if isinstance(self.model, ControlledModel) else None
        system = self.model.equations.system
        self.friction_names = [joint.name for joint in friction_joints(system)]
        self.stiction = has_stiction(system)
        self.modes: tuple[int, ...] = ()

    def _variant_of(self, modes: tuple[int, ...]) -> NumericModel:
        """A segment's model with the joints' friction in ``modes`` and the current contacts held."""
        return contact_model(stiction_model(self.model, modes), self.active)

    @property
    def base(self) -> NumericModel:
        """The model with the joints' friction in their current modes (:func:`~.stiction.stiction_model`)."""
        return stiction_model(self.model, self.modes)

    def solve(self) -> Solution:
        problem, m, n = self.problem, self.problem.m, len(self.kernels)
        t, y = problem.t0, problem.y0
        y = self._start(t, y)
        steps = nfev = njev = 0
        same_time, last_t = 0, None
        while True:
            if self.stiction and self.active:
                check_not_stopped_by_contacts(self.model, contact_model(self.model, self.active), t, y,
                                              [self.kernels.names[i] for i in self.active])
            variant = contact_model(self.base, self.active)
            watch = LimitWatch(self.kernels, np.array([i not in self.active for i in range(n)]),
                               tuple(range(self.model.r, variant.r)), self.first_step,
                               None if variant.time_varying else variant.parameter_vector(t),
                               len(self.friction_names), AT_REST * self.options.atol if self.stiction else 0.0)
            self.first_step = 0.0
            t_eval = problem.t_eval
            if t_eval is not None and t > problem.t0:
                t_eval = t_eval[t_eval > t]
            keep = t_eval is None or len(t_eval) > 0
            segment = replace(problem, model=variant, t0=t, q0=y[:m], qd0=y[m:], watch=watch,
                              t_eval=t_eval if keep else None)
            budget = replace(self.options, max_steps=max(self.options.max_steps - steps, 0))
            solution = self._segment(type(self.solver)(budget), segment)
            steps, nfev, njev = steps + solution.steps, nfev + solution.nfev, njev + solution.njev
            self.events += solution.events
            self.intervals += solution.intervals
            for piece, model, start, end in self._pieces(solution, variant, (t, y.copy())):
                if keep and len(piece.t):
                    self._keep(piece, model)
                self.segments.append(Segment(model.uncontrolled if isinstance(model, ControlledModel) else model,
                                             len(piece.t) if keep else 0, start, end))
            if solution.result is not Result.LIMIT or solution.stop is None:
                return self._solution(solution.result, solution.message, steps, nfev, njev)
            same_time = same_time + 1 if last_t is not None and solution.stop.t <= last_t else 0
            last_t = solution.stop.t
            if same_time > _MAX_EVENTS_AT_ONE_TIME:
                return self._solution(Result.SOLVER_FAILED, f"Integration failed at t = {last_t:.6g}: the limits' "
                                      f"events do not let time advance ({same_time} at this instant)",
                                      steps, nfev, njev)
            if not self._sample_at(solution.stop.t, solution.stop.y):  # the sampled controller raised
                stop = self.options.control.stop()
                assert stop is not None  # _sample_at recorded the controller's error
                return self._solution(stop, stopped_text(solution.stop.t, stop), steps, nfev, njev)
            t, y = solution.stop.t, self._events(solution.stop.t, solution.stop.y, solution.stop.triggered)

    def _pieces(self, solution: Solution, variant: NumericModel, start: tuple[float, np.ndarray]):
        """The pieces of a segment's ``solution`` (which began at ``start`` with the model ``variant``) between
        the sliding directions its driver turned itself (:attr:`~.problem.Solution.turns`): ``(outputs, model,
        start, end)`` each, the modes and events updated at each turn as :func:`~.stiction.transition` does at
        a kinematic dead point ('reverse', no force).  One piece without turns."""
        m = self.problem.m
        first, turns = 0, solution.turns if solution.turns is not None else np.empty((0, 2 + 4 * m))
        for t_turn in np.unique(turns[:, 0]):
            rows = turns[turns[:, 0] == t_turn]
            before, after = rows[0, 2:2 + 2 * m].copy(), rows[0, 2 + 2 * m:].copy()
            end = first + int(np.searchsorted(solution.t[first:], t_turn))
            end += end < len(solution.t) and solution.t[end] == t_turn  # an output at the turn: the old side's
            yield _rows(solution, first, end), variant, start, (float(t_turn), before)
            modes = list(self.modes)
            for j in rows[:, 1].astype(int):
                modes[j] = -modes[j]
                self.events.append(StictionEvent(t=float(t_turn), joint=self.friction_names[j], kind="reverse",
                                                 q=before[:m].copy()))
            self.modes = tuple(modes)
            variant, start, first = contact_model(self.base, self.active), (float(t_turn), after), end
        stop = solution.stop
        yield _rows(solution, first, len(solution.t)), variant, start, None if stop is None else (stop.t, stop.y.copy())

    def _segment(self, solver: Solver, segment: MultibodyProblem) -> Solution:
        """One segment by ``solver``; under a sampled controller that the solver cannot stop at itself,
        sample by sample (:func:`~.controllers.solve_sampled`)."""
        if self.loop is None or not self.loop.sampled or solver.samples_inside:
            return solver.solve(segment)
        return solve_sampled(solver, segment, self.loop)

    def _sample_at(self, t: float, y: np.ndarray) -> bool:
        """Under a sampled controller, at an event at ``t``: the sample due at ``t`` (within
        :data:`~kronlag.numeric.tolerances.SAME_INSTANT`, not yet taken by the segment) is taken with the
        state before the event, as the compiled drivers take a sample at a root.  False if the controller
        raised (recorded in the run control)."""
        loop, m = self.loop, self.problem.m
        if loop is None or not loop.sampled:
            return True
        due = loop.next_sample()
        if due > t + SAME_INSTANT * max(1.0, abs(t)) or due >= self.problem.t1:
            return True
        try:
            loop.sample(due, y[:m].copy(), y[m:].copy())
        except (Exception, KeyboardInterrupt) as error:  # noqa: BLE001 - simulate raises it
            self.options.control.record(error)
            return False
        return True

    # -- events ------------------------------------------------------------------------------

    def _start(self, t: float, y: np.ndarray) -> np.ndarray:
        """The sides in contact at the start (gap within :data:`CONTACT_GAP` ``atol``) treated as impacts;
        the joints' friction modes by the start rule of :mod:`.stiction`."""
        if self.friction_names:
            self.modes, events = start_modes(self.model, self._variant_of, t, y, self.options.atol)
            self.events += events
            y = self._project(t, y)
        if not len(self.kernels):
            return y
        gaps = self.kernels.gap(y[:self.problem.m], self.model.parameter_vector(t))
        touching = tuple(int(i) for i in np.flatnonzero(gaps <= CONTACT_GAP * self.options.atol))
        return self._events(t, y, touching) if touching else y

    def _events(self, t: float, y: np.ndarray, triggered: tuple[int, ...]) -> np.ndarray:
        """Apply the events ``triggered`` (indices of the watched functions) at ``(t, y)``; the state after."""
        n, m = len(self.kernels), self.problem.m
        joints = [k - n - len(self.active) for k in triggered if k >= n + len(self.active)]
        if joints:
            y = self._stiction(t, y, joints)
            triggered = tuple(k for k in triggered if k < n + len(self.active))
        released = [self.active[k - n] for k in triggered if k >= n]
        for i in released:
            self.events.append(LimitEvent(t=t, side=self.kernels.names[i], kind="release", q=y[:m].copy()))
        self.active = tuple(i for i in self.active if i not in released)
        impacting = [i for i in triggered if i < n and i not in self.active]
        if not impacting:
            return self._project(t, y)
        # on the stops exactly (the root's state is off them by the root's tolerance or an
        # interpolation's error): a gap left below zero would hide the next crossing
        touching = contact_model(self.base, tuple(sorted(set(self.active) | set(impacting))))
        q = project_positions(touching, y[:m], t, tol=self.options.projection_tol).q
        y = self._project(t, np.concatenate([q, y[m:]]))
        q, qd = y[:m], y[m:]
        values = self.kernels.evaluate(q, qd, self.model.parameter_vector(t))
        J, e = values["J"], values["restitution"]
        before = J[impacting] @ qd
        closing = [i for i, speed in zip(impacting, before) if speed < 0]
        qd_after = self._impulse(t, q, qd, closing, J, e) if closing else qd
        # the Zeno rule: a rebound that lifts the gap by at most RESTING_GAP atol (or none) makes a contact
        free = contact_model(self.base, self.active).forward_dynamics(q, qd_after, t)
        acceleration = J @ free.qdd + values["gamma"]
        rest_height = RESTING_GAP * self.options.atol
        resting = [i for i in impacting
                   if acceleration[i] < 0 and (J[i] @ qd_after) ** 2 <= 2 * -acceleration[i] * rest_height]
        if resting:
            zero = e.copy()
            zero[resting] = 0.0
            qd_after = self._impulse(t, q, qd, [i for i in impacting if J[i] @ qd < 0 or i in resting], J, zero)
        impulses = self._last_impulses
        flights = [2 * (J[i] @ qd_after) / -acceleration[i] for i in impacting
                   if i not in resting and acceleration[i] < 0 and J[i] @ qd_after > 0]
        self.first_step = 0.25 * min(flights) if flights else 0.0
        for i, speed in zip(impacting, before):
            if speed < 0:
                self.events.append(LimitEvent(t=t, side=self.kernels.names[i], kind="impact", q=q.copy(),
                                              impulse=impulses.get(i, 0.0), speed_before=float(speed),
                                              speed_after=float(J[i] @ qd_after)))
        if resting:
            held = tuple(sorted(set(self.active) | set(resting)))
            lam = contact_model(self.base, held).forward_dynamics(q, qd_after, t).lam
            forces = {i: float(-lam[self.model.r + k]) for k, i in enumerate(held)}
            resting = [i for i in resting if forces[i] > 0]  # a contact that would pull is not held
            self.active = tuple(sorted(set(self.active) | set(resting)))
            for i in resting:
                speed = float(before[impacting.index(i)])
                threshold = np.sqrt(2 * -acceleration[i] * rest_height)
                reason = (f"rebound speed {-e[i] * speed:.3g} <= {threshold:.3g}, a rebound height <= "
                          f"{RESTING_GAP:g} atol" if speed < 0 else "on the stop and pressed against it")
                self.events.append(LimitEvent(t=t, side=self.kernels.names[i], kind="contact", q=q.copy(),
                                              force=forces[i], reason=reason))
        if self.stiction:  # the impulse may have turned a sliding joint's rate
            self.modes, events = after_impulse(self._variant_of, self.modes, t, np.concatenate([q, qd_after]),
                                               self.friction_names, AT_REST * self.options.atol)
            self.events += events
        return self._project(t, np.concatenate([q, qd_after]))

    def _stiction(self, t: float, y: np.ndarray, joints: list[int]) -> np.ndarray:
        """The transitions of the joints with friction ``joints`` (their functions fell through zero) at
        ``(t, y)`` (:mod:`.stiction`); the state after, on the new modes' constraints."""
        self.modes, events = transition(self._variant_of, self.modes, joints, t, y, self.friction_names,
                                        AT_REST * self.options.atol)
        self.events += events
        return self._project(t, y)

    def _impulse(self, t: float, q: np.ndarray, qd: np.ndarray, sides: list[int], J: np.ndarray,
                 restitution: np.ndarray) -> np.ndarray:
        """``qd+`` after the impulse on ``sides`` (see the module docstring); the impulses by side are
        kept in ``_last_impulses`` (positive: pushing the gap open)."""
        model = contact_model(self.base, self.active)
        terms = model.dynamics_terms(q, qd, t)
        B = np.vstack([terms["Phi_q"].reshape(-1, len(q)), terms["A"].reshape(-1, len(q))])
        rows = J[sides]
        m, k, c = len(q), B.shape[0], len(sides)
        matrix = np.zeros((m + k + c, m + k + c))
        matrix[:m, :m] = terms["M"]
        matrix[:m, m:m + k], matrix[m:m + k, :m] = B.T, B
        matrix[:m, m + k:], matrix[m + k:, :m] = rows.T, rows
        right = np.zeros(m + k + c)
        right[m + k:] = -(1 + restitution[sides]) * (rows @ qd)
        # least squares: redundant constraint rows leave the matrix singular but the velocities determined
        solution = np.linalg.lstsq(matrix, right, rcond=None)[0]
        self._last_impulses = {i: float(-solution[m + k + j]) for j, i in enumerate(sides)}
        return qd + solution[:m]

    def _project(self, t: float, y: np.ndarray) -> np.ndarray:
        """``y`` projected onto the constraints of the current contact set."""
        held = replace(self.problem, model=contact_model(self.base, self.active), watch=None)
        return held.project(t, y, self.options.projection_tol)

    # -- outputs -------------------------------------------------------------------------------

    def _keep(self, solution: Solution, variant: NumericModel) -> None:
        """The outputs of a segment with the contact rows taken out of the multipliers and residuals
        (they go to ``limit_forces``)."""
        r, s = self.model.r, self.model.s
        derived, parameters = solution.derived, solution.parameters
        if derived is None:
            derived, parameters = self.derived_of(variant, solution.t, solution.y, parameters)
        held = variant.r - r
        forces = np.zeros((len(solution.t), len(self.kernels)))
        for k, i in enumerate(self.active):
            forces[:, i] = -derived["lam"][:, r + k]
        velocity = derived["velocity_residual"]
        piece = dict(derived, lam=derived["lam"][:, :r], position_residual=derived["position_residual"][:, :r],
                     velocity_residual=np.concatenate([velocity[:, :r], velocity[:, r + held:r + held + s]], axis=1),
                     mu=derived["mu"][:, :s], limit_forces=forces, t=solution.t, y=solution.y)
        if self.stiction:  # the holding forces of the joints that stick, rows after the model's own
            piece["friction_held"] = held_forces(variant, s, self.modes, derived["mu"])
        if not len(self.kernels):
            del piece["limit_forces"]
        if parameters is not None:  # under a controller: the inputs at the outputs
            piece["parameters"] = parameters
        self.pieces.append(piece)

    def _empty(self) -> dict[str, np.ndarray]:
        """The outputs of a run that ended before its first output."""
        m, r, s = self.model.shape
        empty = {**{name: np.empty(shape) for name, shape in derived_shapes(0, m, r, s).items()},
                 "limit_forces": np.empty((0, len(self.kernels))), "t": np.empty(0), "y": np.empty((0, 2 * m))}
        if self.loop is not None:
            empty["parameters"] = np.empty((0, len(self.model.parameter_names)))
        if self.stiction:
            empty["friction_held"] = np.empty((0, len(self.friction_names)))
        if not len(self.kernels):
            del empty["limit_forces"]
        return empty

    def _solution(self, result: Result, message: str, steps: int, nfev: int, njev: int) -> Solution:
        pieces = self.pieces or [self._empty()]
        joined = {key: np.concatenate([piece[key] for piece in pieces]) for key in pieces[0]}
        t, y, parameters = joined.pop("t"), joined.pop("y"), joined.pop("parameters", None)
        events = tuple(sorted(self.events, key=lambda event: event.t))
        return Solution(t=t, y=y, result=result, message=message, nfev=nfev, njev=njev, steps=steps,
                        derived=joined, events=events, parameters=parameters, intervals=tuple(self.intervals),
                        segments=tuple(self.segments))


def _rows(solution: Solution, first: int, end: int) -> Solution:
    """``solution`` with its output rows ``first:end`` alone."""
    if first == 0 and end == len(solution.t):
        return solution
    return replace(solution, t=solution.t[first:end], y=solution.y[first:end],
                   derived=None if solution.derived is None else {key: value[first:end]
                                                                  for key, value in solution.derived.items()},
                   parameters=None if solution.parameters is None else solution.parameters[first:end])
