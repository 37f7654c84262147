"""Frames, rotations and points fixed in a body.

Rotation matrices ``R`` map body-frame components to world components
(``r_world = origin + R r_body``), as :class:`~kronlag.RigidBody` expects:

- :func:`elementary_rotation` (``R_x``, ``R_y``, ``R_z``), :func:`axis_angle`
  (Rodrigues), :func:`euler_sequence` (Euler/Cardan angles, intrinsic or
  extrinsic) and :func:`euler_parameters` (unit quaternion ``e0, e1, e2, e3``,
  whose normalization constraint :func:`euler_parameter_constraint` returns);
- :class:`Frame`: an origin and a rotation, composed with ``*``;
- :func:`body_frame`, :func:`body_point`: the world position of a point given in
  body coordinates (relative to the body's centre of mass, in its body frame);
- :func:`point_velocity`, :func:`point_acceleration`: its time derivatives by
  Theorem 1 of Van Khang (2011), ``d r/dt = dr/dq (I ⊗ qd)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp

from .calculus import time_derivative
from .system import (
    ModelError,
    PlanarBody,
    PointMass,
    RigidBody,
    acceleration_symbol,
    speed_symbol,
)

__all__ = [
    "elementary_rotation",
    "planar_rotation",
    "axis_angle",
    "euler_sequence",
    "euler_parameters",
    "euler_parameter_constraint",
    "euler_parameters_of",
    "skew",
    "Frame",
    "body_frame",
    "body_point",
    "point_velocity",
    "point_acceleration",
]


def _elementary_entries(c, s) -> dict[str, list[list]]:
    return {
        "x": [[1, 0, 0], [0, c, -s], [0, s, c]],
        "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
        "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]],
    }


def elementary_rotation(axis: str, angle) -> sp.Matrix:
    """Rotation by ``angle`` about the body axis ``"x"``, ``"y"`` or ``"z"``, shape (3, 3).

    >>> elementary_rotation("z", sp.Symbol("a"))
    Matrix([
    [cos(a), -sin(a), 0],
    [sin(a),  cos(a), 0],
    [     0,       0, 1]])
    """
    entries = _elementary_entries(sp.cos(angle), sp.sin(angle))
    if axis not in entries:
        raise ModelError(f"rotation axis must be 'x', 'y' or 'z', got {axis!r}")
    return sp.Matrix(entries[axis])


def planar_rotation(angle) -> sp.Matrix:
    """Rotation of the plane by ``angle``, shape (2, 2)."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[c, -s], [s, c]])


def skew(vector) -> sp.Matrix:
    """The matrix ``[v]x`` with ``[v]x w = v x w``, shape (3, 3)."""
    x, y, z = _vector(vector, "skew: vector", 3)
    return sp.Matrix([[0, -z, y], [z, 0, -x], [-y, x, 0]])


def axis_angle(axis, angle) -> sp.Matrix:
    """Rotation by ``angle`` about ``axis`` (Rodrigues): ``R = I + sin a K + (1 - cos a) K^2``.

    ``K = [u]x`` with ``u = axis / |axis|``; the axis must not be zero.

    >>> R = axis_angle((0, 0, 2), sp.Symbol("a"))
    >>> R == elementary_rotation("z", sp.Symbol("a"))
    True
    """
    direction = _vector(axis, "axis_angle: axis", 3)
    length = sp.sqrt(sum(entry ** 2 for entry in direction))
    if length == 0:
        raise ModelError("axis_angle: the axis is the zero vector")
    K = skew(direction / length)
    return sp.eye(3) + sp.sin(angle) * K + (1 - sp.cos(angle)) * K * K


def euler_sequence(axes: str, angles: Sequence, *, extrinsic: bool = False) -> sp.Matrix:
    """Rotation from Euler/Cardan angles, e.g. ``"zxz"`` (Euler) or ``"xyz"`` (Cardan).

    Intrinsic (default; rotations about the axes of the moving frame):
    ``R = R_a1(angle1) R_a2(angle2) R_a3(angle3)``.  Extrinsic (about the fixed
    axes, in the order given): ``R = R_a3(angle3) R_a2(angle2) R_a1(angle1)``.

    >>> psi, theta, phi = sp.symbols("psi theta phi")
    >>> euler_sequence("zxz", (psi, theta, phi)) == (elementary_rotation("z", psi)
    ...     * elementary_rotation("x", theta) * elementary_rotation("z", phi))
    True
    """
    if not isinstance(axes, str) or not axes or any(axis not in "xyz" for axis in axes):
        raise ModelError(f"euler_sequence: axes must be a non-empty string of x, y, z, got {axes!r}")
    angles = list(angles)
    if len(angles) != len(axes):
        raise ModelError(f"euler_sequence: {len(axes)} axes {axes!r} need {len(axes)} angles, got {len(angles)}")
    factors = [elementary_rotation(axis, angle) for axis, angle in zip(axes, angles)]
    rotation = sp.eye(3)
    for factor in (reversed(factors) if extrinsic else factors):
        rotation = rotation * factor
    return rotation


