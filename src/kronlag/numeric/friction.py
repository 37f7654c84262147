"""Joint friction in forward dynamics: ``(qdd, lambda)`` and the friction forces solved together.

With friction in joints (:mod:`kronlag.model.friction`) the equations of motion gain
``Q_f = -sum_j J_j^T f_j`` where ``f_j = phi_j(lambda, v_j)`` is joint j's friction force or torque,
``v_j = J_j qd`` its rate, and ``phi_j`` grows with the normal load read from ``lambda``.  The
augmented system is linear in its right-hand side ``h``, so with ``(qdd_0, nu_0)`` its solution
without friction and ``(qdd_j, nu_j)`` the change a unit ``f_j`` causes (one more solve each, the
same factorization up to rounding)::

    qdd(f) = qdd_0 + sum_j f_j qdd_j,   nu(f) = nu_0 + sum_j f_j nu_j,   f = phi(lambda(f))

and the small nonlinear system in ``f`` (one unknown per joint with friction) is solved by Newton
steps to :data:`~kronlag.numeric.tolerances.FRICTION_RTOL` at every evaluation (never lagged).  This
module is the Python backend's form and the reference of ``kronlag_friction_solve`` in
``numeric/codegen/c/augmented.c``; both read the records of :func:`kronlag.model.friction.friction_record`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..core.errors import NumericalError
from ..model.friction import (
    MODE_HELD,
    MODE_LOCKED,
    MODE_SIGN,
    MODE_SMOOTH,
    RECORD_FIELDS,
    friction_record,
    record_size,
)
from .tolerances import FRICTION_MAX_ITERATIONS, FRICTION_RTOL

__all__ = [
    "friction_columns",
    "friction_force",
    "friction_joints",
    "friction_kernel_matrices",
    "friction_records",
    "has_stiction",
    "solve_with_friction",
    "sticking_limit",
    "stiction_values",
]


def friction_joints(system) -> list:
    """The joints of ``system`` with friction, in the order added."""
    return [joint for joint in system.joints if joint.friction is not None]


def has_stiction(system) -> bool:
    """Whether a joint of ``system`` has the exact law (``Friction(law="exact")``)."""
    return any(joint.friction.law == "exact" for joint in friction_joints(system))


def friction_kernel_matrices(system) -> dict:
    """``{"friction": (n_f * record_size(m), 1)}``: the records of every joint with friction, stacked."""
    import sympy as sp

    records = [friction_record(system, joint) for joint in friction_joints(system)]
    return {"friction": sp.Matrix.vstack(*records)}


def _split(record: np.ndarray, m: int) -> dict:
    parts = {"J": record[:m], "W": record[m:m + 36].reshape(6, 6), "rows": record[m + 36:m + 42].astype(int),
             "u_force": record[m + 42:m + 45], "u_couple": record[m + 45:m + 48]}
    parts.update(zip(RECORD_FIELDS, record[m + 48:m + 48 + len(RECORD_FIELDS)]))
    return parts


def _perpendicular(vector: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """``vector - (vector . unit) unit``."""
    return vector - (vector @ unit) * unit


def _wrench(record: dict, lam: np.ndarray) -> np.ndarray:
    """The joint's wrench ``W lambda_J`` (6: force, couple)."""
    return record["W"] @ np.array([lam[row] if row >= 0 else 0.0 for row in record["rows"]])


def _load(record: dict, wrench: np.ndarray) -> float:
    """The normal load N from the joint's wrench (module docstring of :mod:`kronlag.model.friction`)."""
    return float(np.linalg.norm(_perpendicular(wrench[:3], record["u_force"])) + record["inverse_arm"]
                 * np.linalg.norm(_perpendicular(wrench[3:], record["u_couple"])) + record["preload"])


def _direction(record: dict, rate: float) -> float:
    """The law's ``sign(v)`` by the record's mode (:data:`~kronlag.model.friction.MODE_SMOOTH` etc.)."""
    mode = record["mode"]
    if mode == MODE_SMOOTH:
        return math.tanh(rate / record["smoothing_velocity"])
    if mode == MODE_SIGN:
        return float(np.sign(rate))
    return mode if mode in (1.0, -1.0) else 0.0  # held or locked: no force of the law


