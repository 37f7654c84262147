"""Exact stiction (``Friction(law="exact")``): joints that slide, stick and slip during a run.

A run of a model with the exact law is a sequence of segments, like a run with limits (it is driven
by the same loop, :mod:`.impacts`).  Within a segment each such joint has a *mode*:

* **sliding** in the direction ``d = +-1``: its friction is ``r mu(v) N d + c v`` (``mu`` with the
  Stribeck term when a ``stribeck_velocity`` is given; ``N`` from the reactions solved with ``qdd``),
  ``d`` fixed for the segment so that the right-hand side stays smooth where ``v`` passes zero; the
  watched function is ``d v``;
* **held** (stuck): the constraint ``v = J_rate qd = 0`` is a nonholonomic row of the segment's model,
  whose multiplier is the friction force ``f``; the watched function is ``r mu_s N - |f|`` (``N`` from
  the reactions of that solve).

Where one falls through zero (root finding to the integrator's tolerance, as for the limits):

* a sliding joint's rate reached zero: held, if the holding force then satisfies ``|f| <= r mu_s N``
  (event ``stick``), else it slides on in the direction of ``f`` (``reverse`` when that is the
  other way: a swing's turning point);
* a held joint's ``|f|`` reached ``r mu_s N``: it slides in the direction of ``f`` (event ``slip``).

The rule at the start: a joint whose rate is within :data:`~kronlag.numeric.tolerances.AT_REST`
``atol`` of zero is at rest and decided as a joint that has just stopped (all such joints held
together: each sticks if its holding force is within ``r mu_s N``, else slides in that force's
direction); any other slides in the direction of its rate.  Joints that stop at one instant are
decided together in the same way, with every sliding joint whose rate the constraints tie to theirs
(:func:`_stopped_with`).  Joints at kinematic dead points are turned inside the compiled run where it is
sure of the decision (``kl_turn`` in ``c/cvode.c``, :meth:`.impacts._LimitRun._pieces`).  A joint whose rate the holds make zero for every allowed motion is
*locked* to them (:data:`MODE_LOCKED`, no force of its own, no events) and its group is decided as a
whole (:func:`_decide`); where that takes dividing the holding force among the group, a run refuses.  Each transition is a :class:`~.trajectory.StictionEvent` in
``trajectory.events``.
"""

from __future__ import annotations

import copy
import weakref
from collections.abc import Callable

import numpy as np

from ..model.friction import (
    MODE_HELD,
    MODE_LOCKED,
    MODE_SMOOTH,
    friction_record,
    stick_constraint_name,
)
from ..numeric.friction import friction_joints, friction_records, sticking_limit
from ..core.errors import NumericalError
from ..numeric.numeric_model import NumericModel
from ..numeric.tolerances import AT_REST, RATE_CHANGE_STEP, TIED_RATIO, matrix_rank
from ..symbolic.derivation import derive
from .controllers import ControlledModel
from .trajectory import StictionEvent

__all__ = ["after_impulse", "check_not_stopped_by_contacts", "held_forces", "start_modes", "stiction_model", "transition"]

_STICTION_EQUATIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_STICTION_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def stiction_model(model: NumericModel, modes: tuple[int, ...]) -> NumericModel:
    """``model`` with its joints with friction in ``modes`` (one per joint, :data:`MODE_SMOOTH` for the
    smooth law; +-1 sliding, :data:`MODE_HELD` held by a nonholonomic row ``"stick <joint>"`` appended
    after its own); derived and compiled once per set of modes.  Under a controller, under the same."""
    if not modes or all(mode == MODE_SMOOTH for mode in modes):
        return model
    if isinstance(model, ControlledModel):
        return ControlledModel.of(stiction_model(model.uncontrolled, modes), model.loop)
    models = _STICTION_MODELS.setdefault(model, {})
    if modes not in models:
        by_modes = _STICTION_EQUATIONS.setdefault(model.equations, {})
        if modes not in by_modes:
            system = model.equations.system
            variant = copy.copy(system)
            variant.nonholonomic_constraints = list(system.nonholonomic_constraints)
            joints = friction_joints(system)
            # read by friction_record (the record's mode field); not an attribute of every System
            variant.__dict__["stiction_modes"] = {joint.name: mode for joint, mode in zip(joints, modes)}
            for joint, mode in zip(joints, modes):
                if mode == MODE_HELD:
                    rate = friction_record(system, joint)[:len(system.coordinates), 0]
                    speed = sum(a * b for a, b in zip(rate, system.speeds))
                    variant.add_nonholonomic_constraint(speed, name=stick_constraint_name(joint.name))
            by_modes[modes] = derive(variant)
        parameters = model.__getstate__()["parameters"]
        models[modes] = NumericModel(by_modes[modes], parameters, backend=model.backend, rank_rtol=model.rank_rtol)
    return models[modes]


