"""What bodies and loads contribute to the equations of motion, and the calculus they ask for.

A body contributes terms ``1/2 v^T W v`` to the kinetic energy (:class:`KineticTerm`: a
:class:`Velocity` ``v = J qd`` and its weight ``W``); a load contributes a potential
energy term or generalized forces ``f_Q``.  They compute them with a :class:`Calculus`
lent by the derivation, in the derivation's own representation of expressions (SymEngine
in :func:`kronlag.derive`), so that the model layer describes *what* enters the
equations and the symbolic layer does the heavy algebra.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import sympy as sp

if TYPE_CHECKING:
    from .bodies import RigidBody

__all__ = ["Calculus", "Velocity", "KineticTerm"]


@dataclass(frozen=True)
class Velocity:
    """A velocity ``v = J qd`` that is linear in the speeds, in a :class:`Calculus`' representation.

    Attributes
    ----------
    jacobian : matrix
        ``J`` (k x m).
    bias : matrix
        ``Jd qd`` (k x 1): the part of ``dv/dt`` without the accelerations.
    gradient : bool
        ``J = dx/dq`` of some ``x(q)`` (a position, a planar angle), so that the columns'
        derivatives are symmetric, ``dJ_i/dq_k = dJ_k/dq_i``; false for the body-frame
        angular velocity of a spatial body.
    """

    jacobian: Any
    bias: Any
    gradient: bool = True


@dataclass(frozen=True)
class KineticTerm:
    """A term ``1/2 v^T W v`` of a body's kinetic energy.

    Attributes
    ----------
    velocity : Velocity
    weight : scalar or matrix
        ``W``: a scalar (a mass, a planar moment of inertia) or a symmetric square matrix
        (an inertia tensor), in the calculus' representation.
    """

    velocity: Velocity
    weight: Any


class Calculus(Protocol):
    """The algebra a derivation lends bodies and loads.

    Matrices and scalars are in the derivation's representation (SymEngine for
    :func:`kronlag.derive`) and support ``+``, ``-``, ``*``, ``/``, ``.T`` and indexing
    ``[i, j]``; ``q`` are the system's coordinates.

    Attributes
    ----------
    speeds : matrix
        ``qd`` (m x 1).
    """

    speeds: Any

    def scalar(self, expression: sp.Expr) -> Any:
        """A SymPy expression in the derivation's representation."""

    def matrix(self, matrix: sp.MatrixBase) -> Any:
        """A SymPy matrix in the derivation's representation."""

    def jacobian(self, vector: Any) -> Any:
        """``d vector / dq`` of a vector (k x 1) in the derivation's representation, (k x m)."""

    def velocity(self, vector: sp.MatrixBase) -> Velocity:
        """``d/dt`` of a vector of expressions of q: ``J = d vector/dq`` and ``Jd qd`` (a gradient)."""

    def angular_velocity(self, body: RigidBody) -> Velocity:
        """The body-frame angular velocity ``omega = J_R qd`` of a spatial body's rotation."""
