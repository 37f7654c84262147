"""Inverse dynamics: the actuator forces and multipliers of a prescribed motion.

The actuators add ``B u`` to ``f_Q`` in Eq. 23::

    M qdd + C qd + g - f_Q + Phi_q^T lambda + A^T mu = B u

where column ``j`` of ``B`` (m, n_a) selects the actuated coordinate ``j``.  With ``N``
spanning the null space of ``G = [Phi_q; A]`` (the rank policy of :mod:`.tolerances`),
``u`` is the minimum-norm solution of ``N^T B u = N^T (M qdd + C qd + g - f_Q)`` and
``[lambda; mu]`` the minimum-norm solution of ``G^T [lambda; mu] = B u - (M qdd + C qd + g - f_Q)``,
all N states at once (stacked pseudo-inverses, :func:`~kronlag.numeric.linalg.pseudo_inverses`).
:class:`~kronlag.numeric.NumericModel` calls these functions from ``inverse_dynamics`` and
``inverse_dynamics_trajectory``.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import ActuationWarning, InputError
from .friction import friction_joints
from .linalg import pseudo_inverses
from .results import InverseDynamicsResult

if TYPE_CHECKING:
    from .numeric_model import NumericModel

__all__ = ["solve_inverse_dynamics", "constraint_rows", "check_motion"]


def solve_inverse_dynamics(model: NumericModel, t, terms, q, qd, qdd, actuated, constraints, rtol: float,
                      constraint_tol: float) -> InverseDynamicsResult:
    """The stacked solution of :meth:`NumericModel.inverse_dynamics` at N states (``terms``: the
    blocks of the ``"dynamics"`` kernel, :func:`~kronlag.numeric.codegen.layouts.split_terms`, each with a
    leading N)."""
    friction = friction_joints(model.equations.system)
    if friction:  # rather than forces silently without it
        names = ", ".join(joint.name for joint in friction)
        raise InputError(f"inverse dynamics does not include joint friction (joints {names})")
    columns = model.coordinate_indices(list(actuated), "actuated coordinate(s)")
    rows = constraint_rows(model, constraints)
    check_motion(model, t, terms, q, qd, qdd, rows, constraint_tol)
    n = len(t)
    inertial = np.einsum("nij,nj->ni", terms["M"], qdd)
    rhs = inertial - terms["h"]
    G = np.concatenate([terms["Phi_q"][:, rows], terms["A"]], axis=1)
    selection = np.zeros((n, model.m, len(columns)))
    selection[:, columns, range(len(columns))] = 1.0
    # null-space projector of G: P = I - G^+ G, so that P G^T = 0
    G_pinv, G_ranks = pseudo_inverses(G, model.rank_rtol)
    projector = np.eye(model.m) - G_pinv @ G
    reduced = projector @ selection
    reduced_pinv, reduced_ranks = pseudo_inverses(reduced, model.rank_rtol)
    forces = np.einsum("nij,nj->ni", reduced_pinv, np.einsum("nij,nj->ni", projector, rhs))
    excess = np.einsum("nij,nj->ni", selection, forces) - rhs
    multipliers = np.einsum("nji,nj->ni", G_pinv, excess)  # (G^T)^+ = (G^+)^T
    residual = np.linalg.norm(excess - np.einsum("nji,nj->ni", G, multipliers), axis=1)
    scale = np.maximum.reduce([np.linalg.norm(rhs, axis=1), np.linalg.norm(inertial, axis=1),
                               np.linalg.norm(terms["h"], axis=1), np.full(n, 1e-300)])
    violated = np.flatnonzero(residual > rtol * scale)
    degrees = model.m - G_ranks[0] if n else 0
    if len(violated):
        i = violated[0]
        shortage = f"; {len(columns)} actuator(s) for {degrees} degree(s) of freedom" if len(columns) < degrees else ""
        raise InputError(f"the actuators {list(actuated)} cannot produce this motion at t = {t[i]:g} "
                         f"(and {len(violated) - 1} other times): the equations of motion are violated "
                         f"by {residual[i]:.3g} (relative {residual[i] / scale[i]:.3g}){shortage}")
    forces_unique = bool(np.all(reduced_ranks == len(columns)))
    if not forces_unique:
        warnings.warn(f"{len(columns)} actuators {list(actuated)} for {degrees} degree(s) of freedom: "
                      "over-actuated, the forces returned are the minimum-norm split", ActuationWarning,
                      stacklevel=3)
    multipliers_unique = bool(np.all(G_ranks == G.shape[1]))
    lam = np.zeros((n, model.r))
    lam[:, rows] = multipliers[:, :len(rows)]
    return InverseDynamicsResult(forces, lam, multipliers[:, len(rows):], forces_unique and multipliers_unique)


def constraint_rows(model: NumericModel, constraints: Sequence | None) -> list[int]:
    """Indices of the holonomic constraints named (or indexed) in ``constraints`` (default: all)."""
    if constraints is None:
        return list(range(model.r))
    names = [item.name for item in model.equations.system.constraints]
    rows = []
    for item in constraints:
        if isinstance(item, int | np.integer) and 0 <= item < model.r:
            rows.append(int(item))
        elif item in names:
            rows.append(names.index(item))
        else:
            raise InputError(f"unknown constraint {item!r}; constraints are {names}")
    return sorted(set(rows))


def check_motion(model: NumericModel, t, terms, q, qd, qdd, rows: list[int], tol: float) -> None:
    """ValueError naming the first constraint (of ``rows`` and the nonholonomic ones) that the
    motion violates at position, velocity or acceleration level, relative to ``tol``."""
    system = model.equations.system
    names = ([system.constraints[j].name for j in rows]
             + [item.name for item in system.nonholonomic_constraints])
    jacobian = np.concatenate([terms["Phi_q"][:, rows], terms["A"]], axis=1)
    offset = np.concatenate([terms["Phi_t"][:, rows], terms["b"]], axis=1)
    rate = np.concatenate([terms["gamma"][:, rows], terms["gamma_nh"]], axis=1)
    # speeds and accelerations are compared with their largest along the whole motion: where the
    # motion stops for an instant, rounding (relative to the motion's own size) would otherwise count
    magnitude = np.max(np.abs(jacobian), axis=(1, 2), initial=0.0)[:, None]
    speed, acceleration = (np.max(np.abs(x), initial=0.0) for x in (qd, qdd))
    phi = terms["Phi"][:, rows]
    size = 1.0 + np.max(np.abs(q), axis=1, initial=0.0)[:, None]
    levels = [("position", "Phi", names[:len(rows)], phi, np.broadcast_to(size, phi.shape)),
              ("velocity", "Phi_q qd + Phi_t (A qd + b)", names, np.einsum("nij,nj->ni", jacobian, qd) + offset,
               magnitude * speed + np.abs(offset)),
              ("acceleration", "Phi_q qdd - gamma (A qdd - gamma_nh)", names,
               np.einsum("nij,nj->ni", jacobian, qdd) - rate,
               magnitude * acceleration + np.abs(rate))]
    rounding = 1e3 * np.finfo(float).eps * magnitude  # a motion at rest still carries this much
    for level, formula, level_names, residual, scale in levels:
        excess = np.abs(residual) - tol * scale - (0.0 if level == "position" else rounding)
        if residual.size and np.max(excess) > 0:
            i, j = np.unravel_index(np.argmax(excess), excess.shape)
            raise InputError(f"the motion violates constraint {level_names[j]!r} at {level} level at "
                             f"t = {t[i]:g}: {formula} = {residual[i, j]:.3g} (tolerance "
                             f"{tol * scale[i, j]:.3g}); give q, qd, qdd that satisfy the constraints "
                             "(e.g. from kronlag.kinematic_analysis or a simulation)")