def _factor(record: dict, rate: float) -> float:
    """``r mu(v)``: the factor of the normal load at the rate ``v``."""
    coefficient = record["kinetic"]
    if record["stribeck_velocity"] > 0:
        coefficient += (record["static"] - record["kinetic"]) * math.exp(-(rate / record["stribeck_velocity"]) ** 2)
    return record["radius"] * coefficient * _direction(record, rate)


def _viscous(record: dict, rate: float) -> float:
    """``c v``, none while held or locked (the holding row gives the whole force)."""
    return 0.0 if record["mode"] in (MODE_HELD, MODE_LOCKED) else record["viscous"] * rate


def friction_force(record: dict, lam: np.ndarray, rate: float) -> tuple[float, float]:
    """``(f, N)``: the friction force (torque) of one joint at multipliers ``lam`` and rate ``rate``, and
    its normal load (see :mod:`kronlag.model.friction`)."""
    load = _load(record, _wrench(record, lam))
    return _factor(record, rate) * load + _viscous(record, rate), load


def _load_slope(record: dict, wrench: np.ndarray) -> np.ndarray:
    """``dN / d wrench`` (6): the unit directions of the force's and the couple's parts that count (zero
    where a part vanishes), the couple's over the arm."""
    slope = np.zeros(6)
    for part, unit, weight in ((slice(0, 3), record["u_force"], 1.0), (slice(3, 6), record["u_couple"],
                                                                         record["inverse_arm"])):
        perpendicular = _perpendicular(wrench[part], unit)
        norm = np.linalg.norm(perpendicular)
        if norm > 0:
            slope[part] = weight * perpendicular / norm
    return slope


def _converged(change: float, previous: float, largest: float) -> bool:
    """Whether a Newton step that changed the forces by at most ``change`` (the step before by ``previous``,
    0 for the first) left them within ``FRICTION_RTOL * largest``: the step itself is that small, or the
    error bound from the contraction ``theta = change / previous`` of the last two steps, ``theta / (1 -
    theta) * change`` (exact for linear convergence, an upper bound for Newton's quadratic one), is; the
    second saves the step that would only confirm what the last one found."""
    theta = change / previous if previous > 0.0 else 1.0
    return change <= FRICTION_RTOL * largest or (theta < 1.0 and theta / (1.0 - theta) * change
                                                 <= FRICTION_RTOL * largest)


def solve_with_friction(solve: Callable[[np.ndarray], tuple], flat: np.ndarray, h_offset: int,
                        records: np.ndarray, qd: np.ndarray) -> tuple:
    """Forward dynamics with friction: ``(qdd, lam, mu, rank)`` as ``solve(flat)`` returns them (the
    solve of the dynamics kernel's output ``flat`` without friction), with the friction forces of the
    stacked ``records`` included (module docstring: Newton steps on ``f - phi(lambda(f)) = 0`` from
    ``f = 0``); rank -1 as ``solve`` gives it.  A joint whose force is zero whatever the load (held, or
    ``r mu(v) = 0`` without a viscous term) is no unknown and needs no response."""
    m = len(qd)
    base = solve(flat)
    if base[3] < 0:
        return base
    joints = [_split(record, m) for record in records.reshape(-1, record_size(m))]
    rates = [float(joint["J"] @ qd) for joint in joints]
    active = [(joint, _factor(joint, rate), _viscous(joint, rate)) for joint, rate in zip(joints, rates)]
    active = [(joint, factor, viscous) for joint, factor, viscous in active if factor != 0.0 or viscous != 0.0]
    responses = []
    for joint, _, _ in active:
        shifted = flat.copy()
        shifted[h_offset:h_offset + m] -= joint["J"]
        solution = solve(shifted)
        if solution[3] < 0:
            return solution
        responses.append([after - before for after, before in zip(solution[:3], base[:3])])
    wrenches = [_wrench(joint, base[1]) for joint, _, _ in active]
    unit_wrenches = [[_wrench(joint, response[1]) for response in responses] for joint, _, _ in active]
    forces, previous = np.zeros(len(active)), 0.0
    for _ in range(FRICTION_MAX_ITERATIONS):
        residual, jacobian = np.zeros(len(active)), np.eye(len(active))
        for j, (joint, factor, viscous) in enumerate(active):
            wrench = wrenches[j] + sum(f * unit for f, unit in zip(forces, unit_wrenches[j]))
            residual[j] = forces[j] - factor * _load(joint, wrench) - viscous
            slope = _load_slope(joint, wrench)
            jacobian[j] -= factor * np.array([slope @ unit for unit in unit_wrenches[j]])
        try:
            step = np.linalg.solve(jacobian, residual)
        except np.linalg.LinAlgError:
            break
        forces, change = forces - step, float(np.max(np.abs(step), initial=0.0))
        if _converged(change, previous, float(np.max(np.abs(forces), initial=0.0))):
            qdd, lam, mu = (part + sum(f * response[k] for f, response in zip(forces, responses))
                            for k, part in enumerate(base[:3]))
            return qdd, lam, mu, base[3]
        previous = change
    raise NumericalError(f"the joints' friction forces did not converge in {FRICTION_MAX_ITERATIONS} Newton "
                         "steps (a wedged joint: the friction grows with the load faster than the load allows)")