def held_forces(model: NumericModel, base_s: int, modes: tuple[int, ...], mu: np.ndarray) -> np.ndarray:
    """The friction force of each joint with friction held in ``modes`` (NaN for the others) from the
    multipliers ``mu`` (N, s) of the segment's model, whose rows past ``base_s`` hold the joints; 0 for a
    joint locked to a held one (its static friction is not needed: the held joint holds the group within its
    own ``r mu_s N``, the rule of :func:`transition`)."""
    forces = np.full((len(mu), len(modes)), np.nan)
    forces[:, [j for j, mode in enumerate(modes) if mode == MODE_LOCKED]] = 0.0
    held = [j for j, mode in enumerate(modes) if mode == MODE_HELD]
    for k, j in enumerate(held):
        forces[:, j] = mu[:, base_s + k]
    return forces


def _holding(variant: NumericModel, t: float, y: np.ndarray) -> list[tuple[float, float]]:
    """Per joint with friction: ``(f, r mu_s N)`` at ``(t, y)`` in the segment model ``variant`` (f: the
    holding force of a held joint, 0 for the others)."""
    m = variant.m
    solution = variant.forward_dynamics(y[:m], y[m:], t)
    nu = np.concatenate([solution.lam, solution.mu])
    records = friction_records(variant, t, y[:m], y[m:])
    return [(float(nu[int(record["hold_row"])]) if record["mode"] == MODE_HELD else 0.0, sticking_limit(record, nu))
            for record in records]


def _dependent(rows: np.ndarray, row: np.ndarray, rank_rtol: float, rank: int | None = None) -> bool:
    """Whether ``row`` is a combination of ``rows`` (the one rank policy); ``rank``: that of ``rows``, when
    known."""
    if rank is None:
        rank = matrix_rank(rows, rank_rtol) if len(rows) else 0
    return matrix_rank(np.vstack([rows, row[None, :]]), rank_rtol) == rank


def check_not_stopped_by_contacts(free: NumericModel, touching: NumericModel, t: float, y: np.ndarray,
                                  contacts: list[str]) -> None:
    """NumericalError when the rate of a joint with exact friction is free in ``free`` (the model without
    contacts) but held at zero by the limit ``contacts`` held in ``touching``: the joint's friction and the
    contact forces then share one direction of motion, and how the load divides between them is
    statically indeterminate.  kronlag does not pick a division (a minimum-norm one can exceed ``r mu_s
    N`` by orders of magnitude without a slip): it stops and says so."""
    m = free.m
    q = y[:m]

    def rows(model: NumericModel) -> np.ndarray:
        return np.vstack([model.Phi_q(q, t).reshape(-1, m), model.A(q, t).reshape(-1, m)])

    free_rows, touching_rows = rows(free), rows(touching)
    joints = friction_joints(free.equations.system)
    for joint, record in zip(joints, friction_records(free, t, q, y[m:])):
        if joint.friction.law == "smooth":
            continue
        J = np.asarray(record["J"], dtype=float)
        if _dependent(touching_rows, J, free.rank_rtol) and not _dependent(free_rows, J, free.rank_rtol):
            raise NumericalError(
                f"exact stiction at t = {t:.9g}, q = {np.array2string(q, precision=6)}: the motion of joint "
                f"{joint.name!r} is stopped by the contact of {', '.join(map(repr, contacts))}, so its friction "
                "and the contact force are statically indeterminate there; kronlag does not divide the load "
                "between them: give this joint Friction(law='smooth'), or put the limit on another motion")


