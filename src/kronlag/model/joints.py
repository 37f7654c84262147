"""Joints: named holonomic constraints between two bodies, and their reaction wrenches.

A joint connects body A (``"ground"`` for the world) and body B at a point
given in each body's coordinates (``at_a``, ``at_b``: from the centre of mass,
in the body frame; on the ground, world coordinates) and adds its constraint
rows ``Phi_J(q) = 0`` to the system as ``"<joint>.<row>"``.  The rows are
written in the bodies' poses, so they serve both styles:

- redundant body coordinates (each body with its own position and rotation
  coordinates, :func:`free_body` and :func:`mechanism`), where every joint
  gives constraints;
- joint-angle coordinates (bodies placed by the angles of a tree), where a
  joint is added only where a loop closes.

Kinds (``P_A``, ``P_B``: world positions of the joint points; ``R_A``, ``R_B``:
rotations; ``theta``: planar angles; ``a``: ``axis`` in A's frame, ``b``:
``axis_b`` in B's frame, ``n = R_A perp(a)``, ``p1, p2`` unit normals of ``a``)::

    planar   revolute     P_B - P_A = 0                                  x, y
             prismatic    n . (P_B - P_A) = 0,  theta_B - theta_A - angle = 0   normal, angle
             pin_in_slot  n . (P_B - P_A) = 0  (pin of B in a slot of A)  normal
             rigid        P_B - P_A = 0, theta_B - theta_A - angle = 0   x, y, angle
    spatial  spherical    P_B - P_A = 0                                  x, y, z
             revolute     spherical + (R_A p_i) . (R_B b) = 0            x, y, z, axis1, axis2
             cylindrical  (R_A p_i) . (P_B - P_A) = 0, (R_A p_i) . (R_B b) = 0
                                                                         normal1, normal2, axis1, axis2
             prismatic    (R_A p_i) . (P_B - P_A) = 0 + orientation lock normal1, normal2, rx, ry, rz
             universal    spherical + (R_A a) . (R_B b) = 0              x, y, z, cross
             rigid        spherical + orientation lock                   x, y, z, rx, ry, rz

The orientation lock holds ``R_B = R_A R0`` (``rotation``, default I) by the
rows ``(R_A R0 e_y).(R_B e_z)``, ``(R_A R0 e_z).(R_B e_x)``, ``(R_A R0 e_x).(R_B e_y)``.

Reactions
---------
With Eq. 23, ``M qdd + C qd + Phi_q^T lambda + ... = f_Q``, the constraint
forces are ``-Phi_q^T lambda``.  The reaction of a joint is the wrench that
body A exerts on body B, reduced at B's joint point ``P_B``, in world
components::

    [F; T] = W(q) lambda_J,   W = -(dPhi_J / d(P_B, pi_B))^T

where ``P_B`` is moved with B's orientation held and ``pi_B`` is a small
rotation of B about ``P_B`` (world components; the angle for planar
systems).  Body B feels ``F`` at ``P_B`` and the couple ``T``; body A feels
``-F`` at ``P_B`` and ``-T`` (the rows depend on relative placements only).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp

from ..core.errors import ModelError
from .bodies import Pose
from .frames import GROUND, BodyPoint, Frame
from .friction import Friction, check_friction
from .rotations import skew

if TYPE_CHECKING:
    from .system import System

__all__ = ["Joint", "add_joint", "JOINT_KINDS"]


@dataclass(frozen=True)
class _Geometry:
    at_a: sp.Matrix
    at_b: sp.Matrix
    axis: sp.Matrix | None
    axis_b: sp.Matrix | None
    angle: sp.Expr
    rotation: sp.Matrix


Rows = list[tuple[str, sp.Expr]]


def _dot(u: sp.Matrix, v: sp.Matrix) -> sp.Expr:
    return (u.T * v)[0, 0]


def _separation(a: Pose, b: Pose, g: _Geometry) -> sp.Matrix:
    """``P_B - P_A``: from A's joint point to B's."""
    return b.frame.point(g.at_b) - a.frame.point(g.at_a)


def _coincident(a: Pose, b: Pose, g: _Geometry) -> Rows:
    return list(zip("xyz", _separation(a, b, g)))


def _planar_normal(a: Pose, b: Pose, g: _Geometry) -> Rows:
    normal = a.frame.direction(sp.Matrix([-g.axis[1], g.axis[0]]))
    return [("normal", _dot(normal, _separation(a, b, g)))]


def _planar_angle(a: Pose, b: Pose, g: _Geometry) -> Rows:
    return [("angle", b.angle - a.angle - g.angle)]


def _unit_normals(axis: sp.Matrix) -> tuple[sp.Matrix, sp.Matrix]:
    """Two unit vectors ``p1, p2`` with ``(p1, p2, axis/|axis|)`` right-handed and orthonormal."""
    unit = axis / axis.norm()
    helper = sp.eye(3)[:, min(range(3), key=lambda i: abs(float(unit[i])))]
    p1 = unit.cross(helper)
    p1 = sp.simplify(p1 / p1.norm())
    return p1, sp.simplify(unit.cross(p1))


def _axis_alignment(a: Pose, b: Pose, g: _Geometry) -> Rows:
    p1, p2 = _unit_normals(g.axis)
    axis_b = b.frame.direction(g.axis_b)
    return [("axis1", _dot(a.frame.direction(p1), axis_b)), ("axis2", _dot(a.frame.direction(p2), axis_b))]


def _spatial_normal(a: Pose, b: Pose, g: _Geometry) -> Rows:
    separation = _separation(a, b, g)
    return [(f"normal{i + 1}", _dot(a.frame.direction(p), separation)) for i, p in enumerate(_unit_normals(g.axis))]


def _orientation_lock(a: Pose, b: Pose, g: _Geometry) -> Rows:
    expected = a.frame.rotation * g.rotation
    e = sp.eye(3)
    return [(name, _dot(expected * e[:, i], b.frame.rotation * e[:, j]))
            for name, i, j in (("rx", 1, 2), ("ry", 2, 0), ("rz", 0, 1))]


def _cross_axes(a: Pose, b: Pose, g: _Geometry) -> Rows:
    return [("cross", _dot(a.frame.direction(g.axis), b.frame.direction(g.axis_b)))]


@dataclass(frozen=True)
class _Kind:
    rows: tuple[Callable[[Pose, Pose, _Geometry], Rows], ...]
    needs: tuple[str, ...] = ()  # geometry the kind needs: "axis", "axis_b"
    turns: bool = False  # uses the orientation of both bodies (not for bodies without one: point masses)
    accepts: tuple[str, ...] = ()  # optional geometry it uses: "axis_b", "angle", "rotation"


#: Joint kinds by dimension and name.
JOINT_KINDS: dict[int, dict[str, _Kind]] = {
    2: {
        "revolute": _Kind((_coincident,)),
        "prismatic": _Kind((_planar_normal, _planar_angle), ("axis",), turns=True, accepts=("angle",)),
        "pin_in_slot": _Kind((_planar_normal,), ("axis",)),
        "rigid": _Kind((_coincident, _planar_angle), turns=True, accepts=("angle",)),
    },
    3: {
        "spherical": _Kind((_coincident,)),
        "revolute": _Kind((_coincident, _axis_alignment), ("axis",), turns=True, accepts=("axis_b",)),
        "cylindrical": _Kind((_spatial_normal, _axis_alignment), ("axis",), turns=True, accepts=("axis_b",)),
        "prismatic": _Kind((_spatial_normal, _orientation_lock), ("axis",), turns=True, accepts=("rotation",)),
        "universal": _Kind((_coincident, _cross_axes), ("axis", "axis_b"), turns=True),
        "rigid": _Kind((_coincident, _orientation_lock), turns=True, accepts=("rotation",)),
    },
}


@dataclass(frozen=True)
class Joint:
    """A joint added by :func:`add_joint`.

    Attributes
    ----------
    name, kind : str
    body_a, body_b : str
        ``body_a`` may be ``"ground"``.
    constraint_names : tuple of str
        Its rows in ``system.constraints`` (``"<name>.x"``, ...), k of them.
    point : (d, 1)
        ``P_B(q)``, the world position of B's joint point, where the reaction is reduced.
    rotation_b : (d, d)
        ``R_B(q)``; body-frame components of the reaction are ``R_B^T F`` and ``R_B^T T``.
    wrench : (d + d_rot, k)
        ``W(q)``: ``[F; T] = W lambda_J`` is the wrench A exerts on B (world
        components; ``d_rot`` is 1 planar, 3 spatial).
    geometry : tuple of (str, value)
        The geometry it was added with (``at_a``, ``at_b`` as body coordinates, and
        whichever of ``axis``, ``axis_b``, ``angle``, ``rotation`` its kind uses), so
        that ``add_joint(kind, body_a, body_b, name=name, **dict(geometry))`` adds it again.
    friction : Friction or None
        Its friction (:mod:`kronlag.model.friction`), if any.
    """

    name: str
    kind: str
    body_a: str
    body_b: str
    constraint_names: tuple[str, ...]
    point: sp.ImmutableMatrix
    rotation_b: sp.ImmutableMatrix
    wrench: sp.ImmutableMatrix
    geometry: tuple[tuple[str, object], ...] = ()
    friction: Friction | None = None

    @property
    def dimension(self) -> int:
        return self.point.rows


def _pose(system: System, name: str, dimension: int) -> Pose:
    return Pose(Frame((0,) * dimension)) if name == GROUND else system.body(name).pose()


def _virtual_pose(pose: Pose, at_b: sp.Matrix, point: sp.Matrix, turn: sp.Matrix) -> Pose:
    """B's pose moved so that its joint point is at ``point`` and turned by ``turn`` about it
    (to first order): ``R' = (I + [turn]x) R``, ``origin' = point - R' at_b`` (in the plane
    ``turn`` is one angle, which also turns the planar angle)."""
    rotation = (sp.eye(point.rows) + skew(turn)) * pose.frame.rotation
    angle = pose.angle + turn[0] if turn.rows == 1 else pose.angle
    return Pose(Frame(point - rotation * at_b, rotation), angle)


def _local(system: System, value, body: str, dimension: int, what: str) -> sp.Matrix:
    """Body coordinates from a vector or the name of a point of ``body``."""
    if isinstance(value, str):
        point: BodyPoint = system.point(value)
        if point.body != body:
            raise ModelError(f"{what}: point {value!r} is on {point.body!r}, not on {body!r}")
        value = point.local
    try:
        entries = [sp.sympify(x) for x in value]
    except (TypeError, sp.SympifyError) as error:
        raise ModelError(f"{what}: expected {dimension} numbers or expressions, got {value!r}") from error
    if len(entries) != dimension:
        raise ModelError(f"{what}: expected {dimension} entries, got {len(entries)}")
    return sp.Matrix(entries)


def _axis(value, dimension: int, what: str, *, numeric: bool) -> sp.Matrix:
    try:
        entries = sp.Matrix([sp.sympify(x) for x in value])
    except (TypeError, sp.SympifyError):
        entries = None
    if entries is None or entries.rows != dimension:
        raise ModelError(f"{what}: expected a direction of {dimension} entries, got {value!r}")
    if numeric and not all(x.is_number and x.is_real for x in entries):
        raise ModelError(f"{what}: the entries of a spatial axis must be numbers, got {list(entries)}")
    if all(x == 0 for x in entries):
        raise ModelError(f"{what}: the axis is the zero vector")
    return entries


def add_joint(system: System, kind: str, body_a: str, body_b: str, *, at_a=None, at_b=None, axis=None,
              axis_b=None, angle=0, rotation=None, name: str | None = None,
              friction: Friction | None = None) -> Joint:
    """Add a joint between ``body_a`` (``"ground"`` for the world) and ``body_b``.

    Parameters
    ----------
    system : System
    kind : str
        A key of ``JOINT_KINDS[d]`` (see the module docstring), d = the system's dimension.
    body_a, body_b : str
        Body names; ``body_a`` may be ``"ground"``.
    at_a, at_b : d numbers/expressions or the name of a point of that body, optional
        The joint point in each body's coordinates (default: the centre of mass;
        on the ground: world coordinates, default the origin).
    axis : d entries, optional
        In A's frame: the sliding direction (planar prismatic, pin_in_slot), the
        joint axis (spatial revolute, cylindrical, prismatic) or A's cross axis
        (universal).  Spatial axes must be numbers.
    axis_b : 3 entries, optional
        In B's frame: the joint axis (revolute, cylindrical; default ``axis``) or
        B's cross axis (universal, required, perpendicular to A's at assembly).
    angle : expression
        ``theta_B - theta_A`` held by planar prismatic and rigid joints.
    rotation : (3, 3), optional
        ``R_A^T R_B`` held by spatial prismatic and rigid joints (default I).
    name : str, optional
        Default ``"<body_a>_<body_b>_<kind>"``.
    friction : Friction, optional
        Friction from the joint's normal load (revolute and prismatic joints), see
        :mod:`kronlag.model.friction`.

    Returns
    -------
    Joint
    """
    dimension = system.dimension
    if dimension is None:
        raise ModelError(f"joint {kind!r} between {body_a!r} and {body_b!r}: add the bodies first")
    kinds = JOINT_KINDS[dimension]
    name = name or f"{body_a}_{body_b}_{kind}"
    what = f"joint {name!r}"
    if kind not in kinds:
        raise ModelError(f"{what}: unknown {dimension}-d joint kind {kind!r}; known: {', '.join(kinds)}")
    if body_b == GROUND:
        raise ModelError(f"{what}: body_b must be a body; put the ground first (body_a = 'ground')")
    if body_a == body_b:
        raise ModelError(f"{what}: joins body {body_a!r} to itself")
    if any(joint.name == name for joint in system.joints):
        raise ModelError(f"duplicate joint name {name!r}")
    spec = kinds[kind]
    if friction is not None:
        check_friction(system, friction, kind, what)
    for body in (body_a, body_b):
        if body != GROUND and spec.turns and not system.body(body).oriented:
            raise ModelError(f"{what}: a {kind} joint holds the orientation of its bodies, but {body!r} is a "
                             f"{system.body(body).kind} without one")
    if body_a != GROUND and "axis" in spec.needs and not system.body(body_a).oriented:
        raise ModelError(f"{what}: the axis of a {kind} joint is fixed in body_a, but {body_a!r} is a "
                         f"{system.body(body_a).kind} without an orientation")
    given = {"axis": axis, "axis_b": axis_b, "angle": None if angle == 0 else angle, "rotation": rotation}
    unused = [key for key, value in given.items() if value is not None and key not in (*spec.needs, *spec.accepts)]
    if unused:
        raise ModelError(f"{what}: a {dimension}-d {kind} joint does not use {', '.join(unused)}")
    missing = [key for key in spec.needs if given[key] is None]
    if missing:
        raise ModelError(f"{what}: a {dimension}-d {kind} joint needs {', '.join(f'{key}=...' for key in missing)}")
    if axis_b is None and "axis_b" in spec.accepts:
        axis_b = axis
    if rotation is not None and sp.Matrix(rotation).shape != (3, 3):
        raise ModelError(f"{what}: rotation must be a 3x3 matrix, got shape {sp.Matrix(rotation).shape}")
    zero = (0,) * dimension
    geometry = _Geometry(
        at_a=_local(system, zero if at_a is None else at_a, body_a, dimension, f"{what} at_a"),
        at_b=_local(system, zero if at_b is None else at_b, body_b, dimension, f"{what} at_b"),
        axis=None if axis is None else _axis(axis, dimension, f"{what} axis", numeric=dimension == 3),
        axis_b=None if axis_b is None else _axis(axis_b, dimension, f"{what} axis_b", numeric=dimension == 3),
        angle=sp.sympify(angle),
        rotation=sp.eye(3) if rotation is None else sp.Matrix(rotation))
    pose_a, pose_b = _pose(system, body_a, dimension), _pose(system, body_b, dimension)
    rows = [row for rule in spec.rows for row in rule(pose_a, pose_b, geometry)]

    point = sp.Matrix(sp.symbols(f"kronlag_point0:{dimension}", cls=sp.Dummy))
    turn = sp.Matrix(sp.symbols(f"kronlag_turn0:{1 if dimension == 2 else 3}", cls=sp.Dummy))
    virtual = _virtual_pose(pose_b, geometry.at_b, point, turn)
    virtual_rows = sp.Matrix([expr for rule in spec.rows for _, expr in rule(pose_a, virtual, geometry)])
    joint_point = pose_b.frame.point(geometry.at_b)
    at_state = {**dict(zip(point, joint_point)), **{x: 0 for x in turn}}
    wrench = -virtual_rows.jacobian(list(point) + list(turn)).T.subs(at_state)

    constraint_names = tuple(f"{name}.{suffix}" for suffix, _ in rows)
    existing = {c.name for c in system.constraints}
    clash = [c for c in constraint_names if c in existing]
    if clash:
        raise ModelError(f"{what}: constraint name(s) {clash} already used")
    for constraint_name, (_, expression) in zip(constraint_names, rows):
        system.add_constraint(expression, name=constraint_name)
    stored = {"at_a": geometry.at_a, "at_b": geometry.at_b, "axis": geometry.axis, "axis_b": geometry.axis_b,
              "angle": geometry.angle, "rotation": geometry.rotation}
    kept = tuple((key, sp.ImmutableMatrix(stored[key]) if key != "angle" else stored[key])
                 for key in ("at_a", "at_b", *spec.needs, *spec.accepts) if key in ("at_a", "at_b")
                 or given[key] is not None)
    joint = Joint(name, kind, body_a, body_b, constraint_names, sp.ImmutableMatrix(joint_point),
                  sp.ImmutableMatrix(pose_b.frame.rotation), sp.ImmutableMatrix(wrench), kept, friction)
    system.joints.append(joint)
    return joint
