"""Bodies: planar and spatial rigid bodies and point masses, and the physical checks of their values.

Every body type is a :class:`Body` and answers for itself what the rest of kronlag asks of a body:

- its kinetic energy (:meth:`~Body.kinetic_terms`) and the generalized force of a torque on it
  (:meth:`~Body.generalized_torque`), which :func:`kronlag.derive` sums with the calculus it lends
  (:class:`~kronlag.model.contributions.Calculus`);
- its pose (:meth:`~Body.pose`), for frames, body points and joints, and whether it has an
  orientation (:attr:`~Body.oriented`), how a torque on it is given (:meth:`~Body.torque_components`);
- its fields (:attr:`~Body.fields`): the constructor's arguments, which symbols each may use
  (:meth:`kronlag.System.add_body`) and how model files read and write them (the type's
  ``file_type`` names it there; :data:`BODY_TYPES` holds the types by it);
- the physical checks of its values (:meth:`~Body.check_values`, :func:`check_parameter_values`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import sympy as sp

from ..core.errors import ModelError
from .contributions import Calculus, KineticTerm, Velocity
from .frames import Frame
from .inputs import as_matrix, as_scalar, as_vector
from .rotations import RotationSequence, check_rotation, planar_rotation
from .symbols import check_name

if TYPE_CHECKING:
    from .system import System

__all__ = ["Body", "Field", "Pose", "PlanarBody", "RigidBody", "PointMass", "BODY_TYPES", "check_parameter_values"]

#: The body types by their ``file_type`` (``"planar"``, ``"rigid"``, ``"point"``): every subclass of
#: :class:`Body` that sets ``file_type`` is entered here, and model files can hold it.
BODY_TYPES: dict[str, type[Body]] = {}

#: Relative tolerance of the physical checks of :func:`check_parameter_values`.
_PHYSICAL_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Field:
    """A constructor argument of a body type: which symbols it may use and how model files hold it.

    Attributes
    ----------
    name : str
        The keyword argument, the attribute and the model-file field.
    kind : str
        ``"expression"`` (a scalar), ``"point"`` (a position of :attr:`Body.dimensions` entries; in
        a model file also the name of a point), ``"tensor"`` (a symmetric 3x3 matrix; in a model file
        also 3 principal moments), ``"rotation"`` (a 3x3 matrix or a
        :class:`~kronlag.model.rotations.RotationSequence`) or ``"flag"`` (a bool, not an expression).
    varies : bool
        An expression of the coordinates (the pose); otherwise a constant (mass, inertia).
    required : bool
        False for a keyword argument with a default.
    """

    name: str
    kind: str
    varies: bool = False
    required: bool = True

    @property
    def is_expression(self) -> bool:
        """Whether the value is made of expressions (whose symbols are checked)."""
        return self.kind != "flag"


@dataclass(frozen=True)
class Pose:
    """A body's placement: its frame (origin at the centre of mass, body axes) and, in the plane,
    its orientation angle (0 for a body without one and in space)."""

    frame: Frame
    angle: sp.Expr = sp.Integer(0)


class Body(ABC):
    """A body of a :class:`~kronlag.System`: the interface every body type implements.

    A subclass is a frozen dataclass whose constructor takes ``name`` and the keyword
    arguments :attr:`fields`; setting :attr:`file_type` enters it in :data:`BODY_TYPES`.

    Attributes
    ----------
    name : str
    mass : expression
    position : (d, 1) matrix of expressions of q
        The centre of mass in the world frame.
    """

    name: str
    mass: sp.Expr
    position: sp.ImmutableMatrix

    #: The type's name in model files (``type = "planar"``); ``None``: model files cannot hold it.
    file_type: ClassVar[str | None] = None
    #: The constructor's keyword arguments after ``name``, in the order model files write them.
    fields: ClassVar[tuple[Field, ...]]
    #: The lengths the position may have: the dimensions of the systems the body can be part of.
    dimensions: ClassVar[tuple[int, ...]]
    #: What messages call a body of this type (``"planar body"``).
    kind: ClassVar[str]
    #: Whether the body has an orientation: takes torques, carries points off its centre of mass and
    #: can be held by joints that hold orientations.
    oriented: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "file_type" in vars(cls):
            BODY_TYPES[cls.file_type] = cls

    def _identify(self, name: str, mass) -> str:
        """Set the checked ``name`` and ``mass``; returns ``"body '<name>'"``, which the other fields' messages use."""
        what = f"body {name!r}"
        object.__setattr__(self, "name", check_name(name, "body"))
        object.__setattr__(self, "mass", as_scalar(mass, f"{what} mass"))
        return what

    def _place(self, position, what: str) -> None:
        object.__setattr__(self, "position", as_vector(position, f"{what} position", self.dimensions))

    @property
    def dimension(self) -> int:
        """2 for a body in the plane, 3 for one in space."""
        return self.position.rows

    # -- the derivation -------------------------------------------------------------------------

    def kinetic_terms(self, calculus: Calculus) -> tuple[KineticTerm, ...]:
        """The terms of the kinetic energy: here ``1/2 m v^T v`` of the centre of mass, to which
        oriented bodies add the rotation ``1/2 omega^T I omega``."""
        return (KineticTerm(calculus.velocity(self.position), calculus.scalar(self.mass)),)

    def angular_velocity(self, calculus: Calculus) -> Velocity | None:
        """``omega = J qd`` in the frame of the body's inertia (a scalar in the plane); ``None`` without
        an orientation."""
        return None

    def generalized_torque(self, calculus: Calculus, torque: sp.ImmutableMatrix, frame: str) -> Any:
        """The generalized force ``J^T torque`` of a torque on the body, ``J`` the Jacobian of its angular
        velocity; ``torque`` is from :meth:`torque_components` (here in the frame of the angular velocity),
        ``frame`` ``"world"`` or ``"body"``."""
        velocity = self.angular_velocity(calculus)
        if velocity is None:
            raise ModelError(f"{self.kind} {self.name!r} cannot take a torque")
        return velocity.jacobian.T * calculus.matrix(torque)

    # -- the model ------------------------------------------------------------------------------

    @abstractmethod
    def pose(self) -> Pose:
        """The body's frame and planar angle."""

    def point(self, local: Iterable) -> sp.Matrix:
        """World position ``r_c + R s`` of the point with body coordinates ``s`` (from the centre of mass)."""
        if not self.oriented and any(sp.sympify(x) != 0 for x in local):
            raise ModelError(f"{self.kind} {self.name!r} has no extent: a point on it must be at (0, ...), "
                             f"got {tuple(local)}")
        return self.pose().frame.point(local)

    def torque_components(self, torque, what: str) -> sp.ImmutableMatrix:
        """A torque on the body as a column: a scalar in the plane, a 3-vector in space (``what`` names
        it in errors)."""
        raise ModelError(f"{what} acts on {self.kind} {self.name!r}, which cannot take a torque")

    def expressions(self) -> list[tuple[str, sp.Basic, bool]]:
        """``(field, value, varies)`` for the fields made of expressions; ``varies``: may depend on q."""
        return [(field.name, getattr(self, field.name), field.varies) for field in self.fields if field.is_expression]

    def arguments(self) -> dict[str, object]:
        """The keyword arguments that make the body again: ``type(body)(body.name, **body.arguments())``."""
        return {field.name: getattr(self, field.name) for field in self.fields}

    def check_values(self, number: Callable[[object, str], float]) -> None:
        """Check that the body is physical; ``number(expr, what)`` is the value of an expression.

        Raises
        ------
        ModelError
            Naming the body, the quantity and its value.
        """
        mass = number(self.mass, f"body {self.name!r} mass")
        if not mass >= 0:
            raise ModelError(f"body {self.name!r}: mass = {mass:.6g} ({self.mass}); a mass must not be negative")