def _rate_changes(model: NumericModel, t: float, y: np.ndarray, now: list[dict]) -> np.ndarray:
    """``dv/dt`` of every joint with friction at ``(t, y)`` in the segment model ``model`` (``now``: its
    records there): the rate one short step along the motion (``v`` is zero where this is asked)."""
    m = model.m
    q, qd = y[:m], y[m:]
    qdd = model.forward_dynamics(q, qd, t).qdd
    step = RATE_CHANGE_STEP * max(1.0, abs(t))
    ahead = friction_records(model, t + step, q + step * qd, qd + step * qdd)
    return np.array([(float(a["J"] @ (qd + step * qdd)) - float(b["J"] @ qd)) / step for a, b in zip(ahead, now)])


def _base_rows(model: NumericModel, modes: tuple[int, ...], t: float, q: np.ndarray) -> np.ndarray:
    """``[Phi_q; A]`` of the segment's model ``model`` in ``modes`` without its holding rows (the last rows of
    ``A``, one per held joint)."""
    m = len(q)
    held = sum(mode == MODE_HELD for mode in modes)
    A = model.A(q, t).reshape(-1, m)
    return np.vstack([model.Phi_q(q, t).reshape(-1, m), A[:len(A) - held]])


def _ratios(base: np.ndarray, holds: list[np.ndarray], row: np.ndarray) -> np.ndarray:
    """The coefficients ``c`` with ``row = sum_h c_h holds[h] + (a combination of base)``: a locked joint's
    rate is ``sum_h c_h v_h`` for every motion the constraints allow (``row`` is such a combination)."""
    columns = np.vstack([base, *[hold[None, :] for hold in holds]]).T
    solution = np.linalg.lstsq(columns, row, rcond=None)[0]
    return solution[len(base):]


def _tied(ratios: np.ndarray) -> list[int]:
    """The holds (indices into ``ratios`` of :func:`_ratios`) a locked joint's rate is tied to."""
    return [k for k, ratio in enumerate(ratios) if abs(ratio) > TIED_RATIO * np.max(np.abs(ratios))]


def _refuse(names: list[str], joints: list[int], t: float, y: np.ndarray, why: str) -> NumericalError:
    m = len(y) // 2
    return NumericalError(
        f"exact stiction at t = {t:.9g}, q = {np.array2string(y[:m], precision=6)}: joints "
        f"{', '.join(repr(names[j]) for j in joints)} are locked together (the rate of one is zero for every "
        f"motion that holding the other allows), {why}; kronlag does not divide the holding force among "
        "them: give these joints Friction(law='smooth')")


