"""The body-frame axes of a :class:`~kronlag.model.rotations.RotationSequence` in SymEngine, for the rotation
Jacobian of :func:`kronlag.derive`: the products of ``RotationSequence.body_axes`` without SymPy's
arithmetic, which on the floating-point axes of a robot file's long sequences took most of the
derivation of Cassie (8 of its 10 s of CPU)."""

from __future__ import annotations

from collections.abc import Callable

import symengine as se
import sympy as sp

from ..model.rotations import EULER_PARAMETERS, RotationSequence

__all__ = ["body_axes"]


def body_axes(sequence: RotationSequence,
              convert: Callable[[sp.Expr], se.Basic]) -> list[tuple[se.DenseMatrix, se.Basic]]:
    """:meth:`RotationSequence.body_axes <kronlag.model.rotations.RotationSequence.body_axes>` in
    SymEngine: ``w_k = (R_{k+1} ... R_n)^T u_k`` with each angle (an Euler-parameter factor: four
    pairs ``((R_{k+1} ... R_n)^T 2 G(e)[:, j], e_j)``), the angles converted by ``convert``."""
    result: list[tuple[se.DenseMatrix, se.Basic]] = []
    tail = se.eye(3)
    for axis, angle in reversed(sequence.factors):
        if isinstance(axis, str) and axis == EULER_PARAMETERS:  # 2 G(e) edot, one term per parameter
            e = [convert(entry) for entry in angle]
            rates = 2 * tail.T * _euler_parameter_rates(e)
            result.extend((rates[:, j], e[j]) for j in reversed(range(4)))
        else:
            angle = convert(angle)
            unit = [float(entry) for entry in axis]
            result.append((tail.T * se.DenseMatrix(3, 1, unit), angle))
        tail = _factor_matrix(axis, angle) * tail
    return result[::-1]


def _factor_matrix(axis, angle) -> se.DenseMatrix:
    """A :class:`RotationSequence` factor's matrix in SymEngine, as ``RotationSequence._factor_matrix``:
    :func:`~kronlag.model.rotations.euler_parameters` of the four SymEngine expressions ``angle``
    (``axis`` is :data:`EULER_PARAMETERS`), else Rodrigues' ``I + sin(a) K + (1 - cos(a)) K^2``
    (``K = [u]x``, ``u`` the axis normalized; for a principal axis the elementary rotation)."""
    if isinstance(axis, str) and axis == EULER_PARAMETERS:
        e0, *e = angle
        norm = e0 ** 2 - se.Add(*(x ** 2 for x in e))
        skew = [[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]]
        return se.DenseMatrix(3, 3, [(norm if i == j else 0) + 2 * (e[i] * e[j] + e0 * skew[i][j])
                                     for i in range(3) for j in range(3)])
    unit = [float(entry) for entry in axis]
    length = sum(x * x for x in unit) ** 0.5
    if length != 1.0:
        unit = [x / length for x in unit]
    skew = [[0.0, -unit[2], unit[1]], [unit[2], 0.0, -unit[0]], [-unit[1], unit[0], 0.0]]
    square = [[sum(skew[i][k] * skew[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    sine, versine = se.sin(angle), 1 - se.cos(angle)
    return se.DenseMatrix(3, 3, [(1 if i == j else 0) + _times(skew[i][j], sine) + _times(square[i][j], versine)
                                 for i in range(3) for j in range(3)])


def _times(number: float, expr: se.Basic) -> se.Basic:
    """``number * expr`` with an exact 0 or 1 kept exact (the entries of a principal axis's rotation)."""
    if number == 0.0:
        return se.Integer(0)
    if abs(number) == 1.0:
        return expr if number > 0 else -expr
    return se.RealDouble(number) * expr


def _euler_parameter_rates(e: list) -> se.DenseMatrix:
    """:func:`~kronlag.model.rotations.euler_parameter_rates` of SymEngine expressions."""
    e0, e1, e2, e3 = e
    return se.DenseMatrix([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])
