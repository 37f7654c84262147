"""Loads: springs, dampers, potentials, applied forces and torques; and the named constraints of a system.

Every load type is a :class:`Load` and contributes to the equations of motion itself, as
:func:`kronlag.derive` sums ``system.loads``: a potential energy term (:meth:`Load.potential`,
entering ``g = (dPi/dq)^T``) and generalized forces (:meth:`Load.generalized_force`, entering
``f_Q``), the latter with the calculus the derivation lends
(:class:`~kronlag.model.contributions.Calculus`).  Its ``file_table`` names its array of
tables in model files (``[[springs]]``), whose formats :mod:`kronlag.model.modelfile.formats`
holds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import sympy as sp

from .contributions import Calculus

if TYPE_CHECKING:
    from .bodies import Body

__all__ = ["Load", "Spring", "Damper", "Potential", "AppliedForce", "GeneralizedForce", "PointForce",
           "BodyTorque", "NamedExpression"]


class Load:
    """A load of a :class:`~kronlag.System`: the interface every load type implements.

    Attributes
    ----------
    name : str
    """

    name: str

    #: The array of tables that holds loads of this type in model files (``"springs"``); ``None``:
    #: model files cannot hold it.
    file_table: ClassVar[str | None] = None

    def potential(self) -> sp.Expr:
        """Its potential energy ``Pi(q)`` (SymPy; 0 for a load that is not conservative)."""
        return sp.Integer(0)

    def generalized_force(self, calculus: Calculus) -> Any | None:
        """Its generalized force ``f_Q`` (m x 1) in the calculus' representation; ``None`` for none."""
        return None


@dataclass(frozen=True)
class Spring(Load):
    """Linear spring between two points: ``Pi = 1/2 k (|p_a - p_b| - L0)^2``."""

    name: str
    point_a: sp.ImmutableMatrix
    point_b: sp.ImmutableMatrix
    stiffness: sp.Expr
    free_length: sp.Expr

    file_table = "springs"

    def potential(self) -> sp.Expr:
        separation = self.point_a - self.point_b
        squared = (separation.T * separation)[0, 0]
        if self.free_length == 0:
            return self.stiffness * squared / 2
        return self.stiffness * (sp.sqrt(squared) - self.free_length) ** 2 / 2


@dataclass(frozen=True)
class Damper(Load):
    """Linear damper between two points: force ``-c dL/dt`` along the line, ``L = |p_a - p_b|``."""

    name: str
    point_a: sp.ImmutableMatrix
    point_b: sp.ImmutableMatrix
    coefficient: sp.Expr

    file_table = "dampers"

    def generalized_force(self, calculus: Calculus) -> Any:
        """``-c (dL/dt) (dL/dq)^T``, written with ``d = p_a - p_b``: ``L dL/dq = d^T dd/dq``."""
        separation = calculus.matrix(self.point_a - self.point_b)
        gradient = separation.T * calculus.jacobian(separation)
        rate = (gradient * calculus.speeds)[0, 0]
        squared = (separation.T * separation)[0, 0]
        return -(gradient.T * (calculus.scalar(self.coefficient) * rate / squared))


@dataclass(frozen=True)
class Potential(Load):
    """A potential energy term ``Pi(q)``."""

    name: str
    expression: sp.Expr

    file_table = "potentials"

    def potential(self) -> sp.Expr:
        return self.expression


@dataclass(frozen=True)
class AppliedForce(Load):
    """A non-conservative force or torque given by its components ``value`` (entries may depend on q,
    qd, the parameters and the time); ``system.forces`` lists them."""

    name: str
    value: sp.ImmutableMatrix


@dataclass(frozen=True)
class GeneralizedForce(AppliedForce):
    """Generalized forces ``value`` (m x 1) added to ``f_Q`` as they are."""

    file_table = "generalized_forces"

    def generalized_force(self, calculus: Calculus) -> Any:
        return calculus.matrix(self.value)


@dataclass(frozen=True)
class PointForce(AppliedForce):
    """A force ``value`` (world components) at ``point`` (world position, an expression of q):
    ``f_Q = J^T value``, ``J = d point/dq``."""

    point: sp.ImmutableMatrix

    file_table = "forces"

    def generalized_force(self, calculus: Calculus) -> Any:
        return calculus.jacobian(calculus.matrix(self.point)).T * calculus.matrix(self.value)


@dataclass(frozen=True)
class BodyTorque(AppliedForce):
    """A torque ``value`` on ``body`` (a scalar in the plane; in space a 3-vector in the ``frame``
    ``"world"`` or ``"body"``), mapped to ``f_Q`` by the body
    (:meth:`~kronlag.model.bodies.Body.generalized_torque`)."""

    body: Body
    frame: str = "world"

    file_table = "torques"

    def generalized_force(self, calculus: Calculus) -> Any:
        return self.body.generalized_torque(calculus, self.value, self.frame)


@dataclass(frozen=True)
class NamedExpression:
    """A named scalar: a holonomic or nonholonomic constraint."""

    name: str
    expression: sp.Expr