def _decide(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: tuple[int, ...], triggered: list[int],
            t: float, y: np.ndarray, names: list[str], rest: float) -> tuple[tuple[int, ...], dict]:
    """The modes after the joints ``triggered`` had their watched functions fall through zero at ``(t, y)``
    (:func:`transition`), and ``(holding force, r mu_s N)`` of the joints decided.

    Locked groups: a joint whose row ``J_rate`` is a combination of the constraints' rows and a held
    joint's row ``J_h`` (``v = c v_h`` for every allowed motion) does not slide while ``h`` is held: it is
    *locked* (:data:`MODE_LOCKED`: no force, no row, not watched).  A group ``h`` + its locked joints sticks
    when ``|f_h| <= r mu_s N`` of ``h`` alone (a division of the hold with zero in the locked joints is
    admissible, so exact), and slides as a whole (each locked joint in the direction ``sign(c) sign(f_h)``)
    when ``|f_h|`` exceeds the group's capacity ``r_h mu_s N_h + sum |c| r mu_s N`` (loads from the
    reactions with ``h`` holding the group).  Between the two, and for a joint locked to several held ones,
    the division of the holding force decides and a run refuses (:class:`NumericalError`)."""
    m = len(y) // 2
    current = variant_of(modes)
    records = friction_records(current, t, y[:m], y[m:])
    rows = [np.asarray(record["J"], dtype=float) for record in records]
    rates = [float(row @ y[m:]) for row in rows]
    base = _base_rows(current, modes, t, y[:m])
    rank_rtol = current.rank_rtol
    new = list(modes)
    found: dict[int, tuple[float, float]] = {}  # (holding force, r mu_s N) by joint, for the events
    # locked to the old holds: with each hold, the rate ratios of the joints locked to it
    old_holds = [j for j, mode in enumerate(modes) if mode == MODE_HELD]
    old_locked = [j for j, mode in enumerate(modes) if mode == MODE_LOCKED]
    slipping = [j for j in triggered if modes[j] == MODE_HELD]  # holding force reached r mu_s N: slide along it
    if slipping:  # (the multipliers cost a forward dynamics: only where a hold is read)
        nu = _multipliers(current, t, y)
        for j in slipping:
            force = float(nu[int(records[j]["hold_row"])])
            new[j] = 1 if force > 0 else -1
            found[j] = (force, sticking_limit(records[j], nu))
            members = []
            for i in old_locked:
                ratios = _ratios(base, [rows[h] for h in old_holds], rows[i])
                if old_holds.index(j) in _tied(ratios):
                    members.append((i, ratios[old_holds.index(j)]))
            if members:  # the hold reached its own capacity; the locked joints' capacity would hold on
                limits = _holding(current, t, y)
                capacity = found[j][1] + sum(abs(ratio) * limits[i][1] for i, ratio in members)
                if abs(force) <= capacity:
                    raise _refuse(names, [j] + [i for i, _ in members], t, y,
                                  f"the holding force {force:.6g} of {names[j]!r} reached its own r mu_s N "
                                  f"{found[j][1]:.6g} but not the group's {capacity:.6g}")
                for i, ratio in members:
                    new[i] = int(np.sign(ratio)) * new[j]
    stopped = [j for j, mode in enumerate(modes) if mode in (1, -1) and (j in triggered or abs(rates[j]) <= rest)]
    base_rank = matrix_rank(base, rank_rtol) if len(base) else 0
    dead = [j for j in stopped if _dependent(base, rows[j], rank_rtol, base_rank)]
    for j in dead:  # kinematic dead points (the constraints alone zero the rate here): the rate passes zero
        new[j] = -modes[j]
    stopped = [j for j in stopped if j not in dead]
    stopped += _stopped_with(base, rows, rates, modes, stopped, dead, rank_rtol, rest)
    stopped.sort(key=lambda j: -_mobility(base, rows[j]))  # the holds: the freest joints first (_mobility)
    if stopped:  # held together, each group by its own hold (module docstring, and above)
        holds = [j for j, mode in enumerate(new) if mode == MODE_HELD]
        locked = [j for j, mode in enumerate(new) if mode == MODE_LOCKED]
        new_holds = []
        for j in stopped:
            held_rows = np.vstack([base, *[rows[h][None, :] for h in holds]])
            if _dependent(held_rows, rows[j], rank_rtol):
                locked.append(j)
            else:
                holds.append(j)
                new_holds.append(j)
        trial = tuple(MODE_HELD if j in holds else MODE_LOCKED if j in locked else mode for j, mode in enumerate(new))
        holding = _holding(variant_of(trial), t, y)
        groups: dict[int, list[tuple[int, float]]] = {h: [] for h in new_holds}
        for i in locked:
            if i not in stopped:
                continue
            ratios = _ratios(base, [rows[h] for h in holds], rows[i])
            tied = [holds[k] for k in _tied(ratios)]
            if len(tied) != 1 or tied[0] not in groups:  # several holds, or one decided before it stopped
                raise _refuse(names, [i] + tied, t, y, f"the rate of {names[i]!r} is tied to held joints "
                              "that do not stop with it alone")
            groups[tied[0]].append((i, float(ratios[holds.index(tied[0])])))
        for h, members in groups.items():
            force, threshold = found[h] = holding[h]
            capacity = threshold + sum(abs(ratio) * holding[i][1] for i, ratio in members)
            holder = _holder(variant_of, trial, h, [i for i, _ in members], holding, t, y)
            if holder is not None:
                for i in [h] + [i for i, _ in members]:
                    new[i], found[i] = (MODE_HELD, holder[1]) if i == holder[0] else (MODE_LOCKED, (0.0, holder[2][i][1]))
            elif abs(force) > capacity and _slides_as_whole(variant_of, trial, h, members, force, t, y):
                new[h] = 1 if force > 0 else -1
                for i, ratio in members:
                    new[i], found[i] = int(np.sign(ratio)) * new[h], holding[i]
            else:
                raise _refuse(names, [h] + [i for i, _ in members], t, y,
                              f"the holding force {force:.6g} of {names[h]!r} exceeds its own r mu_s N "
                              f"{threshold:.6g} but not surely the group's ({capacity:.6g} with the loads "
                              "without the others' friction)")
    return tuple(_consistent(variant_of, new, t, y, rest, names)), found