def friction_records(model, t: float, q: np.ndarray, qd: np.ndarray) -> list[dict]:
    """The records of ``model``'s joints with friction at a state, split into their fields (the kernel
    compiled with the model's dynamics, as its forward dynamics reads them)."""
    flat = model._evaluate("friction", np.asarray(q, dtype=float), np.asarray(qd, dtype=float), float(t))
    return [_split(record, model.m) for record in flat.reshape(-1, record_size(model.m))]


def sticking_limit(record: dict, nu: np.ndarray) -> float:
    """``r mu_s N``: the largest holding force of a joint at the multipliers ``nu`` (``[lambda; mu]``)."""
    return float(record["radius"] * record["static"] * _load(record, _wrench(record, nu)))


def stiction_values(records: list[dict], qd: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """What a run watches per joint with friction (:mod:`kronlag.simulation.stiction`), each positive while
    nothing happens: ``d v`` for a joint sliding in the direction ``d`` (its mode +-1), ``r mu_s N - |f|``
    for a held one (``f`` its holding row's multiplier in ``nu = [lambda; mu]``), 1 otherwise."""
    values = np.ones(len(records))
    for j, record in enumerate(records):
        mode = record["mode"]
        if mode in (1.0, -1.0):
            values[j] = mode * float(record["J"] @ qd)
        elif mode == MODE_HELD:
            values[j] = sticking_limit(record, nu) - abs(float(nu[int(record["hold_row"])]))
    return values


def friction_columns(model, t, q, qd, lam, held: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per joint with friction, along a motion: ``<joint>.friction`` (its friction force or torque, N or
    N*m, acting against its rate), ``<joint>.normal_load`` (N) and ``<joint>.rate`` (rad/s or m/s),
    each (N,); and ``friction_power`` ``Q_f . qd = -sum f v`` (W, <= 0 without preload).  ``held``
    (N, joints with friction): the holding force of a sticking joint (exact law), NaN where it slides."""
    system = model.equations.system
    joints = friction_joints(system)
    t, q, qd, lam = np.atleast_1d(t), np.atleast_2d(q), np.atleast_2d(qd), np.atleast_2d(lam)
    columns = {name: np.zeros(len(t)) for joint in joints
               for name in (f"{joint.name}.friction", f"{joint.name}.normal_load", f"{joint.name}.rate")}
    power = np.zeros(len(t))
    for i, (time, state, speed, multipliers) in enumerate(zip(t, q, qd, lam)):
        for joint, parts in zip(joints, friction_records(model, time, state, speed)):
            rate = float(parts["J"] @ speed)
            force, load = friction_force(parts, multipliers, rate)
            j = joints.index(joint)
            if held is not None and np.isfinite(held[i, j]):
                force = float(held[i, j])
            columns[f"{joint.name}.friction"][i] = force
            columns[f"{joint.name}.normal_load"][i] = load
            columns[f"{joint.name}.rate"][i] = rate
            power[i] -= force * rate
    columns["friction_power"] = power
    return columns
