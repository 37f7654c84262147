"""The kinematic tree of a robot file turned into a :class:`~kronlag.System` in joint coordinates,
shared by the readers (:mod:`.urdf`, :mod:`.mjcf`, :mod:`.sdf`).

A reader gives links (with their :class:`Inertial` in the link frame) and :class:`TreeJoint` s
(parent, child, the joint frame's placement in the parent link's frame as ``x y z roll pitch
yaw``, the kind and axis); :func:`build_system` places every link with the joint coordinates:
the root link is the ``ground``, ``fixed`` joints merge their child into the parent's body (masses
and inertias added by the parallel-axis theorem), a ``revolute`` (or ``continuous``) joint turns
its child about the axis, a ``prismatic`` one slides it.  Each body's rotation is a
:class:`~kronlag.RotationSequence` of the placements' elementary rotations and the joint axes, so
that its angular velocity needs no simplification; an angle within 1e-11 rad of a multiple of pi/2
is taken as that multiple exactly (:func:`exact_angle`), which keeps the expressions small.

Joints of several coordinates (:data:`JOINT_COORDINATES`), named ``<joint>_<suffix>``:
``floating`` (a floating base: ``_x _y _z``, the translation in the joint frame, then the rotation
by the Euler parameters ``_e0 .. _e3``, without gimbal lock), ``ball`` (Euler parameters), each with
the constraint ``"<joint>.normalization"`` (``e0^2 + e1^2 + e2^2 + e3^2 = 1``); ``planar``
(``_x _y`` along two unit vectors normal to the axis, ``_theta`` about it) and ``universal``
(``_1`` about the axis, then ``_2`` about ``axis2``).  Their reference pose is the joint frame
(``e0 = 1``, the other coordinates 0); they are passive (no torque parameter).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import SupportsFloat, cast
from xml.etree.ElementTree import Element

import numpy as np
import sympy as sp

from ...core.errors import InputError, ModelError
from ..bodies import RigidBody
from ..frames import GROUND, Frame
from ..rotations import (EULER_PARAMETERS, MAX_ROTATION_FACTORS, RotationSequence, euler_parameter_constraint,
                         euler_parameters, matrix_product)
from ..system import System
from ..symbols import free_symbols
from .absolute import COORDINATE_CHOICES, absolute_system
from .description import (JointLimits, RobotDescription, RobotFileWarning, RobotJoint, TreeBody, Visual,
                          coordinate_name)
from .meshes import with_mesh_bounds
from .safe_xml import XmlDocument

#: A visual as a reader gives it: ``(link, shape, size, pose in the link frame, filename)``.
VisualSpec = tuple[str, str, tuple[float, ...], np.ndarray, str | None]


def three(values: Sequence[float]) -> tuple[float, float, float]:
    """The three numbers of ``values`` (a reader's ``numbers(..., 3)``) as a 3-tuple."""
    x, y, z = values
    return x, y, z

__all__ = ["Inertial", "NO_MASS", "JOINT_COORDINATES", "TreeJoint", "at_reference", "common_ancestor", "relative_frames", "build_system", "check_inertia", "combine", "moved",
           "orientation_rows", "report_skipped", "rpy_matrix", "rpy_of", "transform"]


@dataclass(frozen=True)
class Inertial:
    """Mass, centre of mass and central inertia tensor in a link's frame."""

    mass: float
    centre: np.ndarray
    tensor: np.ndarray


NO_MASS = Inertial(0.0, np.zeros(3), np.zeros((3, 3)))


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    c, s = np.cos([roll, pitch, yaw]), np.sin([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    return rz @ ry @ rx


#: An angle of a file within this many radians of a multiple of pi/2 is that multiple: files write pi
#: to 12 significant digits (kinova's ``3.14159265359``, 2.1e-13 off; ``1.57079632679``, 4.9e-12 off
#: pi/2), and a turn of 1e-11 rad moves a point 1 m away by 10 pm, far below the precision of the
#: file's lengths.  Coarser values (``1.5708``, 3.7e-6 off pi/2) are taken as written, as Pinocchio
#: and MuJoCo take them.
ANGLE_SNAP = 1e-11


def exact_angle(value: float) -> sp.Expr:
    """An angle of the file: ``k pi/2`` exactly where ``value`` is within :data:`ANGLE_SNAP` (or double
    rounding) of it (the file means it, and exact zeros keep the expressions small: kinova's kernel has
    3.5x fewer operations), else the number as given."""
    quarter = round(value / (np.pi / 2))
    if abs(value - quarter * (np.pi / 2)) <= max(ANGLE_SNAP, 4 * np.finfo(float).eps * abs(value)):
        return quarter * sp.pi / 2
    return sp.Float(value)


def rpy_factors(roll: float, pitch: float, yaw: float) -> list[tuple[str, sp.Expr]]:
    """The elementary rotations of an ``rpy`` (zero angles left out), as RotationSequence factors."""
    return [(axis, exact_angle(angle)) for axis, angle in (("z", yaw), ("y", pitch), ("x", roll)) if angle != 0]



def transform(origin: tuple[float, ...]) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = rpy_matrix(*origin[3:])
    matrix[:3, 3] = origin[:3]
    return matrix



def combine(parts: list[Inertial]) -> Inertial:
    """The inertial of rigidly joined parts (all in one frame): total mass, centre of mass, and the
    central tensor by the parallel-axis theorem."""
    mass = sum(part.mass for part in parts)
    if mass == 0:
        return Inertial(0.0, np.zeros(3), sum((part.tensor for part in parts), np.zeros((3, 3))))
    centre = sum((part.mass * part.centre for part in parts), np.zeros(3)) / mass
    tensor = np.zeros((3, 3))
    for part in parts:
        d = part.centre - centre
        tensor += part.tensor + part.mass * (d @ d * np.eye(3) - np.outer(d, d))
    return Inertial(mass, centre, (tensor + tensor.T) / 2)


def moved(part: Inertial, transform: np.ndarray) -> Inertial:
    """``part`` given in a frame placed by ``transform``, expressed in the outer frame."""
    rotation = transform[:3, :3]
    return Inertial(part.mass, transform[:3, :3] @ part.centre + transform[:3, 3],
                     rotation @ part.tensor @ rotation.T)


#: The coordinates of each kind of joint, by the suffix of their names (``""``: the joint's name).
JOINT_COORDINATES = {"revolute": ("",), "continuous": ("",), "prismatic": ("",), "fixed": (),
                     "floating": ("x", "y", "z", "e0", "e1", "e2", "e3"), "ball": ("e0", "e1", "e2", "e3"),
                     "planar": ("x", "y", "theta"), "universal": ("1", "2")}


@dataclass
class TreeJoint:
    """A joint of the tree as a reader gives it: ``kind`` one of :data:`JOINT_COORDINATES`;
    ``origin`` the joint frame in the parent link's frame (``x y z roll pitch yaw``); ``axis`` a
    unit vector in the joint frame (``axis2`` the second of a universal joint); ``mimic``
    ``(leader, multiplier, offset)`` declared by ``mimic_element``; ``element`` names it in errors."""

    element: Element
    name: str
    kind: str
    parent: str
    child: str
    origin: tuple[float, ...]
    axis: tuple[float, float, float]
    limits: JointLimits = JointLimits()
    mimic: tuple[str, float, float] | None = None
    mimic_element: Element | None = None
    axis2: tuple[float, float, float] | None = None


def _joint_factors(axis_of_joint: Sequence[float], coordinate: sp.Symbol) -> list[tuple[object, sp.Expr]]:
    """The rotation about a joint axis as RotationSequence factors: about its axis, a principal axis
    where the axis is one."""
    axis = np.array(axis_of_joint)
    for index, name in enumerate("xyz"):
        if abs(axis[index]) == 1.0:
            return [(name, coordinate if axis[index] > 0 else -coordinate)]
    # a general axis u = Rz(phi) Ry(theta) e_z: R_u(q) = Rz(phi) Ry(theta) Rz(q) Ry(-theta) Rz(-phi)
    theta, phi = float(np.arccos(np.clip(axis[2], -1, 1))), float(np.arctan2(axis[1], axis[0]))
    turn = [("z", exact_angle(phi)), ("y", exact_angle(theta))]
    back = [("y", exact_angle(-theta)), ("z", exact_angle(-phi))]
    return [factor for factor in (*turn, ("z", coordinate), *back) if factor[1] != 0]


def _exact(x: float) -> sp.Expr:
    """``x`` as a SymPy number, an Integer where it is one to rounding: a Float ``0.0`` is not SymPy's
    zero, and ``0.0 * expr`` keeps (and makes SymPy query the assumptions of) the whole ``expr``."""
    return sp.Integer(round(x)) if abs(x - round(x)) < 1e-15 else sp.Float(x)


def _plane(axis: Sequence[float]) -> tuple[sp.Matrix, sp.Matrix]:
    """Two unit vectors ``u, v`` normal to ``axis`` with ``u x v = axis``: for the axis z, x and y (the
    next principal axes in cyclic order; projected onto the plane for a general axis)."""
    normal = np.array(axis, dtype=float)
    helper = np.eye(3)[(int(np.argmax(np.abs(normal))) + 1) % 3]
    u = helper - (helper @ normal) * normal
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    return tuple(sp.Matrix([_exact(x) for x in w]) for w in (u, v))


def _moves(factor) -> bool:
    """Whether a RotationSequence factor varies with the coordinates."""
    return factor[0] == EULER_PARAMETERS or bool(factor[1].free_symbols)


def _step(spec: TreeJoint, coordinates: list[sp.Symbol], origin: sp.Matrix,
          rotation: sp.Matrix) -> tuple[sp.Matrix, list, sp.Matrix]:
    """The child frame of a moving joint whose frame is ``(origin, rotation)``: its origin, its
    rotation's factors after the joint frame's, and its rotation."""
    kind = spec.kind
    if kind == "prismatic":
        return origin + matrix_product(rotation, sp.Matrix(spec.axis)) * coordinates[0], [], rotation
    if kind in ("floating", "planar"):
        if kind == "floating":
            shift = sp.Matrix(coordinates[:3])
        else:
            u, v = _plane(spec.axis)
            shift = u * coordinates[0] + v * coordinates[1]
        origin = origin + matrix_product(rotation, shift)
    if kind in ("floating", "ball"):
        e = tuple(coordinates[-4:])
        return origin, [(EULER_PARAMETERS, e)], matrix_product(rotation, euler_parameters(*e))
    step = _joint_factors(spec.axis, coordinates[-1] if kind == "planar" else coordinates[0])
    if kind == "universal":
        assert spec.axis2 is not None  # a reader that makes a universal joint gives its second axis
        step = step + _joint_factors(spec.axis2, coordinates[1])
    return origin, step, matrix_product(rotation, RotationSequence(step).matrix)


@dataclass
class _Placement:
    """A link frame: world origin and rotation (expressions of q), its rotation's factors, its body."""

    origin: sp.Matrix
    rotation: sp.Matrix
    factors: list
    body: str
    in_body: np.ndarray  # the link frame in its body's link frame (fixed joints), 4x4
    points: list  # joint origins from the root, for the drawing


def _body_rotation(placement: _Placement):
    """The body's rotation: its factors as a RotationSequence; a chain of more than
    MAX_ROTATION_FACTORS factors is rewritten with the constant rotations moved to its end
    (``C R_a(q) = R_{C a}(q) C``): one factor per joint about its axis at q = 0, then the constant
    rest as at most three; a body that does not turn keeps its constant matrix."""
    factors = placement.factors
    if not factors:
        return placement.rotation
    if len(factors) > MAX_ROTATION_FACTORS:
        moved, constant = [], np.eye(3)
        for axis, angle in factors:
            if axis == EULER_PARAMETERS:  # C R(e0, e) = R(e0, C e) C
                moved.append((axis, (angle[0], *(sp.Matrix(3, 3, [_exact(x) for x in constant.flat]) * sp.Matrix(angle[1:])))))
                continue
            unit = np.array(_PRINCIPAL[axis] if isinstance(axis, str) else axis, dtype=float)
            if angle.free_symbols:
                moved.append((tuple(_exact(x) for x in constant @ unit / np.linalg.norm(constant @ unit)), angle))
            else:
                constant = constant @ np.array(RotationSequence([(axis, angle)]).matrix, dtype=float)
        factors = moved + _matrix_factors(constant)
    return RotationSequence(factors)


_PRINCIPAL = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def _matrix_factors(matrix: np.ndarray) -> list:
    """A constant rotation matrix as (at most three) factors ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    roll, pitch, yaw = rpy_of(matrix)
    return rpy_factors(roll, pitch, yaw)


def _compact(factors: list) -> list:
    """``factors`` with every run of more than three constant rotations replaced by three (z, y, x)."""
    result: list = []
    run: list = []

    def flush():
        result.extend(run if len(run) <= 3 else _matrix_factors(np.array(RotationSequence(run).matrix, dtype=float)))
        run.clear()

    for factor in factors:
        if _moves(factor):
            flush()
            result.append(factor)
        else:
            run.append(factor)
    flush()
    return result



def check_inertia(document: XmlDocument, element: Element, mass: float, tensor: np.ndarray, *,
                  allow_nonphysical: bool = False) -> None:
    """ModelFileError at ``element`` unless the inertial is physical: kronlag's checks of a rigid
    body (:meth:`kronlag.RigidBody.check_values`: mass not negative, tensor positive semidefinite,
    principal moments satisfying the triangle inequality).  With ``allow_nonphysical`` a violated
    triangle inequality is a :class:`RobotFileWarning` naming the element instead (the body the link
    belongs to is checked again when the numeric model is built)."""
    body = RigidBody("inertial", mass=sp.Float(mass), inertia=sp.Matrix((tensor + tensor.T) / 2),
                     position=(0, 0, 0), rotation=sp.eye(3))
    try:
        body.check_values(lambda value, what: float(cast(SupportsFloat, value)))  # a SymPy number
    except ModelError as error:
        located = document.error(element, "<inertial>: " + str(error).removeprefix("body 'inertial': "))
        if not (allow_nonphysical and "triangle inequality" in str(error)):
            raise located from None
        warnings.warn(f"{located} (kept: allow_nonphysical_inertia=True)", RobotFileWarning, stacklevel=4)


def rpy_of(rotation: np.ndarray) -> tuple[float, float, float]:
    """``(roll, pitch, yaw)`` with ``rpy_matrix(roll, pitch, yaw) == rotation`` (to rounding)."""
    # the pitch by arctan2, not arcsin(-R[2, 0]): near +-pi/2 (Cassie's 1.5708) arcsin loses half the digits
    return (float(np.arctan2(rotation[2, 1], rotation[2, 2])),
            float(np.arctan2(-rotation[2, 0], np.hypot(rotation[0, 0], rotation[1, 0]))),
            float(np.arctan2(rotation[1, 0], rotation[0, 0])))


def _tree(document: XmlDocument, links: dict[str, Element], joints: list[TreeJoint]) -> str:
    """The root link; errors for unknown links, loops and several roots."""
    by_child: dict[str, TreeJoint] = {}
    names: set[str] = set()
    for joint in joints:
        if joint.name in names:
            raise document.error(joint.element, "a second joint of this name")
        names.add(joint.name)
        for link in (joint.parent, joint.child):
            if link not in links:
                raise document.error(joint.element, f"names the link {link!r}, which the file does not define")
        if joint.child in by_child:
            raise document.error(joint.element, f"link {joint.child!r} already has the parent joint "
                                                f"{by_child[joint.child].name!r}: a tree has no loops")
        by_child[joint.child] = joint
    roots = [name for name in links if name not in by_child]
    if not roots:
        raise document.error(document.root, "the joints form a loop: no link is a root")
    if len(roots) > 1:
        raise document.error(links[roots[1]], f"a second root link: {len(roots)} links ({', '.join(roots)}) have "
                                              "no parent joint; a robot has one root, joined to every other link")
    return roots[0]


def build_system(document: XmlDocument, *, name: str, file_format: str, links: dict[str, Element],
                 inertials: dict[str, Inertial], specs: list[TreeJoint],
                 visuals: Sequence[VisualSpec],
                 gravity: tuple[float, float, float] = (0.0, 0.0, -9.81), coordinates: str = "joint",
                 package_paths: Sequence[str | Path] = ()) -> System:
    """The System of a kinematic tree in joint coordinates, with its :class:`RobotDescription`
    (``system.robot``); ``visuals`` are ``(link, shape, size, pose in the link frame, filename)``;
    ``gravity`` is the file's (the parameter ``g`` is its magnitude, its direction is kept).
    The reader reports the skipped elements (:func:`report_skipped`) once it is done.
    ``coordinates="absolute"`` rewrites the system in absolute body coordinates
    (:func:`~.absolute.absolute_system`); meshes are looked up in ``package_paths`` and the other
    search paths of :mod:`.meshes` and drawn by their bounding boxes.

    Raises
    ------
    ModelFileError
        Naming the element: an unknown link, a link with two parents, two roots, a mimic of an
        unknown joint, a zero-mass leaf.
    """
    if coordinates not in COORDINATE_CHOICES:
        raise InputError(f"coordinates={coordinates!r}: expected one of {', '.join(COORDINATE_CHOICES)}")
    root = _tree(document, links, specs)
    children: dict[str, list[TreeJoint]] = {link: [] for link in links}
    for spec in specs:
        children[spec.parent].append(spec)
    order = _depth_first(root, children)

    moving = [spec for spec in order if spec.kind != "fixed"]
    if not moving:
        raise document.error(document.root, "has no moving joint: nothing to simulate")
    taken: set[str] = set()
    coordinates_of: dict[str, list[sp.Symbol]] = {}
    for spec in moving:
        coordinates_of[spec.name] = []
        for suffix in JOINT_COORDINATES[spec.kind]:
            symbol = coordinate_name(f"{spec.name}_{suffix}" if suffix else spec.name, taken)
            taken.update({symbol, symbol + "d", symbol + "dd"})
            coordinates_of[spec.name].append(sp.Symbol(symbol))
    coordinate_of = {name: symbols[0] for name, symbols in coordinates_of.items() if len(symbols) == 1}
    for spec in moving:
        if spec.mimic is not None and (spec.mimic[0] not in coordinate_of or spec.mimic[0] == spec.name
                                       or spec.name not in coordinate_of):
            known = ("a fixed joint" if any(s.name == spec.mimic[0] and s.kind == "fixed" for s in specs)
                     else "a joint of several coordinates" if spec.mimic[0] in coordinates_of
                     else "not a joint of the file")
            assert spec.mimic_element is not None  # a reader that sets mimic sets its element
            raise document.error(spec.mimic_element, f"of joint {spec.name!r}: " + (
                f"a {spec.kind} joint cannot mimic (one coordinate only)" if spec.name not in coordinate_of
                else f"{spec.mimic[0]!r} is {known if spec.mimic[0] != spec.name else 'the joint itself'}"))
    actuated = [spec for spec in moving if spec.mimic is None and spec.name in coordinate_of]
    torques = {spec.name: sp.Symbol(f"tau_{coordinate_of[spec.name].name}") for spec in actuated}
    g = sp.Symbol("g")
    magnitude = float(np.linalg.norm(gravity))
    direction = np.array(gravity) / magnitude if magnitude > 0 else np.array([0.0, 0.0, -1.0])
    down = [sp.Integer(int(x)) if x in (-1.0, 0.0, 1.0) else sp.Float(x) for x in direction]
    system = System([q for symbols in coordinates_of.values() for q in symbols], parameters=[g, *torques.values()],
                    gravity=[g * x for x in down], name=name)
    placements = {root: _Placement(sp.zeros(3, 1), sp.eye(3), [], GROUND, np.eye(4), [])}
    parts: dict[str, list[Inertial]] = {}
    local_frames: dict[str, tuple[str, Frame]] = {}
    for spec in order:
        parent = placements[spec.parent]
        x, y, z, roll, pitch, yaw = spec.origin
        turn = rpy_factors(roll, pitch, yaw)
        factors = _compact(parent.factors + turn)
        turned = RotationSequence(turn).matrix if turn else sp.eye(3)
        rotation = matrix_product(parent.rotation, turned) if turn else parent.rotation
        origin = parent.origin + matrix_product(parent.rotation, sp.Matrix([x, y, z]))
        points = parent.points + [origin]
        if spec.kind == "fixed":
            in_body = parent.in_body @ transform(spec.origin)
            placements[spec.child] = _Placement(origin, rotation, factors, parent.body, in_body, points)
            local_frames[spec.child] = (spec.parent, Frame(sp.Matrix([x, y, z]), turned))
            continue
        local_frames[spec.child] = (spec.parent, Frame(*_step(spec, coordinates_of[spec.name], sp.Matrix([x, y, z]),
                                                              turned)[::2]))
        origin, step, rotation = _step(spec, coordinates_of[spec.name], origin, rotation)
        factors = factors + step
        placements[spec.child] = _Placement(origin, rotation, factors, spec.child, np.eye(4), points)
    for link, placement in placements.items():
        parts.setdefault(placement.body, []).append(moved(inertials[link], placement.in_body))

    centres: dict[str, sp.Matrix] = {}
    tree_bodies: dict[str, TreeBody] = {}
    for spec in moving:
        inertial = combine(parts[spec.child])
        placement = placements[spec.child]
        has_children = any(placements[other.child].body != spec.child and placements[other.parent].body == spec.child
                           for other in moving)
        if inertial.mass == 0 and not np.any(inertial.tensor):
            if not has_children:
                raise document.error(links[spec.child], f"is a zero-mass leaf: the joint {spec.name!r} moves nothing "
                                                        "that has mass or inertia (its acceleration is undetermined)")
            continue
        centre = placement.origin + matrix_product(placement.rotation, sp.Matrix(inertial.centre))
        centres[spec.child] = centre
        body = system.add_body(RigidBody(spec.child, mass=sp.Float(inertial.mass), inertia=sp.Matrix(inertial.tensor),
                                         position=centre, rotation=_body_rotation(placement), simplify=False))
        tree_bodies[spec.child] = TreeBody(body, three(inertial.centre.tolist()))
    for spec in moving:
        if spec.kind in ("floating", "ball"):
            system.add_constraint(euler_parameter_constraint(*coordinates_of[spec.name][-4:]),
                                  name=f"{spec.name}.normalization")
        if spec.mimic is not None:
            joint, multiplier, offset = spec.mimic
            system.add_constraint(coordinate_of[spec.name] - sp.Float(multiplier) * coordinate_of[joint]
                                  - sp.Float(offset), name=f"{spec.name}.mimic")
    system.add_generalized_force([torques.get(spec.name, 0) for spec in moving for _ in coordinates_of[spec.name]],
                                 name="joint torques")
    _add_drawing(system, order, placements, centres)

    system.robot = RobotDescription(
        source=document.source, format=file_format, root=root,
        joints=tuple(RobotJoint(spec.name, spec.kind, spec.parent, spec.child, spec.axis, spec.origin,
                                coordinates_of[spec.name][0].name if spec.name in coordinates_of else None,
                                spec.limits, spec.mimic, torques[spec.name].name if spec.name in torques else None,
                                tuple(q.name for q in coordinates_of.get(spec.name, ())))
                     for spec in order),
        body_of_link={name: placement.body for name, placement in placements.items()},
        visuals=tuple(with_mesh_bounds((Visual(link, placements[link].body, shape, size, placements[link].in_body @ pose,
                                               filename) for link, shape, size, pose, filename in visuals),
                                       document.source, package_paths)),
        frames={link: Frame(placement.origin, placement.rotation) for link, placement in placements.items()},
        local_frames=local_frames,
        values={"g": magnitude, **{symbol.name: 0.0 for symbol in torques.values()}},
        q_reference={q.name: value for spec in moving for q, value in _reference(spec, coordinates_of[spec.name])},
        skipped=document.skipped_summary(), joint_values=dict(coordinate_of), tree_bodies=tree_bodies)
    return absolute_system(document, system) if coordinates == "absolute" else system


def _reference(spec: TreeJoint, coordinates: list[sp.Symbol]) -> list[tuple[sp.Symbol, float]]:
    """The coordinates of a joint at the file's reference pose: 0 (a mimic joint its offset), and
    ``e0 = 1`` for Euler parameters (the joint frame's own orientation)."""
    values = [spec.mimic[2] if spec.mimic else 0.0] * len(coordinates)
    if spec.kind in ("floating", "ball"):
        values[-4] = 1.0
    return list(zip(coordinates, values))


def robot_of(system: System) -> RobotDescription:
    """``system.robot`` of a system :func:`build_system` made (never ``None`` there)."""
    assert system.robot is not None, "not a system read from a robot file"
    return system.robot


def _path_to_root(local: dict[str, tuple[str, Frame]], link: str) -> list[str]:
    links = [link]
    while links[-1] in local:
        links.append(local[links[-1]][0])
    return links


def common_ancestor(system: System, first: str, second: str) -> str:
    """The nearest link that both ``first`` and ``second`` descend from (or are)."""
    local = robot_of(system).local_frames
    second_path = _path_to_root(local, second)
    return next(link for link in _path_to_root(local, first) if link in second_path)


def relative_frames(system: System, first: str, second: str) -> tuple[Frame, Frame]:
    """The frames of the links ``first`` and ``second`` in the frame of their nearest common ancestor
    link: expressions of the joints between them only (a loop's constraints written so stay small;
    in the world frame they would hold every joint from the root, the floating base's among them)."""
    local = robot_of(system).local_frames
    first_path, second_path = _path_to_root(local, first), _path_to_root(local, second)
    ancestor = common_ancestor(system, first, second)

    def frame(links: list[str]) -> Frame:
        origin, rotation = sp.zeros(3, 1), sp.eye(3)
        for link in reversed(links[:links.index(ancestor)]):
            step = local[link][1]
            origin, rotation = (origin + matrix_product(rotation, sp.Matrix(step.origin)),
                                matrix_product(rotation, sp.Matrix(step.rotation)))
        return Frame(origin, rotation)

    return frame(first_path), frame(second_path)


def at_reference(system: System, expression) -> np.ndarray:
    """A matrix of expressions of the coordinates at the file's reference pose, as floats."""
    reference = {q: robot_of(system).q_reference.get(q.name, 0.0) for q in system.coordinates}
    return np.array(sp.Matrix(expression).subs(reference).evalf(), dtype=float)


def orientation_rows(rotation1: sp.Matrix, relative: np.ndarray, rotation2: sp.Matrix) -> list[tuple[str, sp.Expr]]:
    """The rows ``rx, ry, rz`` that hold ``R2 = R1 relative`` (as kronlag.joints' orientation lock:
    ``(R1 relative e_y).(R2 e_z)``, ``(R1 relative e_z).(R2 e_x)``, ``(R1 relative e_x).(R2 e_y)``)."""
    expected, unit = rotation1 * sp.Matrix(relative), sp.eye(3)
    return [(label, (expected * unit[:, i]).dot(rotation2 * unit[:, j]))
            for label, i, j in (("rx", 1, 2), ("ry", 2, 0), ("rz", 0, 1))]


def report_skipped(document: XmlDocument, system: System) -> None:
    """Record the elements the reader skipped in ``system.robot`` and warn once, listing them."""
    robot = robot_of(system)
    robot.skipped = document.skipped_summary()
    if robot.skipped:
        warnings.warn(f"{document.source}: not used by kronlag (skipped): {robot.skipped}", RobotFileWarning,
                      stacklevel=3)



def _depth_first(root: str, children: dict[str, list[TreeJoint]]) -> list[TreeJoint]:
    """The joints depth-first from the root, siblings in file order (the order Pinocchio numbers them)."""
    order: list[TreeJoint] = []
    stack = list(reversed(children[root]))
    while stack:
        spec = stack.pop()
        order.append(spec)
        stack.extend(reversed(children[spec.child]))
    return order


def _add_drawing(system: System, order: list[TreeJoint], placements: dict[str, _Placement],
                 centres: dict[str, sp.Matrix]) -> None:
    """A stick figure for the animation: a polyline through the joint origins from the root to each
    leaf link (and on to its centre of mass if it moves), each starting where it leaves the
    branches drawn before."""
    drawn: set[int] = set()
    for spec in order:
        if any(other.parent == spec.child for other in order):
            continue  # not a leaf
        leaf = placements[spec.child]
        ends = [leaf.origin] + ([centres[spec.child]] if spec.child in centres else [])  # a moving leaf: on to its COM
        points = leaf.points + [point for point in ends if point != leaf.points[-1]]
        start = max((index for index, point in enumerate(points) if id(point) in drawn), default=0)
        line = points[start:]
        drawn.update(id(point) for point in line)
        if len(line) >= 2 and any(free_symbols(point) for point in line):
            system.add_drawing_line(line, name=f"{spec.child} branch")
