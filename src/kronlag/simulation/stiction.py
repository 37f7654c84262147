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
decided together in the same way.  Each transition is a :class:`~.trajectory.StictionEvent` in
``trajectory.events``.
"""

from __future__ import annotations

import copy
import weakref
from collections.abc import Callable

import numpy as np

from ..model.friction import MODE_HELD, MODE_SMOOTH, friction_record, stick_constraint_name
from ..numeric.friction import friction_joints, friction_records, sticking_limit
from ..numeric.numeric_model import NumericModel
from ..numeric.tolerances import AT_REST
from ..symbolic.derivation import derive
from .controllers import ControlledModel
from .trajectory import StictionEvent

__all__ = ["stiction_model", "start_modes", "decide", "slip", "held_forces"]

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
            variant.stiction_modes = {joint.name: mode for joint, mode in zip(joints, modes)}
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
    multipliers ``mu`` (N, s) of the segment's model, whose rows past ``base_s`` hold the joints."""
    forces = np.full((len(mu), len(modes)), np.nan)
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


def decide(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: tuple[int, ...], stopped: list[int],
           t: float, y: np.ndarray, names: list[str]) -> tuple[tuple[int, ...], list[StictionEvent]]:
    """The modes after the joints ``stopped`` (indices) reached zero rate at ``(t, y)`` (see the module
    docstring), and the events; ``variant_of(modes)`` is a segment's model in ``modes``."""
    trial = tuple(MODE_HELD if j in stopped else mode for j, mode in enumerate(modes))
    holding = _holding(variant_of(trial), t, y)
    m = len(y) // 2
    modes = list(modes)
    events = []
    for j in stopped:
        force, threshold = holding[j]
        before = modes[j]
        if abs(force) <= threshold:
            modes[j] = MODE_HELD
            events.append(StictionEvent(t=t, joint=names[j], kind="stick", q=y[:m].copy(), force=force,
                                        threshold=threshold))
        else:
            modes[j] = 1 if force > 0 else -1
            if before != modes[j]:
                events.append(StictionEvent(t=t, joint=names[j], kind="slip" if before == MODE_HELD else "reverse",
                                            q=y[:m].copy(), force=force, threshold=threshold))
    return tuple(modes), events


def slip(variant_of: Callable[[tuple[int, ...]], NumericModel], modes: tuple[int, ...], slipping: list[int],
         t: float, y: np.ndarray, names: list[str]) -> tuple[tuple[int, ...], list[StictionEvent]]:
    """The modes after the held joints ``slipping`` reached ``|f| = r mu_s N`` at ``(t, y)``: each slides in
    the direction of its holding force (event ``slip``)."""
    holding = _holding(variant_of(modes), t, y)
    m = len(y) // 2
    modes = list(modes)
    events = []
    for j in slipping:
        force, threshold = holding[j]
        modes[j] = 1 if force > 0 else -1
        events.append(StictionEvent(t=t, joint=names[j], kind="slip", q=y[:m].copy(), force=force,
                                    threshold=threshold))
    return tuple(modes), events


def start_modes(model: NumericModel, variant_of: Callable[[tuple[int, ...]], NumericModel], t: float,
                y: np.ndarray, atol: float) -> tuple[tuple[int, ...], list[StictionEvent]]:
    """The modes at the start (the rule of the module docstring) and the events of the joints at rest."""
    system = model.equations.system
    joints = friction_joints(system)
    m = model.m
    records = friction_records(model, t, y[:m], y[m:])
    modes, resting = [], []
    for j, (joint, record) in enumerate(zip(joints, records)):
        rate = float(record["J"] @ y[m:])
        if joint.friction.law == "smooth":
            modes.append(MODE_SMOOTH)
        elif abs(rate) <= AT_REST * atol:
            modes.append(MODE_HELD)
            resting.append(j)
        else:
            modes.append(1 if rate > 0 else -1)
    if not resting:
        return tuple(modes), []
    return decide(variant_of, tuple(modes), resting, t, y, [joint.name for joint in joints])