@dataclass(frozen=True)
class PlanarBody(Body):
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

    file_type = "planar"
    fields = (Field("mass", "expression"), Field("inertia", "expression"), Field("position", "point", varies=True),
              Field("angle", "expression", varies=True))
    dimensions = (2,)
    kind = "planar body"

    def __init__(self, name: str, *, mass, inertia, position, angle):
        what = self._identify(name, mass)
        object.__setattr__(self, "inertia", as_scalar(inertia, f"{what} inertia"))
        self._place(position, what)
        object.__setattr__(self, "angle", as_scalar(angle, f"{what} angle"))

    def kinetic_terms(self, calculus: Calculus) -> tuple[KineticTerm, ...]:
        return (*super().kinetic_terms(calculus),
                KineticTerm(self.angular_velocity(calculus), calculus.scalar(self.inertia)))

    def angular_velocity(self, calculus: Calculus) -> Velocity:
        return calculus.velocity(sp.ImmutableMatrix([self.angle]))

    def pose(self) -> Pose:
        return Pose(Frame(self.position, planar_rotation(self.angle)), self.angle)

    def torque_components(self, torque, what: str) -> sp.ImmutableMatrix:
        if isinstance(torque, Iterable) and not isinstance(torque, sp.Expr | str):
            raise ModelError(f"{what} on {self.kind} {self.name!r} must be a scalar")
        return sp.ImmutableMatrix([as_scalar(torque, what)])

    def check_values(self, number: Callable[[object, str], float]) -> None:
        super().check_values(number)
        inertia = number(self.inertia, f"body {self.name!r} inertia")
        if inertia < 0:
            raise ModelError(f"body {self.name!r}: moment of inertia = {inertia:.6g} ({self.inertia}); "
                             "it must not be negative")


