"""The symbols of a model: coordinates ``q``, their speeds ``qd`` and accelerations ``qdd``, the time ``t``.

Coordinates are plain SymPy symbols chosen by the user (a redundant set is allowed).  The
speed and acceleration of a coordinate named ``x`` are the plain symbols ``xd`` and ``xdd``.
Every other symbol of a model is a declared parameter; the time symbol :data:`t` may appear in
forces and in holonomic and nonholonomic constraints (drives).  The names ``lambda1,
lambda2, ...`` and ``mu1, mu2, ...`` are reserved for the multipliers that
:func:`kronlag.derive` creates.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import sympy as sp

from ..core.errors import InputError, ModelError

__all__ = ["t", "coordinates", "speed_symbol", "acceleration_symbol", "MULTIPLIER_NAME", "check_name",
           "name_indices", "free_symbols"]

#: The time symbol; allowed in applied forces and torques and in constraints (drives).
t = sp.Symbol("t")

#: The names reserved for the multipliers lambda_j and mu_k.
MULTIPLIER_NAME = re.compile(r"^(lambda|mu)\d+$")


def coordinates(names: str) -> tuple[sp.Symbol, ...]:
    """Create generalized coordinates as plain SymPy symbols.

    >>> coordinates("q1 q2")
    (q1, q2)
    """
    created = sp.symbols(names, seq=True)
    return tuple(created)


def speed_symbol(coordinate: sp.Symbol) -> sp.Symbol:
    """The speed symbol of a coordinate: ``q1`` -> ``q1d``."""
    return sp.Symbol(coordinate.name + "d")


def acceleration_symbol(coordinate: sp.Symbol) -> sp.Symbol:
    """The acceleration symbol of a coordinate: ``q1`` -> ``q1dd``."""
    return sp.Symbol(coordinate.name + "dd")


def check_name(name, what: str) -> str:
    """``name`` if it is a non-empty string; ModelError naming ``what`` otherwise."""
    if not isinstance(name, str) or not name.strip():
        raise ModelError(f"a {what} needs a non-empty name, got {name!r}")
    return name


_UNIONS_ITS_ARGUMENTS: dict[type, bool] = {}


def _unions_its_arguments(kind: type) -> bool:
    """Whether ``kind``'s free symbols are just the union of its arguments' (SymPy's default rule);
    symbols, matrices and binding forms (Derivative, Integral, Lambda, Subs...) have their own."""
    known = _UNIONS_ITS_ARGUMENTS.get(kind)
    if known is None:
        owner = next(base for base in kind.__mro__ if "free_symbols" in vars(base))
        known = _UNIONS_ITS_ARGUMENTS[kind] = owner is sp.Basic
    return known


def free_symbols(expression) -> set[sp.Symbol]:
    """``expression.free_symbols`` (a SymPy expression or matrix), visiting each shared subexpression once.

    SymPy's own ``free_symbols`` re-walks a subexpression every time it is shared, so on the
    world-frame positions of a deep kinematic chain (each link reusing its parent's pose) its
    cost doubles with every level; this walk over the expression DAG is linear in its distinct nodes.
    """
    found: set[sp.Symbol] = set()
    seen: set[int] = set()  # node ids: the nodes stay alive inside ``expression`` during the walk
    pending = [expression]
    while pending:
        node = pending.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, sp.MatrixBase):
            pending.extend(node)
        elif _unions_its_arguments(type(node)):
            pending.extend(node.args)
        else:
            found |= node.free_symbols
    return found


def name_indices(keys: Sequence, known: Mapping[str, int], what: str) -> list[int]:
    """Indices of ``keys`` (names or SymPy symbols) in ``known``; InputError listing the unknown ones."""
    names = [key.name if isinstance(key, sp.Symbol) else key for key in keys]
    unknown = [repr(name) for name in names if name not in known]
    if unknown:
        raise InputError(f"unknown {what}: {', '.join(unknown)}; known: {', '.join(known)}")
    return [known[name] for name in names]
