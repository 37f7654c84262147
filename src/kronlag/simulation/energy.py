"""Energy balance along a solution of Eq. 23.

With ``T = 1/2 qd^T M qd`` and the potential ``Pi(q)`` (gravity, springs,
potentials), Eq. 23 gives ``d(T + Pi)/dt = qd^T (f_Q - Phi_q^T lambda - A^T mu)``.
On motions that satisfy ``Phi_q qd + Phi_t = 0`` and ``A qd + b = 0`` the
constraint forces' power is ``lambda^T Phi_t + mu^T b``: zero for scleronomic
constraints, the power of the drives for rheonomic ones.  So::

    E(t) - E(0) = W(t),   W(t) = integral_0^t qd^T (f_Q - Phi_q^T lambda - A^T mu) dt

where ``W`` is the work of the non-conservative forces (applied forces and
torques, dampers, generalized forces, joint friction) and of the drives.  ``E - E(0) - W`` is
the true energy drift of an integration, for driven and damped models as well
as conservative ones.

A run with limits or exact stiction is a sequence of segments (:mod:`.impacts`), each integrated
with its own model: the contacts held as constraints, the sticking joints held by their rows, the
sliding joints' friction in a fixed direction.  The joints' friction depends on the multipliers of
that model (the normal loads), so the work of each segment is computed with the model that was
integrated there (:class:`Segment`), from the state where it began to the state where it ended;
an impact's jump of the kinetic energy is no work, and shows in ``E - E(0) - W`` as the loss it is.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from ..core.errors import KronlagWarning
from ..numeric.friction import friction_columns, friction_joints
from ..numeric.numeric_model import NumericModel
from ..numeric.tolerances import SAME_INSTANT

__all__ = ["Segment", "event_energy", "friction_work", "nonconservative_work"]


@dataclass(frozen=True, eq=False)
class Segment:
    """A piece of a run integrated with one model (:attr:`Trajectory.segments
    <kronlag.simulation.trajectory.Trajectory.segments>`).

    Attributes
    ----------
    model : NumericModel
        The model integrated over the piece (with limits: its held contacts as constraints; with exact
        stiction: its held joints' rows and sliding directions), without a controller.
    outputs : int
        How many consecutive output rows of the trajectory the piece gave (0: none fell in it).
    start : (float, (2 m,)) or None
        ``(t, [q, qd])`` where the piece began (after an event's jump and projection).
    end : (float, (2 m,)) or None
        ``(t, [q, qd])`` where it ended at an event, before the event changed the state; None for the
        run's last piece (it ends at its last output).
    """

    model: NumericModel
    outputs: int
    start: tuple[float, np.ndarray] | None = None
    end: tuple[float, np.ndarray] | None = None


#: ``power(model, t, q, qd)``: a power at N states, ``t`` (N,), ``q`` and ``qd`` (N, m), shape (N,).
Power = Callable[[NumericModel, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
#: ``with_inputs(row, model, t)``: ``model`` with a controller's inputs at time ``t`` as they were set at (or
#: held from) output ``row``.
WithInputs = Callable[[int, NumericModel, float], NumericModel]


def _multipliers(model: NumericModel, t: np.ndarray, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``lambda`` (N, r) and ``mu`` (N, s) at N states in one call; a state the batch could not solve is
    solved alone, so that it raises the error :meth:`NumericModel.forward_dynamics` gives (a singular
    configuration, friction that did not converge) rather than passing NaN on."""
    solved = model.forward_dynamics_batch(q, qd, t)
    for row in np.flatnonzero(solved.rank < 0):
        alone = model.forward_dynamics(q[row], qd[row], float(t[row]))
        solved.lam[row], solved.mu[row] = alone.lam, alone.mu
    return solved.lam, solved.mu


def _friction_power(model: NumericModel, t: np.ndarray, q: np.ndarray, qd: np.ndarray,
                    lam: np.ndarray | None = None) -> np.ndarray:
    """``Q_f . qd = -sum_j f_j v_j``, the power of the joints' friction (:mod:`kronlag.model.friction`)
    with the multipliers ``lam`` of ``model`` (a segment's: its held contacts and joints load the joints)."""
    if not friction_joints(model.equations.system):
        return np.zeros(len(t))
    if lam is None:
        lam = _multipliers(model, t, q, qd)[0]
    return friction_columns(model, t, q, qd, lam)["friction_power"]


def _power(model: NumericModel, t: np.ndarray, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    forces = model.evaluate_batch("f_Q", q, qd, t)
    lam = None
    if model.equations.constraints_do_work:
        lam, mu = _multipliers(model, t, q, qd)
        if model.r:
            forces = forces - np.einsum("nrm,nr->nm", model.evaluate_batch("Phi_q", q, t=t), lam)
        if model.s:
            forces = forces - np.einsum("nsm,ns->nm", model.evaluate_batch("A", q, t=t), mu)
    return np.einsum("nm,nm->n", qd, forces) + _friction_power(model, t, q, qd, lam)


def nonconservative_work(model, t, q, qd, qdd, *, inputs=None, segments: Sequence[Segment] = (),
                         sample_times=None) -> np.ndarray:
    """``W(t_k) = integral_{t_0}^{t_k} P dt`` along a sampled motion, shape (N,).

    The power ``P = qd^T f_Q``, plus that of the constraint forces
    ``-qd^T (Phi_q^T lambda + A^T mu)`` when they do work (drives, ``b != 0``) and that of joint
    friction ``Q_f . qd`` (:func:`friction_work`), is integrated between samples by the cubic
    Hermite rule ``h/2 (P0 + P1) + h^2/12 (P0' - P1')`` (error O(h^5) per
    interval), with ``P' = dP/dt`` by a central difference along the motion
    ``(q + e qd, qd + e qdd, t + e)``.

    Parameters
    ----------
    model : NumericModel
    t : (N,)
    q, qd, qdd : (N, m)
    inputs : dict of str to (N,), optional
        Parameter values at the samples set by a controller (``Trajectory.inputs``).  A continuous
        controller's change along the motion is their rate between the outputs (second-order
        differences); a sampled one's (``sample_times`` given) are held from each sample instant
        to the next, exactly where the instants are outputs (every step is output), and a
        :class:`~kronlag.core.errors.KronlagWarning` says when some are not (``t_eval``).
    segments : sequence of Segment, optional
        The pieces of a run with events (limits, exact stiction), in order, covering the samples:
        each piece's power with its own model, from its start to its end (module docstring).
        Empty: one piece of ``model``.
    sample_times : (S,), optional
        The instants a sampled controller took its samples (``Trajectory.sample_times``).
    """
    t = np.asarray(t, dtype=float)
    if len(t) == 0:
        return np.zeros(0)
    if not inputs:
        return _segmented_work(_power, model, t, q, qd, qdd, segments)
    names = list(model.parameter_names)
    index = [names.index(name) for name in inputs]
    values = np.column_stack([inputs[name] for name in inputs])
    breaks = None if sample_times is None else _sample_rows(t, np.asarray(sample_times, dtype=float))
    rates = _input_rates(t, values, _pieces(model, len(t), segments)) if breaks is None else np.zeros_like(values)

    held: dict[tuple[int, int], NumericModel] = {}  # sampled: the last part's model (its inputs do not vary)

    def with_inputs(row: int, piece: NumericModel, time: float) -> NumericModel:
        if breaks is not None and (id(piece), row) in held:
            return held[id(piece), row]
        parameters = piece.parameter_vector()
        parameters[index] = values[row] + (time - t[row]) * rates[row]
        variant = piece.with_parameters(dict(zip(names, parameters)))
        if breaks is not None:
            held.clear()
            held[id(piece), row] = variant
        return variant

    return _segmented_work(_power, model, t, q, qd, qdd, segments, with_inputs, breaks)


def friction_work(model, t, q, qd, qdd, *, segments: Sequence[Segment] = ()) -> np.ndarray:
    """The work of the joints' friction ``integral Q_f . qd dt`` from ``t[0]`` (<= 0 but for a preload
    pushing a joint along), by the rule of :func:`nonconservative_work`, shape (N,); zeros without friction."""
    t = np.asarray(t, dtype=float)
    if len(t) == 0 or not friction_joints(model.equations.system):
        return np.zeros(len(t))
    return _segmented_work(_friction_power, model, t, q, qd, qdd, segments)


def event_energy(model, t, segments: Sequence[Segment] = ()) -> np.ndarray:
    """The change of the total energy ``E = T + Pi`` at the events of a run (the jump of the state from
    a segment's end to the next one's start: an impact's loss, the rate a sticking joint is held at), summed
    up to each output, shape (N,); zeros for a run without events.  ``E - E0 - W - event_energy`` is the
    integration's own drift."""
    jumps, first = np.zeros(len(t)), 0
    for piece, following in zip(segments, segments[1:]):
        first += piece.outputs
        if piece.end is None or following.start is None:
            continue
        (t_end, before), (t_start, after) = piece.end, following.start
        jumps[first:] += _total_energy(model, t_start, after) - _total_energy(model, t_end, before)
    return jumps


def _total_energy(model: NumericModel, t: float, y: np.ndarray) -> float:
    m = len(y) // 2
    return float(model.kinetic_energy(y[:m], y[m:], t) + model.potential_energy(y[:m], t))


def _pieces(model: NumericModel, outputs: int, segments: Sequence[Segment]) -> Sequence[Segment]:
    pieces = segments or (Segment(model, outputs),)
    if sum(piece.outputs for piece in pieces) != outputs:
        raise ValueError(f"the segments hold {sum(piece.outputs for piece in pieces)} outputs, not {outputs}")
    return pieces


def _input_rates(t: np.ndarray, values: np.ndarray, pieces: Sequence[Segment]) -> np.ndarray:
    """``du/dt`` of a continuous controller's inputs at the outputs: second-order differences over the
    outputs of each piece between events (first-order in a piece of two, zero in a piece of one)."""
    rates, first = np.zeros_like(values), 0
    for piece in pieces:
        last = first + piece.outputs
        # and between outputs repeated at one time (a change of integrator), where the inputs may jump
        cuts = [first, *(first + 1 + np.flatnonzero(np.diff(t[first:last]) == 0)), last]
        for low, high in pairwise(cuts):
            if high - low > 1:
                rates[low:high] = np.gradient(values[low:high], t[low:high], axis=0, edge_order=2 if high - low > 2 else 1)
        first = last
    return rates


def _sample_rows(t: np.ndarray, sample_times: np.ndarray) -> list[int]:
    """The output rows at a sampled controller's sample instants (within :data:`SAME_INSTANT`), where its
    held inputs change; a warning for the instants inside the outputs' span that no output is at."""
    if len(t) < 2:
        return []
    tolerance = SAME_INSTANT * np.maximum(1.0, np.abs(sample_times))
    nearest = np.clip(np.searchsorted(t, sample_times), 1, len(t) - 1)
    closest = np.where(np.abs(t[nearest - 1] - sample_times) <= np.abs(t[nearest] - sample_times),
                       nearest - 1, nearest)
    found = np.abs(t[closest] - sample_times) <= tolerance
    inside = (sample_times > t[0]) & (sample_times < t[-1])
    missed = int(np.count_nonzero(inside & ~found))
    if missed:
        warnings.warn(f"energy balance: {missed} of the controller's sample instants fall between outputs (t_eval), "
                      "where its held inputs jump: the work W is approximate there; output every step (t_eval=None) "
                      "or at the sample instants for an exact balance", KronlagWarning, stacklevel=4)
    return sorted({int(row) for row in closest[found]})


def _segmented_work(power: Power, model: NumericModel, t: np.ndarray, q, qd, qdd, segments: Sequence[Segment],
                    with_inputs: WithInputs | None = None, breaks: Sequence[int] | None = None) -> np.ndarray:
    """``integral P dt`` at the outputs from ``t[0]``, piece by piece (:class:`Segment`): over each piece
    from its start to its end with its model (the start and end added where no output is there, as
    with ``t_eval``), the work carried over from one piece to the next.  ``with_inputs``: a controller's
    inputs at each point; ``breaks``: the output rows where held inputs change (a sampled controller's
    instants), each piece cut there, the inputs of each part those of its first row (and the acceleration
    at its last row the one they gave); None: every row's own inputs."""
    q, qd, qdd = (np.asarray(x, dtype=float) for x in (q, qd, qdd))
    work, carried, first = np.empty(len(t)), 0.0, 0
    for piece in _pieces(model, len(t), segments):
        last = first + piece.outputs
        cuts = [first] + [row for row in breaks or () if first < row < last - 1] + [last - 1]
        for part, (low, high) in enumerate(pairwise(cuts) if piece.outputs > 1 else [(first, last - 1)]):
            rows = list(range(low, high + 1)) if piece.outputs else []
            lead = part == 0 and piece.start is not None and (not rows or piece.start[0] < t[first])
            tail = high == last - 1 and piece.end is not None and (not rows or piece.end[0] > t[last - 1])
            points = [(t[row], q[row], qd[row], qdd[row]) for row in rows]
            if breaks is not None and piece.outputs:
                rows = [low] * len(rows)  # held from the part's first output
                if high in breaks and high > low:  # where the next inputs act: the acceleration of these
                    held = _model_at(with_inputs, low, piece.model, t[high])
                    points[-1] = (*points[-1][:3], held.forward_dynamics(q[high], qd[high], t[high]).qdd)
            for state, at_end, row in ((piece.start if lead else None, False, min(first, len(t) - 1)),
                                       (piece.end if tail else None, True, max(last - 1, 0))):
                if state is not None:
                    time, y = state
                    m = len(y) // 2
                    acting = _model_at(with_inputs, low if breaks is not None else row, piece.model, time)
                    where = len(points) if at_end else 0  # after the start inserted before: in time order
                    points.insert(where, (time, y[:m], y[m:], acting.forward_dynamics(y[:m], y[m:], time).qdd))
                    rows.insert(where, low if breaks is not None else row)
            if points:
                def power_at(time, x, v, rows=rows, model=piece.model):
                    if with_inputs is None:  # one model for the piece: all points in one batch
                        return power(model, time, x, v)
                    return np.array([power(with_inputs(rows[k], model, float(time[k])), time[k:k + 1], x[k:k + 1],
                                           v[k:k + 1])[0] for k in range(len(time))])

                local = _work(power_at, *(np.array(column) for column in zip(*points)))
                count = high - low + 1 if piece.outputs else 0
                work[low:low + count] = carried + local[int(lead):int(lead) + count]
                carried += local[-1]
        first = last
    return work - work[0]


def _model_at(with_inputs: WithInputs | None, row: int, model: NumericModel, time: float) -> NumericModel:
    return model if with_inputs is None else with_inputs(row, model, time)


def _work(power_of: Callable[..., np.ndarray], t: np.ndarray, q, qd, qdd) -> np.ndarray:
    """``integral power_of(t, q, qd) dt`` over the samples (:func:`_integrated`); ``power_of`` gives the
    power at all of them at once (the ``k``-th row at sample ``k``'s inputs)."""
    if t[-1] == t[0]:  # a single sample, or a segment of no duration (events at one instant)
        return np.zeros(len(t))
    power = power_of(t, q, qd)
    step = 1e-6 * np.max(np.diff(t))
    # a segment's end (or start) is a sample repeated at one time (an event: an impact, a joint that
    # sticks or reverses, where the power jumps or has a kink), as are the motion's ends: there the
    # power and its rate come from that segment's side only, extrapolated from two points along the
    # motion (the sample itself may lie on the event's other side by the root's tolerance); elsewhere
    # the rate is a central difference along the motion (q + e qd, qd + e qdd, t + e)
    side = np.zeros(len(t), dtype=int)
    repeated = np.flatnonzero(np.diff(t) == 0)
    side[repeated], side[repeated + 1] = -1, 1
    side[0], side[-1] = 1, -1
    near_step = np.where(side == 0, step, side * step)
    far_step = np.where(side == 0, -step, 2 * side * step)

    def along(e: np.ndarray) -> np.ndarray:
        return power_of(t + e, q + e[:, None] * qd, qd + e[:, None] * qdd)

    near, far = along(near_step), along(far_step)
    inside = side == 0
    rate = np.where(inside, (near - far) / (2 * step), (far - near) / np.where(inside, 1, side * step))
    power = np.where(inside, power, 2 * near - far)
    return _integrated(t, power, rate)


def _integrated(t: np.ndarray, power: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The cubic Hermite rule over the samples, from 0 at ``t[0]``."""
    h = np.diff(t)
    increments = h / 2 * (power[:-1] + power[1:]) + h ** 2 / 12 * (rate[:-1] - rate[1:])
    return np.concatenate([[0.0], np.cumsum(increments)])