def _mobility(base: np.ndarray, row: np.ndarray) -> float:
    """The norm of ``row``'s part outside the row space of ``base``: how fast the joint's rate goes for a unit
    allowed motion.  The joints that stop together are held in decreasing order of it, so that a locked
    group's hold is its freest joint (rate ratios of the others at most about 1: the group's capacity read
    with a good leverage), whichever of them the root finder flagged first (a joint near its own dead point
    as the hold needs a holding force of the order of 1 / its rate, and the capacity read from it is as
    far off)."""
    if not len(base):
        return float(np.linalg.norm(row))
    coefficients = np.linalg.lstsq(base.T, row, rcond=None)[0]
    return float(np.linalg.norm(row - base.T @ coefficients))


def _stopped_with(base: np.ndarray, rows: list[np.ndarray], rates: list[float], modes: tuple[int, ...],
                  stopped: list[int], dead: list[int], rank_rtol: float, rest: float) -> list[int]:
    """The sliding joints (not in ``stopped`` or ``dead``) that the joints ``stopped`` and the holds stop too:
    a joint whose row is a combination of the constraints' rows and theirs (``v = sum_k c_k v_k`` plus the
    rate the constraints themselves impose, e.g. a drive's) has the rate ``v - sum_k c_k v_k`` when they stand
    still, zero (within ``rest``) for a linkage without drives.  Such a joint stops with them, whatever its
    own residual rate ``v`` (of the order of theirs, ``c_k`` times the root's rounding, on either side of the
    at-rest limit): it is decided with them (held or locked), not left sliding at a rate zero by the
    constraints, which made the decision hang on the last bits of ``v``."""
    anchors = [j for j, mode in enumerate(modes) if mode == MODE_HELD] + stopped
    if not stopped:
        return []
    found = []
    for i, mode in enumerate(modes):
        if mode not in (1, -1) or i in stopped or i in dead:
            continue
        held_rows = np.vstack([base, *[rows[k][None, :] for k in anchors]])
        if not _dependent(held_rows, rows[i], rank_rtol):
            continue
        ratios = _ratios(base, [rows[k] for k in anchors], rows[i])
        if abs(rates[i] - sum(c * rates[k] for c, k in zip(ratios, anchors))) <= rest:
            found.append(i)
    return found


def _slides_as_whole(variant_of: Callable[[tuple[int, ...]], NumericModel], trial: tuple[int, ...], hold: int,
                     members: list[tuple[int, float]], force: float, t: float, y: np.ndarray) -> bool:
    """Whether the group ``hold`` + ``members`` (joint, rate ratio) cannot stick even with every locked joint
    at its full static friction against the motion that would start: ``hold`` held in a model where the
    members slide that way (their ``r mu_k N`` and the loads it causes solved together, the friction
    fixed point) still needs more than its own ``r mu_s N`` plus the members' spare ``r (mu_s - mu_k) N``.
    (The group's capacity from the loads without the members' friction is the first estimate; this one
    counts how their friction changes the loads, so both must agree for a slip.)"""
    m = len(y) // 2
    sign = 1 if force > 0 else -1
    modes = list(trial)
    for i, ratio in members:
        modes[i] = int(np.sign(ratio)) * sign
    variant = variant_of(tuple(modes))
    try:
        nu = _multipliers(variant, t, y)
    except NumericalError:
        return False  # no fixed point: not a slip it can vouch for (the caller refuses)
    records = friction_records(variant, t, y[:m], y[m:])
    spare = sum(abs(ratio) * sticking_limit(records[i], nu) * (1 - records[i]["kinetic"] / records[i]["static"])
                for i, ratio in members  # (with a Stribeck term the law already gives mu_s at rest)
                if records[i]["static"] > 0 and records[i]["stribeck_velocity"] <= 0)
    return sign * float(nu[int(records[hold]["hold_row"])]) > sticking_limit(records[hold], nu) + spare