def euler_parameters(e0, e1, e2, e3) -> sp.Matrix:
    """Rotation from Euler parameters (a unit quaternion ``e0 + e1 i + e2 j + e3 k``).

    ``R = (e0^2 - e^T e) I + 2 (e e^T + e0 [e]x)`` with ``e = (e1, e2, e3)``, the
    homogeneous form (equal to ``(2 e0^2 - 1) I + 2 (e e^T + e0 [e]x)`` on the unit
    sphere, and ``R^T R = (e0^2 + e^T e)^2 I`` everywhere); it is a rotation only where
    ``e0^2 + e1^2 + e2^2 + e3^2 = 1``: add :func:`euler_parameter_constraint` to the
    system (:func:`kronlag.joints.free_body` does).
    """
    e = sp.Matrix([e1, e2, e3])
    return (e0 ** 2 - (e.T * e)[0, 0]) * sp.eye(3) + 2 * (e * e.T + e0 * skew(e))


def euler_parameter_constraint(e0, e1, e2, e3) -> sp.Expr:
    """The normalization constraint ``e0^2 + e1^2 + e2^2 + e3^2 - 1 = 0`` of Euler parameters."""
    return e0 ** 2 + e1 ** 2 + e2 ** 2 + e3 ** 2 - 1


def euler_parameters_of(rotation) -> np.ndarray:
    """Euler parameters ``(e0, e1, e2, e3)``, ``e0 >= 0``, of a numeric rotation matrix, shape (4,).

    The inverse of :func:`euler_parameters` (for initial guesses of bodies placed by
    Euler parameters); the largest of ``e0^2 .. e3^2`` is taken from the diagonal
    first, which keeps the result accurate for every rotation.

    >>> euler_parameters_of(np.array(elementary_rotation("z", np.pi / 2), dtype=float)).round(6)
    array([0.707107, 0.      , 0.      , 0.707107])
    """
    R = np.asarray(rotation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ModelError(f"euler_parameters_of: expected a 3x3 rotation matrix, got {R.tolist()}")
    squares = 0.25 * (1 + np.array([np.trace(R), 2 * R[0, 0] - np.trace(R), 2 * R[1, 1] - np.trace(R),
                                    2 * R[2, 2] - np.trace(R)]))
    k = int(np.argmax(squares))
    e = np.empty(4)
    e[k] = np.sqrt(squares[k])
    # off-diagonal sums and differences: 4 e0 e_i = R_kj - R_jk, 4 e_i e_j = R_ij + R_ji
    products = {(0, 1): R[2, 1] - R[1, 2], (0, 2): R[0, 2] - R[2, 0], (0, 3): R[1, 0] - R[0, 1],
                (1, 2): R[0, 1] + R[1, 0], (1, 3): R[0, 2] + R[2, 0], (2, 3): R[1, 2] + R[2, 1]}
    for (i, j), value in products.items():
        if k in (i, j):
            e[j if k == i else i] = value / (4 * e[k])
    return e if e[0] >= 0 else -e


def _vector(value, what: str, length: int) -> sp.Matrix:
    try:
        entries = list(value)
    except TypeError as error:
        raise ModelError(f"{what}: expected {length} entries, got {type(value).__name__}") from error
    if len(entries) != length:
        raise ModelError(f"{what}: expected {length} entries, got {len(entries)}")
    return sp.Matrix([sp.sympify(entry) for entry in entries])


@dataclass(frozen=True)
class Frame:
    """A frame: ``origin`` (d,) and ``rotation`` (d, d) in world components, d = 2 or 3.

    ``frame.point(r)`` is ``origin + rotation r``; ``parent * child`` places a frame
    given relative to ``parent`` in the world (``origin_p + R_p origin_c``, ``R_p R_c``).
    """

    origin: sp.ImmutableMatrix
    rotation: sp.ImmutableMatrix

    def __init__(self, origin=(0, 0, 0), rotation=None):
        origin = sp.ImmutableMatrix(_vector(origin, "Frame origin", len(list(origin))))
        if origin.rows not in (2, 3):
            raise ModelError(f"Frame origin: expected 2 or 3 entries, got {origin.rows}")
        rotation = sp.eye(origin.rows) if rotation is None else sp.Matrix(rotation)
        if rotation.shape != (origin.rows, origin.rows):
            raise ModelError(f"Frame rotation: expected shape {(origin.rows, origin.rows)} to match the "
                             f"origin, got {rotation.shape}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "rotation", sp.ImmutableMatrix(rotation))

    @property
    def dimension(self) -> int:
        return self.origin.rows

    def point(self, local) -> sp.Matrix:
        """World position of the point with frame coordinates ``local``."""
        return sp.Matrix(self.origin) + self.rotation * _vector(local, "point", self.dimension)

    def direction(self, local) -> sp.Matrix:
        """World components of the direction with frame components ``local``."""
        return sp.Matrix(self.rotation * _vector(local, "direction", self.dimension))

    def __mul__(self, child: Frame) -> Frame:
        if not isinstance(child, Frame):
            return NotImplemented
        if child.dimension != self.dimension:
            raise ModelError(f"cannot compose a {self.dimension}-d frame with a {child.dimension}-d frame")
        return Frame(self.point(child.origin), self.rotation * child.rotation)

    def inverse(self) -> Frame:
        """The world frame seen from this frame: ``(-R^T origin, R^T)``."""
        return Frame(-self.rotation.T * self.origin, self.rotation.T)


def body_frame(body: PlanarBody | RigidBody | PointMass) -> Frame:
    """The body frame: origin at the centre of mass, axes of the body's rotation.

    A point mass has no orientation; its frame has the world axes.
    """
    if isinstance(body, PlanarBody):
        return Frame(body.position, planar_rotation(body.angle))
    if isinstance(body, RigidBody):
        return Frame(body.position, body.rotation)
    if isinstance(body, PointMass):
        return Frame(body.position)
    raise ModelError(f"expected a PlanarBody, RigidBody or PointMass, got {type(body).__name__}")


def body_point(body: PlanarBody | RigidBody | PointMass, local) -> sp.Matrix:
    """World position ``r_c + R s`` of the point with body coordinates ``s`` (from the centre of mass)."""
    if isinstance(body, PointMass) and any(sp.sympify(x) != 0 for x in local):
        raise ModelError(f"point mass {body.name!r} has no extent: a point on it must be at (0, ...), "
                         f"got {tuple(local)}")
    return body_frame(body).point(local)


def point_velocity(position, coordinates: Sequence[sp.Symbol]) -> sp.Matrix:
    """``v = dr/dt = dr/dq (I_1 ⊗ qd)`` (Theorem 1), in the speed symbols ``q1d, ...``."""
    coordinates = list(coordinates)
    return time_derivative(sp.Matrix(position), coordinates, [speed_symbol(q) for q in coordinates])


def point_acceleration(position, coordinates: Sequence[sp.Symbol]) -> sp.Matrix:
    """``a = dv/dt`` with ``v`` from :func:`point_velocity`, Theorem 1 over ``(q, qd)``.

    In the speed and acceleration symbols: ``a = J qdd + (dJ/dt) qd``, ``J = dr/dq``.
    """
    coordinates = list(coordinates)
    speeds = [speed_symbol(q) for q in coordinates]
    velocity = point_velocity(position, coordinates)
    return time_derivative(velocity, coordinates + speeds, speeds + [acceleration_symbol(q) for q in coordinates])


@dataclass(frozen=True)
class BodyPoint:
    """A named point fixed in a body (see :meth:`kronlag.System.add_point`).

    Attributes
    ----------
    name : str
    body : str
        Name of the body, or ``"ground"`` for a point fixed in the world.
    local : (d,) body coordinates (from the centre of mass, body axes; world coordinates on ground).
    position : (d,) world position, an expression of q.
    """

    name: str
    body: str
    local: sp.ImmutableMatrix
    position: sp.ImmutableMatrix


#: The body name of points fixed in the world (and of the first body of a joint to the ground).
GROUND = "ground"


def make_body_point(system, name: str, body: str, local) -> BodyPoint:
    """The :class:`BodyPoint` ``name`` at body coordinates ``local`` of ``body`` of ``system``."""
    dimension = system.dimension
    if body == GROUND:
        if dimension is None:
            raise ModelError(f"point {name!r} on the ground: the system's dimension is not known yet "
                             "(give gravity or add a body first)")
        position = _vector(local, f"point {name!r} position", dimension)
    else:
        target = system.body(body)
        position = body_point(target, _vector(local, f"point {name!r} on body {body!r}", target.dimension))
    return BodyPoint(name, body, sp.ImmutableMatrix(_vector(local, f"point {name!r}", position.rows)),
                     sp.ImmutableMatrix(position))


def point_kinematics(system, name: str) -> dict[str, sp.Matrix]:
    """Symbolic kinematics of the named point of ``system``.

    Returns
    -------
    dict
        ``position`` r (d, 1), ``J = dr/dq`` (d, m) and ``Jd_qd = (dJ/dt) qd`` (d, 1),
        so that ``v = J qd`` and ``a = J qdd + Jd_qd``.
    """
    position = sp.Matrix(system.point(name).position)
    coordinates = list(system.coordinates)
    speeds = sp.Matrix([speed_symbol(q) for q in coordinates])
    jacobian = position.jacobian(coordinates)
    return {"position": position, "J": jacobian,
            "Jd_qd": time_derivative(jacobian, coordinates, speeds) * speeds}