@dataclass(frozen=True)
class RigidBody(Body):
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

    file_type = "rigid"
    fields = (Field("mass", "expression"), Field("inertia", "tensor"), Field("position", "point", varies=True),
              Field("rotation", "rotation", varies=True), Field("simplify", "flag", required=False))
    dimensions = (3,)
    kind = "rigid body"

    def __init__(self, name: str, *, mass, inertia, position, rotation, simplify: bool = True):
        what = self._identify(name, mass)
        tensor = as_matrix(inertia, (3, 3), f"{what} inertia tensor")
        asymmetric = [(i, j) for i in range(3) for j in range(i + 1, 3)
                      if sp.simplify(tensor[i, j] - tensor[j, i]) != 0]
        if asymmetric:
            i, j = asymmetric[0]
            raise ModelError(f"{what} inertia tensor is not symmetric: entry [{i},{j}] = {tensor[i, j]} "
                             f"but [{j},{i}] = {tensor[j, i]}")
        object.__setattr__(self, "inertia", tensor)
        self._place(position, what)
        if isinstance(rotation, RotationSequence):
            object.__setattr__(self, "rotation_sequence", rotation)
            object.__setattr__(self, "rotation", rotation.matrix)
        else:
            object.__setattr__(self, "rotation_sequence", None)
            matrix = as_matrix(rotation, (3, 3), f"{what} rotation")
            check_rotation(matrix, f"{what} rotation")
            object.__setattr__(self, "rotation", matrix)
        object.__setattr__(self, "simplify", bool(simplify))

    def kinetic_terms(self, calculus: Calculus) -> tuple[KineticTerm, ...]:
        return (*super().kinetic_terms(calculus),
                KineticTerm(self.angular_velocity(calculus), calculus.matrix(self.inertia)))

    def angular_velocity(self, calculus: Calculus) -> Velocity:
        return calculus.angular_velocity(self)

    def generalized_torque(self, calculus: Calculus, torque: sp.ImmutableMatrix, frame: str) -> Any:
        """``J_R^T R^T torque`` for a torque in world components, ``J_R^T torque`` in body components."""
        components = calculus.matrix(torque)
        if frame == "world":
            components = calculus.matrix(self.rotation).T * components
        return self.angular_velocity(calculus).jacobian.T * components

    def pose(self) -> Pose:
        return Pose(Frame(self.position, self.rotation))

    def torque_components(self, torque, what: str) -> sp.ImmutableMatrix:
        return as_vector(torque, what, (3,))

    def arguments(self) -> dict[str, object]:
        arguments = super().arguments()
        if self.rotation_sequence is not None:
            arguments["rotation"] = self.rotation_sequence
        return arguments

    def check_values(self, number: Callable[[object, str], float]) -> None:
        super().check_values(number)
        what = f"body {self.name!r}"
        tensor = np.array([[number(self.inertia[i, j], f"{what} inertia[{i},{j}]") for j in range(3)]
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


@dataclass(frozen=True)
class PointMass(Body):
    """A particle of mass ``mass`` at ``position`` (2 or 3 expressions of q)."""

    name: str
    mass: sp.Expr
    position: sp.ImmutableMatrix

    file_type = "point"
    fields = (Field("mass", "expression"), Field("position", "point", varies=True))
    dimensions = (2, 3)
    kind = "point mass"
    oriented = False

    def __init__(self, name: str, *, mass, position):
        self._place(position, self._identify(name, mass))

    def pose(self) -> Pose:
        return Pose(Frame(self.position))


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
            body.check_values(number)
        except _NotReal:
            continue


class _NotReal(Exception):
    """A body's mass or inertia is not a real number (see :func:`check_parameter_values`)."""