def _holder(variant_of: Callable[[tuple[int, ...]], NumericModel], trial: tuple[int, ...], hold: int,
            members: list[int], holding: list[tuple[float, float]], t: float,
            y: np.ndarray) -> tuple[int, tuple[float, float], list[tuple[float, float]]] | None:
    """A joint of the locked group ``hold`` + ``members`` (``hold`` held in ``trial``, whose ``_holding`` is
    ``holding``) that holds the whole group within its own ``r mu_s N`` with the others free of friction:
    ``(joint, (f, r mu_s N), holding of that trial)``, or None.  (Which joint holds changes the reactions, so
    each is tried in its own segment model.)"""
    for joint in [hold, *members]:
        if joint != hold:
            modes = list(trial)
            modes[hold], modes[joint] = MODE_LOCKED, MODE_HELD
            holding = _holding(variant_of(tuple(modes)), t, y)
        force, threshold = holding[joint]
        if abs(force) <= threshold:
            return joint, (force, threshold), holding
    return None


def transition(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: tuple[int, ...], triggered: list[int],
               t: float, y: np.ndarray, names: list[str], rest: float) -> tuple[tuple[int, ...], list[StictionEvent]]:
    """The modes after the joints ``triggered`` (indices) had their watched functions fall through zero at
    ``(t, y)`` (the module docstring, :func:`_decide`), and the events; ``variant_of(modes)`` is a segment's
    model in ``modes``, ``rest`` the rate below which a joint is at rest."""
    m = len(y) // 2
    new, found = _decide(variant_of, modes, triggered, t, y, names, rest)
    events = []
    for j, (before, after) in enumerate(zip(modes, new)):
        if before == after or {before, after} == {MODE_HELD, MODE_LOCKED}:
            continue
        stuck = (MODE_HELD, MODE_LOCKED)
        kind = "stick" if after in stuck else "slip" if before in stuck else "reverse"
        force, threshold = found.get(j, (0.0, 0.0))
        events.append(StictionEvent(t=t, joint=names[j], kind=kind, q=y[:m].copy(), force=force,
                                    threshold=threshold))
    return tuple(new), events


def after_impulse(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: tuple[int, ...], t: float,
                  y: np.ndarray, names: list[str], rest: float) -> tuple[tuple[int, ...], list[StictionEvent]]:
    """The modes after an impulse (an impact) changed the rates at ``(t, y)``, and the events: a sliding
    joint whose rate now points against its direction reverses (its watched ``d v`` would start below zero
    and never cross it: the friction would push the joint along, feeding energy in), and one left at rest
    is decided as at a stop (:func:`transition`)."""
    m = len(y) // 2
    records = friction_records(variant_of(modes), t, y[:m], y[m:])
    new, events, resting = list(modes), [], []
    for j, (mode, record) in enumerate(zip(modes, records)):
        rate = float(record["J"] @ y[m:])
        if mode not in (1, -1):
            continue
        if abs(rate) <= rest:
            resting.append(j)
        elif mode * rate < 0:
            new[j] = -mode
            events.append(StictionEvent(t=t, joint=names[j], kind="reverse", q=y[:m].copy()))
    if not resting:
        return tuple(new), events
    decided, more = transition(variant_of, tuple(new), resting, t, y, names, rest)
    return decided, events + more


