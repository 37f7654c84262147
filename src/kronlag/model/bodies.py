"""Bodies: planar and spatial rigid bodies and point masses, and the physical checks of their values."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from ..core.errors import ModelError
from .inputs import as_matrix, as_scalar, as_vector
from .rotations import RotationSequence, check_rotation
from .symbols import check_name

if TYPE_CHECKING:
    from .system import System

__all__ = ["PlanarBody", "RigidBody", "PointMass", "check_parameter_values"]


@dataclass(frozen=True)
class PlanarBody:
    """A rigid body moving in the plane.

    Parameters
    ----------
    name : str
    mass : expression
        ``m_i``, a parameter or number.
    inertia : expression
        Moment of inertia about the centre of mass, normal to the plane.
    position : 2 expressions of q
        Centre of mass ``(x, y)``.
    angle : expression of q
        Orientation angle; the angular velocity is ``d(angle)/dt``.
    """

    name: str
    mass: sp.Expr
    inertia: sp.Expr
    position: sp.ImmutableMatrix
    angle: sp.Expr

    dimension = 2

    def __init__(self, name: str, *, mass, inertia, position, angle):
        what = f"body {name!r}"
        object.__setattr__(self, "name", check_name(name, "body"))
        object.__setattr__(self, "mass", as_scalar(mass, f"{what} mass"))
        object.__setattr__(self, "inertia", as_scalar(inertia, f"{what} inertia"))
        object.__setattr__(self, "position", as_vector(position, f"{what} position", (2,)))
        object.__setattr__(self, "angle", as_scalar(angle, f"{what} angle"))


@dataclass(frozen=True)
class RigidBody:
    """A rigid body moving in space.

    Parameters
    ----------
    name : str
    mass : expression
    inertia : 3x3 symmetric matrix
        Inertia tensor about the centre of mass in the body frame.
    position : 3 expressions of q
        Centre of mass in the inertial frame.
    rotation : 3x3 matrix of expressions of q, or RotationSequence
        ``R(q)`` maps body-frame components to inertial components; it must be orthogonal
        with determinant +1 (checked symbolically where cheap, else numerically at random
        points; the error names the entry of ``R^T R`` that is off).  The body-frame
        angular velocity is ``omega = J_R qd``.  For a :class:`RotationSequence` ``J_R``
        follows from the factors' axes (no simplification needed); for a matrix, its
        column k is ``vee(R^T dR/dq_k)`` (Theorem 1).
    simplify : bool
        For a rotation given as a matrix: apply ``trigsimp`` to the entries of ``J_R``
        (default ``True``) that are small enough for it to be cheap (at most
        ``kronlag.derivation.TRIGSIMP_MAX_OPERATIONS`` operations); larger entries are kept
        as they are, so that the cost stays bounded.  Worth it for Euler-angle rotations,
        whose ``R^T dR/dq_k`` hides many ``sin^2 + cos^2``.
    """

    name: str
    mass: sp.Expr
    inertia: sp.ImmutableMatrix
    position: sp.ImmutableMatrix
    rotation: sp.ImmutableMatrix
    simplify: bool = True
    rotation_sequence: RotationSequence | None = None

    dimension = 3

    def __init__(self, name: str, *, mass, inertia, position, rotation, simplify: bool = True):
        what = f"body {name!r}"
        object.__setattr__(self, "name", check_name(name, "body"))
        object.__setattr__(self, "mass", as_scalar(mass, f"{what} mass"))
        tensor = as_matrix(inertia, (3, 3), f"{what} inertia tensor")
        asymmetric = [(i, j) for i in range(3) for j in range(i + 1, 3)
                      if sp.simplify(tensor[i, j] - tensor[j, i]) != 0]
        if asymmetric:
            i, j = asymmetric[0]
            raise ModelError(f"{what} inertia tensor is not symmetric: entry [{i},{j}] = {tensor[i, j]} "
                             f"but [{j},{i}] = {tensor[j, i]}")
        object.__setattr__(self, "inertia", tensor)
        object.__setattr__(self, "position", as_vector(position, f"{what} position", (3,)))
        if isinstance(rotation, RotationSequence):
            object.__setattr__(self, "rotation_sequence", rotation)
            object.__setattr__(self, "rotation", rotation.matrix)
        else:
            object.__setattr__(self, "rotation_sequence", None)
            matrix = as_matrix(rotation, (3, 3), f"{what} rotation")
            check_rotation(matrix, f"{what} rotation")
            object.__setattr__(self, "rotation", matrix)
        object.__setattr__(self, "simplify", bool(simplify))


@dataclass(frozen=True)
class PointMass:
    """A particle of mass ``mass`` at ``position`` (2 or 3 expressions of q)."""

    name: str
    mass: sp.Expr
    position: sp.ImmutableMatrix

    def __init__(self, name: str, *, mass, position):
        what = f"body {name!r}"
        object.__setattr__(self, "name", check_name(name, "body"))
        object.__setattr__(self, "mass", as_scalar(mass, f"{what} mass"))
        object.__setattr__(self, "position", as_vector(position, f"{what} position", (2, 3)))

    @property
    def dimension(self) -> int:
        return self.position.rows


#: Relative tolerance of the physical checks of :func:`check_parameter_values`.
_PHYSICAL_TOLERANCE = 1e-9


def check_parameter_values(system: System, values: Mapping[str, float]) -> None:
    """Check that the bodies are physical for the given parameter values.

    Every mass must be non-negative (zero is allowed for an auxiliary massless body; a mass
    matrix left singular by it is reported by ``forward_dynamics``); a planar moment of
    inertia non-negative; a spatial
    inertia tensor ``I`` positive semidefinite with principal moments ``I_1, I_2, I_3``
    satisfying the triangle inequalities ``I_a + I_b >= I_c`` (a real mass distribution
    has them).  :class:`kronlag.NumericModel` calls this with the values it was given.

    Parameters
    ----------
    system : System
    values : mapping of parameter name to float

    Raises
    ------
    ModelError
        Naming the body, the quantity and its value.
    """
    symbols = {symbol: sp.Float(float(values[symbol.name])) for symbol in system.parameters if symbol.name in values}

    def number(expr, what: str) -> float:
        value = sp.sympify(expr).xreplace(symbols)
        if value.free_symbols:
            raise ModelError(f"{what} depends on {', '.join(sorted(s.name for s in value.free_symbols))}, "
                             "which have no value")
        if value.is_real is False:  # reported by the code generation, with the matrix entry
            raise _NotReal
        return float(value)

    for body in system.bodies:
        try:
            _check_body(body, number)
        except _NotReal:
            continue


class _NotReal(Exception):
    """A body's mass or inertia is not a real number (see :func:`check_parameter_values`)."""


