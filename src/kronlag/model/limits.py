"""Limits, stops and impacts: one-sided bounds on an expression of the coordinates.

A :class:`Limit` bounds ``value(q)`` (a coordinate, a joint angle, a point's height above a
plane) from below, above or both.  Each bound is a *side* with a gap that must stay
non-negative: ``g = value - lower`` or ``g = upper - value``.  The simulation watches the gaps,
applies Newton's restitution law at contact and holds a side that stays in contact as a
bilateral constraint (:mod:`kronlag.simulation.impacts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from ..core.errors import ModelError
from .inputs import as_scalar
from .symbols import free_symbols

__all__ = ["Limit", "LimitSide", "make_limit"]


@dataclass(frozen=True)
class LimitSide:
    """One bound of a limit: the gap ``g(q) >= 0`` and the restitution coefficient at it.

    Attributes
    ----------
    name : str
        ``"<limit> lower"`` or ``"<limit> upper"``.
    limit : str
        The name of its :class:`Limit`.
    gap : sympy.Expr
        ``value - lower`` or ``upper - value``.
    bound : sympy.Expr
    restitution : sympy.Expr
    """

    name: str
    limit: str
    gap: sp.Expr
    bound: sp.Expr
    restitution: sp.Expr


@dataclass(frozen=True)
class Limit:
    """``lower <= value(q) <= upper`` (either bound may be ``None``), with Newton's coefficient of
    restitution ``restitution`` (0: the contact stays, 1: elastic) at both bounds."""

    name: str
    value: sp.Expr
    lower: sp.Expr | None
    upper: sp.Expr | None
    restitution: sp.Expr

    @property
    def sides(self) -> tuple[LimitSide, ...]:
        """The bounds given, lower first."""
        sides = []
        if self.lower is not None:
            sides.append(LimitSide(f"{self.name} lower", self.name, self.value - self.lower, self.lower,
                                   self.restitution))
        if self.upper is not None:
            sides.append(LimitSide(f"{self.name} upper", self.name, self.upper - self.value, self.upper,
                                   self.restitution))
        return tuple(sides)


def make_limit(name: str, value, lower, upper, restitution, coordinates) -> Limit:
    """A :class:`Limit` from user input; :class:`ModelError` naming the limit for a bad item (the
    symbols are checked by :meth:`kronlag.System.add_limit`)."""
    what = f"limit {name!r}"
    expression = as_scalar(value, what)
    if not free_symbols(expression) & set(coordinates):
        raise ModelError(f"{what} does not depend on any coordinate: {expression}")
    if lower is None and upper is None:
        raise ModelError(f"{what}: give lower=, upper= or both")
    lower = None if lower is None else as_scalar(lower, f"{what} lower bound")
    upper = None if upper is None else as_scalar(upper, f"{what} upper bound")
    e = as_scalar(restitution, f"{what} restitution")
    if e.is_number and not 0 <= float(e) <= 1:
        raise ModelError(f"{what}: the restitution must lie in [0, 1], got {e}")
    if lower is not None and upper is not None and (upper - lower).is_number and float(upper - lower) <= 0:
        raise ModelError(f"{what}: the lower bound {lower} is not below the upper bound {upper}")
    return Limit(name, expression, lower, upper, e)
