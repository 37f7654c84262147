"""The constraint rows of a model grouped by the joint or loop they belong to, with each group's rank
at a state and the rows dependent on the others: what ``kronlag check`` prints about redundancy.

Rows are named ``"<group>.<row>"`` (``"hip-loop.x"``); ranks follow the one rank policy of
:mod:`kronlag.numeric.tolerances`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..numeric.tolerances import matrix_rank, numerical_rank, rank_magnitudes

__all__ = ["ConstraintGroup", "constraint_ranks"]


@dataclass(frozen=True)
class ConstraintGroup:
    """The holonomic rows of one joint or loop (named ``"<group>.<row>"``; a row without a dot is a
    group of its own) and their rank at the assembled state."""

    name: str
    rows: tuple[str, ...]
    rank: int


def constraint_ranks(names: Sequence[str], jacobian: np.ndarray,
                     rank_rtol: float) -> tuple[tuple[ConstraintGroup, ...], tuple[str, ...]]:
    """The rows ``names`` of ``jacobian`` (``Phi_q``) grouped by the name before their last dot, each
    group's rank, and the rows dependent on the others (those ``kronlag check`` reports)."""
    groups: dict[str, list[int]] = {}
    for index, name in enumerate(names):
        groups.setdefault(name.rsplit(".", 1)[0], []).append(index)
    ranked = tuple(ConstraintGroup(group, tuple(names[i] for i in rows), matrix_rank(jacobian[rows], rank_rtol))
                   for group, rows in groups.items())
    count = len(names) - numerical_rank(rank_magnitudes(jacobian)[0], rank_rtol)
    if not count:
        return ranked, ()
    # which rows: those farthest inside the span of the rows before them (|diag R| of the QR of Phi_q^T
    # in the system's order), as many as the rank policy counts dependent
    distances = np.zeros(len(names))
    diagonal = np.abs(np.diag(np.linalg.qr(jacobian.T, mode="r")))
    distances[:len(diagonal)] = diagonal
    return ranked, tuple(names[i] for i in sorted(np.argsort(distances, kind="stable")[:count]))