def _check_body(body, number: Callable[[object, str], float]) -> None:
    """The checks of :func:`check_parameter_values` for one body."""
    what = f"body {body.name!r}"
    mass = number(body.mass, f"{what} mass")
    if not mass >= 0:
        raise ModelError(f"{what}: mass = {mass:.6g} ({body.mass}); a mass must not be negative")
    if isinstance(body, PlanarBody):
        inertia = number(body.inertia, f"{what} inertia")
        if inertia < 0:
            raise ModelError(f"{what}: moment of inertia = {inertia:.6g} ({body.inertia}); "
                             "it must not be negative")
    elif isinstance(body, RigidBody):
        tensor = np.array([[number(body.inertia[i, j], f"{what} inertia[{i},{j}]") for j in range(3)]
                           for i in range(3)])
        moments = np.linalg.eigvalsh(tensor)
        tolerance = _PHYSICAL_TOLERANCE * max(1e-300, np.abs(moments).max())
        if moments[0] < -tolerance:
            raise ModelError(f"{what}: the inertia tensor is not positive semidefinite (principal moments "
                             f"{', '.join(f'{value:.6g}' for value in moments)}); tensor {tensor.tolist()}")
        if moments[0] + moments[1] < moments[2] - tolerance:
            raise ModelError(f"{what}: the principal moments of inertia {', '.join(f'{v:.6g}' for v in moments)} "
                             f"violate the triangle inequality I1 + I2 >= I3 ({moments[0] + moments[1]:.6g} < "
                             f"{moments[2]:.6g}): no mass distribution has them")
