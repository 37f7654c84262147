"""Structure-keeping constraint blocks of the recursive ``"dynamics"`` kernel.

The derivation's ``Phi_q`` and ``gamma`` are flat: for a chain in relative angles, whose tip is
``sum_i l_i (cos, sin)(q1 + ... + qi)``, every entry of ``Phi_q`` is a sum over the links beyond a
joint and ``gamma = -d(Phi_q qd)/dt`` expands ``(qd1 + ... + qdi)^2`` into O(n^3) terms.  Next to
the recursive ``M`` and ``h`` (:mod:`kronlag.numeric.codegen.recursive`) they would dominate the
kernel.  Here

* ``Phi_q`` is differentiated from ``Phi`` as SymEngine keeps it (each ``cos(q1 + ... + qi)`` one
  shared node), and ``gamma`` is the second derivative of ``Phi`` along the motion,
  ``gamma = -d^2/ds^2 Phi(q + s qd, t + s)`` at ``s = 0`` (the same quantity as
  ``-(Phi_q qd)_q qd - 2 Phi_qt qd - Phi_tt``, without expanding the squares);
* :func:`chained_sums` names every sum of three or more terms once, as a sum named before plus
  the one term it lacks where there is one: the partial angle sums ``q1 + ... + qi`` and
  ``qd1 + ... + qdi`` and the sums over the links beyond each joint then cost O(n), not O(n^2).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import TYPE_CHECKING

import symengine as se

from ...core.kernels import rebuilt

if TYPE_CHECKING:
    from .source import KernelSource

__all__ = ["constraint_blocks", "chained_sums"]

#: Sums of at least this many terms get a name of their own.
CHAINED_SUM_TERMS = 3


#: The blocks of each KernelSource, computed once (the dynamics kernel and the eager ones share them).
_BLOCKS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def constraint_blocks(source: KernelSource) -> dict[str, list[list[se.Basic]]]:
    """``Phi_q`` and ``gamma`` of ``source`` differentiated from its ``Phi`` (see the module docstring)."""
    blocks = _BLOCKS.get(source)
    if blocks is None:
        blocks = _BLOCKS[source] = _differentiated(source)
    return blocks


def _differentiated(source: KernelSource) -> dict[str, list[list[se.Basic]]]:
    phi = [row[0] for row in source.matrix("Phi")]
    time = se.Symbol("t")
    step = se.Symbol("kronlag_step")
    along = {**{q: q + step * qd for q, qd in zip(source.q, source.qd)}, time: time + step}
    jacobian = [[se.diff(entry, q) for q in source.q] for entry in phi]
    gamma = [[-se.diff(entry.xreplace(along), step, 2).xreplace({step: se.Integer(0)})] for entry in phi]
    return {"Phi_q": jacobian, "gamma": gamma}


def chained_sums(entries: Sequence[se.Basic], *, prefix: str = "sum"
                 ) -> tuple[list[tuple[se.Symbol, se.Basic]], list[se.Basic]]:
    """``entries`` with every sum of :data:`CHAINED_SUM_TERMS` or more terms replaced by a symbol
    (``<prefix>0``, ``<prefix>1``, ...), and the symbols' definitions (each a sum named before plus
    one term where one is one term short)."""
    names: dict[frozenset, se.Symbol] = {}
    memo: dict[se.Basic, se.Basic] = {}

    def rewritten(expr: se.Basic) -> se.Basic:
        if not expr.args:
            return expr
        result = memo.get(expr)
        if result is None:
            args = [rewritten(arg) for arg in expr.args]
            if isinstance(expr, se.Add) and len(args) >= CHAINED_SUM_TERMS:
                key = frozenset(args)
                result = names.get(key)
                if result is None:
                    result = names[key] = se.Symbol(f"{prefix}{len(names)}")
            else:
                result = rebuilt(expr, args)
            memo[expr] = result
        return result

    outputs = [rewritten(entry) for entry in entries]
    definitions = []
    for terms, symbol in names.items():
        shorter = next(((names[terms - {term}], term) for term in terms if terms - {term} in names), None)
        definitions.append((symbol, se.Add(*terms) if shorter is None else shorter[0] + shorter[1]))
    return definitions, outputs
