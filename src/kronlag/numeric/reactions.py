"""Named joint reactions: the multipliers of a joint turned into a force and a couple.

For a joint J between bodies A and B (see :mod:`kronlag.model.joints`) with
multipliers ``lambda_J`` (its rows of ``lambda`` in Eq. 23,
``M qdd + C qd + Phi_q^T lambda + ... = f_Q``)::

    [F; T] = W(q) lambda_J

is the wrench that body A exerts on body B, reduced at B's joint point
``P_B``: the force ``F`` acts at ``P_B`` and ``T`` is the couple (the torque
about ``P_B``).  Body A feels ``-F`` at ``P_B`` and ``-T``.  Components are
in the world frame, or in B's body frame (``R_B^T F``, ``R_B^T T``) with
``frame="body"``.  Planar systems have ``F = (Fx, Fy)`` and ``T = (Mz,)``,
spatial ones ``F = (Fx, Fy, Fz)`` and ``T = (Mx, My, Mz)``.

Units (:data:`REACTION_UNITS`, for a model in SI units as every model file is): a force
component is in ``N``, a couple's in ``N*m``; the multiplier of a joint row is in ``N`` when the
row is a distance (its column of ``W`` has a force) and in ``N*m`` when it is an angle or an
alignment of axes (only a couple), :func:`multiplier_units`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..core.errors import InputError
from ..model.joints import Joint

__all__ = ["Reaction", "joint_reaction", "reaction_columns", "REACTION_UNITS", "column_unit", "multiplier_units",
           "multiplier_labels", "GENERALIZED_FORCE_UNITS"]

#: SI units of a reaction's force and couple components.
REACTION_UNITS = {"force": "N", "couple": "N*m"}

#: The unit of a generalized force on a coordinate of the unit given (a drive's multiplier).
GENERALIZED_FORCE_UNITS = {"rad": REACTION_UNITS["couple"], "m": REACTION_UNITS["force"]}

_FRAMES = ("world", "body")


@dataclass(frozen=True, eq=False)
class Reaction:
    """The reaction of joint ``name``: the wrench body A exerts on body B.

    Attributes
    ----------
    name : str
    frame : {"world", "body"}
        Components in the world frame or in B's body frame.
    force : (N, d)
        ``F``, acting at ``point``.
    torque : (N, 1) planar or (N, 3) spatial
        ``T``, the couple (torque about ``point``).
    point : (N, d)
        ``P_B``, B's joint point, world coordinates.
    """

    name: str
    frame: str
    force: np.ndarray
    torque: np.ndarray
    point: np.ndarray


def _joint(system, name: str) -> Joint:
    for joint in system.joints:
        if joint.name == name:
            return joint
    known = ", ".join(joint.name for joint in system.joints) or "the system has none"
    raise KeyError(f"no joint named {name!r} (joints: {known})")


def _expressions(joint: Joint) -> dict[str, sp.MatrixBase]:
    return {"W": joint.wrench, "P": joint.point, "R": joint.rotation_b}


def joint_reaction(model, name: str, t, q, lam, *, frame: str = "world") -> Reaction:
    """The reaction of joint ``name`` along a motion (time along the first axis).

    Parameters
    ----------
    model : NumericModel
    name : str
        A joint of ``model.equations.system``.
    t : (N,)
    q : (N, m)
    lam : (N, r)
        The multipliers of Eq. 23 at those states.
    frame : {"world", "body"}

    Returns
    -------
    Reaction
    """
    if frame not in _FRAMES:
        raise InputError(f"frame must be 'world' or 'body', got {frame!r}")
    system = model.equations.system
    joint = _joint(system, name)
    index = {constraint.name: j for j, constraint in enumerate(system.constraints)}
    rows = [index[row] for row in joint.constraint_names]
    t, q, lam = np.atleast_1d(t), np.atleast_2d(q), np.atleast_2d(lam)
    d = joint.dimension
    forces, torques, points = [], [], []
    for time, state, multipliers in zip(t, q, lam):
        values = model.evaluate_expressions(f"joint:{name}", lambda: _expressions(joint), state, t=float(time))
        wrench = values["W"] @ multipliers[rows]
        force, torque = wrench[:d], wrench[d:]
        if frame == "body":
            rotation = values["R"]
            force = rotation.T @ force
            torque = rotation.T @ torque if d == 3 else torque
        forces.append(force)
        torques.append(torque)
        points.append(values["P"][:, 0])
    return Reaction(name, frame, np.array(forces).reshape(len(t), d),
                    np.array(torques).reshape(len(t), 1 if d == 2 else 3), np.array(points).reshape(len(t), d))


def reaction_columns(model, t, q, lam) -> dict[str, np.ndarray]:
    """Export columns of every joint's world-frame reaction: ``<joint>.Fx, .Fy[, .Fz]``,
    ``<joint>.Mz`` (planar) or ``.Mx, .My, .Mz`` (spatial), each of shape (N,)."""
    columns: dict[str, np.ndarray] = {}
    for joint in model.equations.system.joints:
        reaction = joint_reaction(model, joint.name, t, q, lam)
        force_names = "xyz"[:joint.dimension]
        torque_names = "z" if joint.dimension == 2 else "xyz"
        columns.update({f"{joint.name}.F{axis}": reaction.force[:, i] for i, axis in enumerate(force_names)})
        columns.update({f"{joint.name}.M{axis}": reaction.torque[:, i] for i, axis in enumerate(torque_names)})
    return columns


def column_unit(column: str) -> str:
    """The unit of a reaction column of :func:`reaction_columns`: ``REACTION_UNITS["force"]`` for
    ``<joint>.F<axis>``, ``REACTION_UNITS["couple"]`` for ``<joint>.M<axis>``."""
    return REACTION_UNITS["force" if column.rpartition(".")[2].startswith("F") else "couple"]


def multiplier_units(system, coordinate_units: dict[str, str] | None = None) -> dict[str, str]:
    """The unit of each multiplier whose unit is known, by constraint name.

    A joint row's multiplier is in ``N`` when the row's column of the joint's wrench map ``W`` has
    a force component (the row is a distance) and in ``N*m`` when it has only a couple (an angle,
    or an alignment of axes).  A drive of a coordinate whose unit ``coordinate_units`` gives
    (``rad`` or ``m``) has the generalized force on it, ``N*m`` or ``N``.  Other rows are left out.
    """
    units: dict[str, str] = {}
    for joint in system.joints:
        for k, row in enumerate(joint.constraint_names):
            has_force = any(entry != 0 for entry in joint.wrench[:joint.dimension, k])
            units[row] = REACTION_UNITS["force" if has_force else "couple"]
    coordinates = {q: q.name for q in system.coordinates}
    for constraint in system.constraints:
        if constraint.name in system.drives and coordinate_units:
            driven = [name for q, name in coordinates.items() if sp.diff(constraint.expression, q) == 1]
            unit = GENERALIZED_FORCE_UNITS.get(coordinate_units.get(driven[0], "")) if len(driven) == 1 else None
            if unit:
                units[constraint.name] = unit
    return units


def multiplier_labels(system, coordinate_units: dict[str, str] | None = None, *, with_units: bool = True) -> list[str]:
    """A label per holonomic multiplier: ``lambda[<constraint name>]``, with ``(<unit>)`` where
    :func:`multiplier_units` knows it (and ``with_units``)."""
    units = multiplier_units(system, coordinate_units) if with_units else {}
    return [f"lambda[{c.name}]" + (f" ({units[c.name]})" if c.name in units else "") for c in system.constraints]
