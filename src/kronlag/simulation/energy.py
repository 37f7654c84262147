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

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..numeric.friction import friction_columns, friction_joints
from ..numeric.numeric_model import NumericModel

__all__ = ["Segment", "friction_work", "nonconservative_work"]


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


#: ``power(k, model, t, q, qd)``: a power at a state, ``k`` the output row whose inputs it uses.
Power = Callable[[int, NumericModel, float, np.ndarray, np.ndarray], float]


def _friction_power(model: NumericModel, t: float, q: np.ndarray, qd: np.ndarray) -> float:
    """``Q_f . qd = -sum_j f_j v_j``, the power of the joints' friction (:mod:`kronlag.model.friction`)
    with the multipliers of ``model`` (a segment's: its held contacts and joints load the joints)."""
    if not friction_joints(model.equations.system):
        return 0.0
    lam = model.forward_dynamics(q, qd, t).lam
    return float(friction_columns(model, t, q, qd, lam)["friction_power"][0])


def _power(model: NumericModel, t: float, q: np.ndarray, qd: np.ndarray) -> float:
    forces = model.f_Q(q, qd, t)
    if model.equations.constraints_do_work:
        result = model.forward_dynamics(q, qd, t)
        forces = forces - model.Phi_q(q, t).T @ result.lam - model.A(q, t).T @ result.mu
    return float(qd @ forces) + _friction_power(model, t, q, qd)


def nonconservative_work(model, t, q, qd, qdd, *, inputs=None, segments: Sequence[Segment] = ()) -> np.ndarray:
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
        Parameter values at the samples set by a controller (``Trajectory.inputs``): the power at
        sample ``k`` uses them (held over the central difference; a sampled controller's jumps
        between samples are not resolved).
    segments : sequence of Segment, optional
        The pieces of a run with events (limits, exact stiction), in order, covering the samples:
        each piece's power with its own model, from its start to its end (module docstring).
        Empty: one piece of ``model``.
    """
    t = np.asarray(t, dtype=float)
    if len(t) == 0:
        return np.zeros(0)
    if inputs:
        names = list(model.parameter_names)
        index = [names.index(name) for name in inputs]
        values = np.column_stack([inputs[name] for name in inputs])
        held: dict[tuple[int, int], NumericModel] = {}

        def controlled(k: int, piece: NumericModel, time: float, x: np.ndarray, v: np.ndarray) -> float:
            if (id(piece), k) not in held:  # the piece's model with the inputs of output k
                parameters = piece.parameter_vector()
                parameters[index] = values[k]
                held.clear()
                held[id(piece), k] = piece.with_parameters(dict(zip(names, parameters)))
            return _power(held[id(piece), k], time, x, v)

        return _segmented_work(controlled, model, t, q, qd, qdd, segments)
    return _segmented_work(lambda k, piece, *state: _power(piece, *state), model, t, q, qd, qdd, segments)


def friction_work(model, t, q, qd, qdd, *, segments: Sequence[Segment] = ()) -> np.ndarray:
    """The work of the joints' friction ``integral Q_f . qd dt`` from ``t[0]`` (<= 0 but for a preload
    pushing a joint along), by the rule of :func:`nonconservative_work`, shape (N,); zeros without friction."""
    t = np.asarray(t, dtype=float)
    if len(t) == 0 or not friction_joints(model.equations.system):
        return np.zeros(len(t))
    return _segmented_work(lambda k, piece, *state: _friction_power(piece, *state), model, t, q, qd, qdd, segments)


def _segmented_work(power_of: Power, model: NumericModel, t: np.ndarray, q, qd, qdd,
                    segments: Sequence[Segment]) -> np.ndarray:
    """``integral P dt`` at the outputs from ``t[0]``, piece by piece (:class:`Segment`): over each piece
    from its start to its end with its model (the start and end added where no output is there, as
    with ``t_eval``), the work carried over from one piece to the next."""
    q, qd, qdd = (np.asarray(x, dtype=float) for x in (q, qd, qdd))
    pieces = segments or (Segment(model, len(t)),)
    if sum(piece.outputs for piece in pieces) != len(t):
        raise ValueError(f"the segments hold {sum(piece.outputs for piece in pieces)} outputs, not {len(t)}")
    work, carried, first = np.empty(len(t)), 0.0, 0
    for piece in pieces:
        last = first + piece.outputs
        rows = list(range(first, last))
        times, states, rates = list(t[first:last]), list(q[first:last]), list(qd[first:last])
        accelerations = list(qdd[first:last])
        lead = piece.start is not None and (not rows or piece.start[0] < t[first])
        tail = piece.end is not None and (not rows or piece.end[0] > t[last - 1])
        for add, where, row in ((lead, 0, min(first, len(t) - 1)), (tail, len(times), max(last - 1, 0))):
            if not add:
                continue
            time, y = piece.start if where == 0 else piece.end
            m = len(y) // 2
            times.insert(where, time)
            states.insert(where, y[:m])
            rates.insert(where, y[m:])
            accelerations.insert(where, piece.model.forward_dynamics(y[:m], y[m:], time).qdd)
            rows.insert(where, row)
        if times:
            local = _work(lambda k, *state: power_of(rows[k], piece.model, *state), np.array(times),
                          np.array(states), np.array(rates), np.array(accelerations))
            work[first:last] = carried + local[int(lead):int(lead) + piece.outputs]
            carried += local[-1]
        first = last
    return work - work[0]


def _work(power_of: Callable[..., float], t: np.ndarray, q, qd, qdd) -> np.ndarray:
    """``integral power_of(k, t, q, qd) dt`` over the samples (:func:`_integrated`), ``k`` the sample."""
    if t[-1] == t[0]:  # a single sample, or a segment of no duration (events at one instant)
        return np.zeros(len(t))
    power = np.array([power_of(k, *state) for k, state in enumerate(zip(t, q, qd))])
    step = 1e-6 * np.max(np.diff(t))

    def along(k: int, e: float) -> float:
        return power_of(k, t[k] + e, q[k] + e * qd[k], qd[k] + e * qdd[k])

    # a segment's end (or start) is a sample repeated at one time (an event: an impact, a joint that
    # sticks or reverses, where the power jumps or has a kink), as are the motion's ends: there the
    # power and its rate come from that segment's side only, extrapolated from two points along the
    # motion (the sample itself may lie on the event's other side by the root's tolerance)
    ends = np.zeros(len(t), dtype=int)
    repeated = np.flatnonzero(np.diff(t) == 0)
    ends[repeated], ends[repeated + 1] = -1, 1
    ends[0], ends[-1] = 1, -1
    rate = np.empty(len(t))
    for k, side in enumerate(ends):
        if side == 0:
            rate[k] = (along(k, step) - along(k, -step)) / (2 * step)
            continue
        near, far = along(k, side * step), along(k, 2 * side * step)
        power[k], rate[k] = 2 * near - far, (far - near) / (side * step)
    return _integrated(t, power, rate)


def _integrated(t: np.ndarray, power: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The cubic Hermite rule over the samples, from 0 at ``t[0]``."""
    h = np.diff(t)
    increments = h / 2 * (power[:-1] + power[1:]) + h ** 2 / 12 * (rate[:-1] - rate[1:])
    return np.concatenate([[0.0], np.cumsum(increments)])
