"""Loads and other named items of a system: springs, dampers, potentials, applied forces and torques,
constraints."""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

__all__ = ["Spring", "Damper", "NamedExpression", "AppliedForce"]


@dataclass(frozen=True)
class Spring:
    """Linear spring between two points: ``Pi = 1/2 k (|p_a - p_b| - L0)^2``."""

    name: str
    point_a: sp.ImmutableMatrix
    point_b: sp.ImmutableMatrix
    stiffness: sp.Expr
    free_length: sp.Expr

    def potential(self) -> sp.Expr:
        separation = self.point_a - self.point_b
        squared = (separation.T * separation)[0, 0]
        if self.free_length == 0:
            return self.stiffness * squared / 2
        return self.stiffness * (sp.sqrt(squared) - self.free_length) ** 2 / 2


@dataclass(frozen=True)
class Damper:
    """Linear damper between two points: force ``-c dL/dt`` along the line, ``L = |p_a - p_b|``."""

    name: str
    point_a: sp.ImmutableMatrix
    point_b: sp.ImmutableMatrix
    coefficient: sp.Expr



@dataclass(frozen=True)
class NamedExpression:
    """A named scalar: a constraint or a potential term."""

    name: str
    expression: sp.Expr


@dataclass(frozen=True)
class AppliedForce:
    """A generalized force, or a force/torque vector mapped through a Jacobian."""

    name: str
    kind: str  # "generalized", "point", "body torque"
    value: sp.ImmutableMatrix
    where: sp.ImmutableMatrix | str | None = None
    frame: str = "world"
