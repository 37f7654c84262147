"""The ``"tangent"`` kernel (``K = de/dq``, ``D = de/dqd`` of ALI3-P) of a tree, structure-keeping.

The dynamic residual ``e = M a + C qd + g - f_Q + Phi_q^T nu + A^T mu`` at given accelerations ``a``
and multipliers ``nu``, ``mu`` is, for a System the recursion takes
(:func:`~kronlag.numeric.codegen.recursive.recursion_of`), the inverse dynamics by the recursive
Newton-Euler algorithm at ``qdd = a`` plus the loads' terms and the constraint forces.  Its exact
derivatives are taken here in forward mode through the recursion's temporaries: for every coordinate
and speed, the derivative of each temporary that depends on it is a new temporary (the chain rule on
its definition), so that the kernel grows like the number of (temporary, variable) pairs - O(n^2)
for a chain - where differentiating the derivation's flat ``M a + C qd + g`` grows like n^4 and more.
The constraint part ``d(Phi_q^T nu)/dq`` (and ``d(A^T mu)/dq``) is differentiated from the
structure-keeping ``Phi_q`` (:mod:`~kronlag.numeric.codegen.constraint_terms`), its sums named once.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import symengine as se

from ...core.kernels import Block, Kernel
from .constraint_terms import chained_sums, constraint_blocks
from .recursive import (
    _Definitions,
    _eliminated,
    _frames,
    _InputConverter,
    _recursion,
    bias_forces,
    dependency_order,
    gravity_vector,
    load_potential_gradient,
)

if TYPE_CHECKING:
    from .source import KernelSource

__all__ = ["recursive_tangent_kernel"]


def recursive_tangent_kernel(source: KernelSource, blocks: Sequence[Block]) -> Kernel | None:
    """The ``"tangent"`` kernel of ``source`` (blocks ``K``, ``D``; ``a``, ``nu``, ``mu`` read from ``p``
    after the parameters, as :class:`~kronlag.numeric.codegen.KernelSource` lays them out), or ``None``
    when its System does not qualify for the recursion."""
    recursion, _ = _recursion(source)
    if recursion is None:
        return None
    equations = source.equations
    m, r, s = equations.shape
    extra = [se.Symbol(f"p[{len(equations.parameters) + i}]") for i in range(m + r + s)]
    a, nu, mu = extra[:m], extra[m:m + r], extra[m + r:]
    zero = se.Integer(0)
    convert = _InputConverter(source)
    define = _Definitions()
    frames = _frames(recursion, convert, source.qd, define)
    accelerations = [a[link.index] for link in recursion.links]
    inverse = bias_forces(recursion, frames, gravity_vector(equations.system, convert), define, convert,
                          accelerations=accelerations)
    tree = [zero] * m  # M a + C qd + g, in the recursion's temporaries
    for link, entry in zip(recursion.links, inverse):
        tree[link.index] = convert.exact(entry)
    define.pairs[:] = [(symbol, convert.exact(expr)) for symbol, expr in define.pairs]
    forces, loads = source.matrix("f_Q"), load_potential_gradient(source)
    # Phi_q with its sums named (the sums beyond each joint of a chain), the names' definitions joining the
    # temporaries so that d(Phi_q^T nu)/dq is taken through them too
    jacobian = constraint_blocks(source)["Phi_q"]
    sums, named = chained_sums([jacobian[k][i] for k in range(r) for i in range(m)], prefix="jacobian_sum")
    values = dict(sums)
    define.pairs.extend((symbol, values[symbol]) for symbol in dependency_order(values, list(values)))
    nonholonomic = source.matrix("A")
    residual = [tree[i] + loads[i] - forces[i][0] + se.Add(*(named[k * m + i] * nu[k] for k in range(r)))
                + se.Add(*(nonholonomic[k][i] * mu[k] for k in range(s))) for i in range(m)]
    derivatives = _forward_mode(define, [*source.q, *source.qd])
    entries = [define(_chain_rule(residual[i], variable, derivatives[variable]))
               for variables in (source.q, source.qd) for i in range(m) for variable in variables]
    temporaries, outputs = _eliminated(define.pairs, entries)
    return Kernel("tangent", tuple(blocks), temporaries, outputs, dict(source.convert.constants))


def _chain_rule(expr: se.Basic, variable: se.Symbol, derivative: dict[se.Symbol, se.Basic]) -> se.Basic:
    """``d expr / d variable`` for an ``expr`` of the inputs and of temporaries whose derivatives
    (nonzero ones only) ``derivative`` holds."""
    terms = []
    for symbol in expr.free_symbols:
        rate = se.Integer(1) if symbol == variable else derivative.get(symbol)
        if rate is not None:
            terms.append(se.diff(expr, symbol) * rate)
    return se.Add(*terms)


def _forward_mode(define: _Definitions, variables: Sequence[se.Symbol]) -> dict[se.Symbol, dict]:
    """For each variable, the derivative of every temporary of ``define`` that depends on it, each a
    new temporary (appended to ``define``: they follow what they use)."""
    bit = {variable: 1 << k for k, variable in enumerate(variables)}
    depends: dict[se.Symbol, int] = {}
    for symbol, expr in define.pairs:
        mask = 0
        for used in expr.free_symbols:
            mask |= bit.get(used, 0) | depends.get(used, 0)
        depends[symbol] = mask
    originals = list(define.pairs)
    result = {}
    for variable in variables:
        flag = bit[variable]
        derivative: dict[se.Symbol, se.Basic] = {}
        for symbol, expr in originals:
            if depends[symbol] & flag:
                rate = define(_chain_rule(expr, variable, derivative))
                if rate != 0:
                    derivative[symbol] = rate
        result[variable] = derivative
    return result