def _multipliers(model: NumericModel, t: float, y: np.ndarray) -> np.ndarray:
    solution = model.forward_dynamics(y[:model.m], y[model.m:], t)
    return np.concatenate([solution.lam, solution.mu])


def _consistent(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: list[int], t: float, y: np.ndarray,
                rest: float, names: list[str]) -> list[int]:
    """``modes`` with every sliding joint at rest made to slide the way its rate then goes: one whose rate
    would grow against its direction slides the other way, and one that would decelerate either way
    sticks (:func:`_check_none_locked_to`).  (Holding forces of redundant holds -- a linkage stopping with
    several joints -- are the minimum-norm ones and may point a joint the wrong way: this corrects the
    direction.)"""
    m = len(y) // 2
    modes = list(modes)
    flipped: set[int] = set()
    for _ in range(2 * len(modes) + 1):
        model = variant_of(tuple(modes))
        records = friction_records(model, t, y[:m], y[m:])
        changes = _rate_changes(model, t, y, records)
        wrong = [j for j, (mode, record) in enumerate(zip(modes, records))
                 if mode in (1, -1) and abs(float(record["J"] @ y[m:])) <= rest and mode * changes[j] < 0]
        if not wrong:
            return modes
        j = wrong[0]
        modes[j] = MODE_HELD if j in flipped else -modes[j]
        flipped.add(j)
        if modes[j] == MODE_HELD:
            _check_none_locked_to(variant_of, modes, j, t, y, rest, names)
    return modes


def _check_none_locked_to(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: list[int], hold: int,
                          t: float, y: np.ndarray, rest: float, names: list[str]) -> None:
    """NumericalError when holding ``hold`` (a joint that decelerates whichever way it slides) would lock a
    joint still sliding at rest: that joint's friction was taken as sliding when ``hold`` was judged, so the
    judgement is unsure (the locked groups of :func:`_decide` are decided with the joints' capacities)."""
    m = len(y) // 2
    model = variant_of(tuple(modes))
    rows = [np.asarray(record["J"], dtype=float) for record in friction_records(model, t, y[:m], y[m:])]
    base = _base_rows(model, tuple(modes), t, y[:m])
    held = np.vstack([base, *[rows[h][None, :] for h, mode in enumerate(modes) if mode == MODE_HELD]])
    locked = [i for i, mode in enumerate(modes) if mode in (1, -1) and abs(float(rows[i] @ y[m:])) <= rest
              and not _dependent(base, rows[i], model.rank_rtol) and _dependent(held, rows[i], model.rank_rtol)]
    if locked:
        raise _refuse(names, [hold, *locked], t, y, f"{names[hold]!r} decelerates whichever way it slides and "
                      "would hold the others, whose friction was taken as sliding when it was judged")


def start_modes(model: NumericModel, variant_of: Callable[[tuple[int, ...]], NumericModel], t: float,
                y: np.ndarray, atol: float) -> tuple[tuple[int, ...], list[StictionEvent]]:
    """The modes at the start (the rule of the module docstring) and the events of the joints at rest."""
    system = model.equations.system
    joints = friction_joints(system)
    m = model.m
    records = friction_records(model, t, y[:m], y[m:])
    modes = []
    for joint, record in zip(joints, records):
        rate = float(record["J"] @ y[m:])
        modes.append(MODE_SMOOTH if joint.friction.law == "smooth" else 1 if rate >= 0 else -1)
    names = [joint.name for joint in joints]
    rest = AT_REST * atol
    resting = [j for j, record in enumerate(records) if modes[j] != MODE_SMOOTH and abs(float(record["J"] @ y[m:])) <= rest]
    if not resting:
        return tuple(modes), []
    new, found = _decide(variant_of, tuple(modes), resting, t, y, names, rest)
    # at rest at the start: a joint that slides slips, one that is held sticks (whatever direction it was given)
    events = []
    for j in resting:
        force, threshold = found.get(j, (0.0, 0.0))
        events.append(StictionEvent(t=t, joint=names[j], kind="stick" if new[j] in (MODE_HELD, MODE_LOCKED) else "slip",
                                    q=y[:m].copy(), force=force, threshold=threshold))
    return new, events
