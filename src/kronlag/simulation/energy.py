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
"""

from __future__ import annotations

import numpy as np

from ..numeric.friction import friction_columns, friction_joints

__all__ = ["friction_work", "nonconservative_work"]


def _friction_power(model, t: float, q: np.ndarray, qd: np.ndarray) -> float:
    """``Q_f . qd = -sum_j f_j v_j``, the power of the joints' friction (:mod:`kronlag.model.friction`)."""
    if not friction_joints(model.equations.system):
        return 0.0
    lam = model.forward_dynamics(q, qd, t).lam
    return float(friction_columns(model, t, q, qd, lam)["friction_power"][0])


def _power(model, t: float, q: np.ndarray, qd: np.ndarray) -> float:
    forces = model.f_Q(q, qd, t)
    if model.equations.constraints_do_work:
        result = model.forward_dynamics(q, qd, t)
        forces = forces - model.Phi_q(q, t).T @ result.lam - model.A(q, t).T @ result.mu
    return float(qd @ forces) + _friction_power(model, t, q, qd)


def nonconservative_work(model, t, q, qd, qdd, *, inputs=None) -> np.ndarray:
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
    """
    t = np.asarray(t, dtype=float)
    if len(t) == 0:
        return np.zeros(0)
    if inputs:
        power, rate = _controlled_power(model, t, q, qd, qdd, inputs)
        return _integrated(t, power, rate)
    return _work(_power, model, t, q, qd, qdd)


def friction_work(model, t, q, qd, qdd) -> np.ndarray:
    """The work of the joints' friction ``integral Q_f . qd dt`` from ``t[0]`` (<= 0 but for a preload
    pushing a joint along), by the rule of :func:`nonconservative_work`, shape (N,); zeros without friction."""
    t = np.asarray(t, dtype=float)
    if len(t) == 0 or not friction_joints(model.equations.system):
        return np.zeros(len(t))
    return _work(_friction_power, model, t, q, qd, qdd)


def _work(power_of, model, t: np.ndarray, q, qd, qdd) -> np.ndarray:
    """``integral power_of(model, t, q, qd) dt`` over the samples (:func:`_integrated`)."""
    power = np.array([power_of(model, *state) for state in zip(t, q, qd)])
    scale = np.max(np.diff(t)) if len(t) > 1 else 1.0
    step = 1e-6 * scale

    def along(k: int, e: float) -> float:
        return power_of(model, t[k] + e, q[k] + e * qd[k], qd[k] + e * qdd[k])

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


def _controlled_power(model, t, q, qd, qdd, inputs) -> tuple[np.ndarray, np.ndarray]:
    """The power and its rate (:func:`nonconservative_work`) with the parameters of each sample."""
    names = list(model.parameter_names)
    index = [names.index(name) for name in inputs]
    values = np.column_stack([inputs[name] for name in inputs])
    base = model.parameter_vector()
    power, rate = np.empty(len(t)), np.empty(len(t))
    scale = np.max(np.diff(t)) if len(t) > 1 else 1.0
    step = 1e-6 * scale
    for k, (time, x, v, a) in enumerate(zip(t, q, qd, qdd)):
        parameters = base.copy()
        parameters[index] = values[k]
        held = model.with_parameters(dict(zip(names, parameters)))
        power[k] = _power(held, time, x, v)
        rate[k] = (_power(held, time + step, x + step * v, v + step * a)
                   - _power(held, time - step, x - step * v, v - step * a)) / (2 * step)
    return power, rate
