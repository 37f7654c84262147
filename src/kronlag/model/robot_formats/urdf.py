"""URDF reader: :func:`load_urdf` turns a URDF file into a :class:`~kronlag.System` in joint coordinates.

The root link is fixed to the world (the ``ground``); every revolute, continuous and prismatic
joint moves one coordinate named after it; fixed joints are merged (their child's mass and
inertia are added to the parent's body, which keeps the name of the first link of the group).
Each body's pose is written with the joint angles, its rotation as a
:class:`~kronlag.RotationSequence` of the file's ``rpy`` angles and joint axes (so that its
angular velocity needs no simplification).  A ``<mimic>`` joint keeps its own coordinate and
adds the holonomic constraint ``q - multiplier * q_joint - offset = 0`` (``"<name>.mimic"``).
Gravity is ``(0, 0, -g)``; the parameter ``tau_<coordinate>`` is the torque (force) of every
actuated joint.  Limits, damping and friction stay data (``system.robot``,
:class:`~kronlag.model.robot_formats.description.RobotDescription`).

Everything read comes from :func:`~kronlag.model.robot_formats.safe_xml.read_xml`; every error is
one line naming the file, the line and the element.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np
import sympy as sp

from ...core.errors import ModelFileError
from ..bodies import RigidBody
from ..frames import GROUND
from ..rotations import MAX_ROTATION_FACTORS, RotationSequence
from ..system import System
from .description import JointLimits, RobotDescription, RobotFileWarning, RobotJoint, Visual, coordinate_name
from .safe_xml import XmlDocument, read_xml

__all__ = ["load_urdf", "JOINT_TYPES"]

#: The URDF joint types the reader turns into coordinates (``fixed`` merges its links).
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")

#: Joint types URDF defines that this reader does not support yet.
_LATER_TYPES = ("floating", "planar")

#: Relative tolerance of the physical checks of an inertial (as kronlag.model.bodies).
_PHYSICAL_TOLERANCE = 1e-9

_USED = {"robot": {"link", "joint"}, "link": {"inertial", "visual"}, "inertial": {"origin", "mass", "inertia"},
         "visual": {"origin", "geometry"}, "geometry": {"box", "cylinder", "sphere", "capsule", "mesh"},
         "joint": {"origin", "parent", "child", "axis", "limit", "dynamics", "mimic"}}


@dataclass(frozen=True)
class _Inertial:
    """Mass, centre of mass and central inertia tensor in a link's frame."""

    mass: float
    centre: np.ndarray
    tensor: np.ndarray


_NO_MASS = _Inertial(0.0, np.zeros(3), np.zeros((3, 3)))


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    c, s = np.cos([roll, pitch, yaw]), np.sin([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    return rz @ ry @ rx


def _angle(value: float) -> sp.Expr:
    """An angle of the file: ``k pi/2`` exactly where ``value`` is the double nearest to it (the file
    means it; the difference is below double rounding, and exact zeros keep the expressions small),
    else the number as given."""
    quarter = round(value / (np.pi / 2))
    if abs(value - quarter * (np.pi / 2)) <= 4 * np.finfo(float).eps * max(1.0, abs(value)):
        return quarter * sp.pi / 2
    return sp.Float(value)


def _rpy_factors(roll: float, pitch: float, yaw: float) -> list[tuple[str, sp.Expr]]:
    """The elementary rotations of an ``rpy`` (zero angles left out), as RotationSequence factors."""
    return [(axis, _angle(angle)) for axis, angle in (("z", yaw), ("y", pitch), ("x", roll)) if angle != 0]


def _check_children(document: XmlDocument, element: Element) -> None:
    """Note the children of ``element`` the reader does not use."""
    used = _USED.get(element.tag, set())
    for child in element:
        if child.tag not in used:
            document.skip(child, element.tag)
        elif child.tag in _USED:
            _check_children(document, child)


def _origin(document: XmlDocument, element: Element) -> tuple[float, ...]:
    """``x y z roll pitch yaw`` of the ``<origin>`` child (zeros if absent)."""
    origin = element.find("origin")
    if origin is None:
        return (0.0,) * 6
    return (document.numbers(origin, "xyz", 3, default=(0, 0, 0))
            + document.numbers(origin, "rpy", 3, default=(0, 0, 0)))


def _transform(origin: tuple[float, ...]) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = _rpy_matrix(*origin[3:])
    matrix[:3, 3] = origin[:3]
    return matrix


def _inertial(document: XmlDocument, link: Element) -> _Inertial:
    """The link's inertial in its frame, checked physical (mass >= 0, tensor positive semidefinite with
    the triangle inequality); no ``<inertial>``: no mass."""
    inertial = link.find("inertial")
    if inertial is None:
        return _NO_MASS
    mass_element, tensor_element = inertial.find("mass"), inertial.find("inertia")
    if mass_element is None:
        raise document.error(link, "<inertial> has no <mass value=...>")
    mass = document.number(mass_element, "value")
    if mass < 0:
        raise document.error(link, f"<inertial>: mass = {mass:g} is negative")
    if tensor_element is None:
        raise document.error(link, "<inertial> has no <inertia ixx=... ixy=... ixz=... iyy=... iyz=... izz=...>")
    xx, xy, xz, yy, yz, zz = (document.number(tensor_element, key)
                              for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
    tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    moments = np.linalg.eigvalsh(tensor)
    tolerance = _PHYSICAL_TOLERANCE * max(1e-300, np.abs(moments).max())
    shown = ", ".join(f"{value:.6g}" for value in moments)
    if moments[0] < -tolerance:
        raise document.error(link, f"<inertia>: the tensor is not positive definite (principal moments {shown})")
    if moments[0] + moments[1] < moments[2] - tolerance:
        raise document.error(link, f"<inertia>: the principal moments {shown} violate the triangle inequality "
                                   "I1 + I2 >= I3: no mass distribution has them")
    origin = _origin(document, inertial)
    rotation = _rpy_matrix(*origin[3:])
    return _Inertial(mass, np.array(origin[:3]), rotation @ tensor @ rotation.T)


def _combine(parts: list[_Inertial]) -> _Inertial:
    """The inertial of rigidly joined parts (all in one frame): total mass, centre of mass, and the
    central tensor by the parallel-axis theorem."""
    mass = sum(part.mass for part in parts)
    if mass == 0:
        return _Inertial(0.0, np.zeros(3), sum((part.tensor for part in parts), np.zeros((3, 3))))
    centre = sum(part.mass * part.centre for part in parts) / mass
    tensor = np.zeros((3, 3))
    for part in parts:
        d = part.centre - centre
        tensor += part.tensor + part.mass * (d @ d * np.eye(3) - np.outer(d, d))
    return _Inertial(mass, centre, (tensor + tensor.T) / 2)


def _moved(part: _Inertial, transform: np.ndarray) -> _Inertial:
    """``part`` given in a frame placed by ``transform``, expressed in the outer frame."""
    rotation = transform[:3, :3]
    return _Inertial(part.mass, transform[:3, :3] @ part.centre + transform[:3, 3],
                     rotation @ part.tensor @ rotation.T)


def _visuals(document: XmlDocument, link: Element) -> list[tuple[str, tuple[float, ...], np.ndarray, str | None]]:
    """``(shape, size, pose in the link frame, filename)`` of each ``<visual>`` with a geometry."""
    found = []
    for visual in link.findall("visual"):
        geometry = visual.find("geometry")
        shape = None if geometry is None else next(iter(geometry), None)
        if shape is None:
            continue
        pose = _transform(_origin(document, visual))
        if shape.tag == "box":
            found.append(("box", document.numbers(shape, "size", 3), pose, None))
        elif shape.tag == "sphere":
            found.append(("sphere", (document.number(shape, "radius"),), pose, None))
        elif shape.tag in ("cylinder", "capsule"):
            found.append((shape.tag, (document.number(shape, "radius"), document.number(shape, "length")), pose, None))
        elif shape.tag == "mesh":
            found.append(("mesh", document.numbers(shape, "scale", 3, default=(1, 1, 1)), pose,
                          document.required(shape, "filename")))
    return found


@dataclass
class _JointSpec:
    element: Element
    name: str
    kind: str
    parent: str
    child: str
    origin: tuple[float, ...]
    axis: tuple[float, float, float]
    limits: JointLimits
    mimic: tuple[str, float, float] | None


def _joint(document: XmlDocument, element: Element) -> _JointSpec:
    name = document.required(element, "name")
    kind = document.required(element, "type")
    if kind in _LATER_TYPES:
        raise document.error(element, f"type {kind!r} is not supported by the URDF reader yet (fixed-base trees "
                                      f"of {', '.join(JOINT_TYPES)} joints)")
    if kind not in JOINT_TYPES:
        raise document.error(element, f"unknown joint type {kind!r}; URDF joint types are {', '.join(JOINT_TYPES)}, "
                                      f"{', '.join(_LATER_TYPES)}")
    links = []
    for role in ("parent", "child"):
        tag = element.find(role)
        if tag is None:
            raise document.error(element, f"has no <{role} link=...>")
        links.append(document.required(tag, "link"))
    axis_element = element.find("axis")
    axis = (1.0, 0.0, 0.0) if axis_element is None else document.numbers(axis_element, "xyz", 3)
    if kind != "fixed":
        norm = float(np.linalg.norm(axis))
        if norm == 0:
            raise document.error(element, "<axis xyz=\"0 0 0\">: a moving joint needs a nonzero axis")
        axis = tuple(value / norm for value in axis)
    limit, dynamics = element.find("limit"), element.find("dynamics")

    def optional(tag: Element | None, key: str) -> float | None:
        return None if tag is None or tag.get(key) is None else document.number(tag, key)

    limits = JointLimits(lower=optional(limit, "lower"), upper=optional(limit, "upper"),
                         effort=optional(limit, "effort"), velocity=optional(limit, "velocity"),
                         damping=optional(dynamics, "damping"), friction=optional(dynamics, "friction"))
    mimic_element = element.find("mimic")
    mimic = None
    if mimic_element is not None:
        mimic = (document.required(mimic_element, "joint"), document.number(mimic_element, "multiplier", 1.0),
                 document.number(mimic_element, "offset", 0.0))
    return _JointSpec(element, name, kind, links[0], links[1], _origin(document, element), axis, limits, mimic)


def _tree(document: XmlDocument, links: dict[str, Element], joints: list[_JointSpec]) -> tuple[str, dict]:
    """The root link and the joints by child link; errors for unknown links, loops and several roots."""
    by_child: dict[str, _JointSpec] = {}
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
                                                f"{by_child[joint.child].name!r}: a URDF is a tree (no loops)")
        by_child[joint.child] = joint
    roots = [name for name in links if name not in by_child]
    if len(roots) != 1:
        if not roots:
            raise ModelFileError(f"{document.source}: the joints form a loop: no link is a root")
        raise document.error(links[roots[1]], f"a second root link: {len(roots)} links ({', '.join(roots)}) have "
                                              "no parent joint; a URDF robot has one root, joined to every other link")
    return roots[0], by_child


def _joint_factors(joint: _JointSpec, coordinate: sp.Symbol) -> list[tuple[object, sp.Expr]]:
    """The rotation of a revolute or continuous joint as RotationSequence factors: about its axis, a
    principal axis where the axis is one."""
    axis = np.array(joint.axis)
    for index, name in enumerate("xyz"):
        if abs(axis[index]) == 1.0:
            return [(name, coordinate if axis[index] > 0 else -coordinate)]
    # a general axis u = Rz(phi) Ry(theta) e_z: R_u(q) = Rz(phi) Ry(theta) Rz(q) Ry(-theta) Rz(-phi)
    theta, phi = float(np.arccos(np.clip(axis[2], -1, 1))), float(np.arctan2(axis[1], axis[0]))
    turn = [("z", _angle(phi)), ("y", _angle(theta))]
    back = [("y", _angle(-theta)), ("z", _angle(-phi))]
    return [factor for factor in (*turn, ("z", coordinate), *back) if factor[1] != 0]


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
            unit = np.array(_PRINCIPAL[axis] if isinstance(axis, str) else axis, dtype=float)
            if angle.free_symbols:
                moved.append((tuple(sp.Float(x) for x in constant @ unit / np.linalg.norm(constant @ unit)), angle))
            else:
                constant = constant @ np.array(RotationSequence([(axis, angle)]).matrix, dtype=float)
        factors = moved + _matrix_factors(constant)
    return RotationSequence(factors)


_PRINCIPAL = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def _matrix_factors(matrix: np.ndarray) -> list:
    """A constant rotation matrix as (at most three) factors ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    yaw, pitch, roll = (float(np.arctan2(matrix[1, 0], matrix[0, 0])), float(np.arcsin(np.clip(-matrix[2, 0], -1, 1))),
                        float(np.arctan2(matrix[2, 1], matrix[2, 2])))
    return _rpy_factors(roll, pitch, yaw)


def _compact(factors: list) -> list:
    """``factors`` with every run of more than three constant rotations replaced by three (z, y, x)."""
    result, run = [], []

    def flush():
        result.extend(run if len(run) <= 3 else _matrix_factors(np.array(RotationSequence(run).matrix, dtype=float)))
        run.clear()

    for factor in factors:
        if factor[1].free_symbols:
            flush()
            result.append(factor)
        else:
            run.append(factor)
    flush()
    return result


def load_urdf(path: str | Path) -> System:
    """Read a URDF file into a :class:`~kronlag.System` in joint coordinates (see the module docstring).

    Parameters
    ----------
    path : str or Path
        A ``.urdf`` file (xacro files are refused: run ``xacro`` first).

    Returns
    -------
    System
        Named after the robot; ``system.robot`` is its
        :class:`~kronlag.model.robot_formats.description.RobotDescription` (joints with limits,
        visuals, parameter values, skipped elements).

    Raises
    ------
    ModelFileError
        One line naming the file, the line and the element: malformed XML, an unknown joint
        type, a non-physical inertial, a zero-mass leaf body, a mimic of an unknown joint, a
        link with two parents, two roots.
    """
    document = read_xml(path)
    robot = document.root
    if robot.tag != "robot":
        raise document.error(robot, "the root element of a URDF file must be <robot>")
    _check_children(document, robot)
    links: dict[str, Element] = {}
    for element in robot.findall("link"):
        name = document.required(element, "name")
        if name in links:
            raise document.error(element, "a second link of this name")
        links[name] = element
    if not links:
        raise document.error(robot, "has no <link>")
    specs = [_joint(document, element) for element in robot.findall("joint")]
    root, _ = _tree(document, links, specs)
    children: dict[str, list[_JointSpec]] = {name: [] for name in links}
    for spec in specs:
        children[spec.parent].append(spec)
    order = _depth_first(root, children)

    moving = [spec for spec in order if spec.kind != "fixed"]
    if not moving:
        raise document.error(robot, "has no moving joint (revolute, continuous or prismatic): nothing to simulate")
    taken: set[str] = set()
    coordinate_of: dict[str, sp.Symbol] = {}
    for spec in moving:
        name = coordinate_name(spec.name, taken)
        taken.update({name, name + "d", name + "dd"})
        coordinate_of[spec.name] = sp.Symbol(name)
    for spec in moving:
        if spec.mimic is not None and (spec.mimic[0] not in coordinate_of or spec.mimic[0] == spec.name):
            known = "a fixed joint" if any(s.name == spec.mimic[0] for s in specs) else "not a joint of the file"
            raise document.error(spec.element.find("mimic"), f"of joint {spec.name!r}: {spec.mimic[0]!r} is "
                                 f"{known if spec.mimic[0] != spec.name else 'the joint itself'}")
    actuated = [spec for spec in moving if spec.mimic is None]
    torques = {spec.name: sp.Symbol(f"tau_{coordinate_of[spec.name].name}") for spec in actuated}
    g = sp.Symbol("g")
    system = System(list(coordinate_of.values()), parameters=[g, *torques.values()], gravity=(0, 0, -g),
                    name=robot.get("name") or Path(path).stem)

    inertials = {name: _inertial(document, element) for name, element in links.items()}
    placements = {root: _Placement(sp.zeros(3, 1), sp.eye(3), [], GROUND, np.eye(4), [])}
    parts: dict[str, list[_Inertial]] = {}
    for spec in order:
        parent = placements[spec.parent]
        x, y, z, roll, pitch, yaw = spec.origin
        turn = _rpy_factors(roll, pitch, yaw)
        factors = _compact(parent.factors + turn)
        rotation = parent.rotation * RotationSequence(turn).matrix if turn else parent.rotation
        origin = parent.origin + parent.rotation * sp.Matrix([x, y, z])
        points = parent.points + [origin]
        if spec.kind == "fixed":
            in_body = parent.in_body @ _transform(spec.origin)
            placements[spec.child] = _Placement(origin, rotation, factors, parent.body, in_body, points)
            continue
        q = coordinate_of[spec.name]
        if spec.kind == "prismatic":
            origin = origin + rotation * sp.Matrix(spec.axis) * q
        else:
            step = _joint_factors(spec, q)
            factors = factors + step
            rotation = rotation * RotationSequence(step).matrix
        placements[spec.child] = _Placement(origin, rotation, factors, spec.child, np.eye(4), points)
    for name, placement in placements.items():
        parts.setdefault(placement.body, []).append(_moved(inertials[name], placement.in_body))

    for spec in moving:
        inertial = _combine(parts[spec.child])
        placement = placements[spec.child]
        has_children = any(placements[other.child].body != spec.child and placements[other.parent].body == spec.child
                           for other in moving)
        if inertial.mass == 0 and not np.any(inertial.tensor):
            if not has_children:
                raise document.error(links[spec.child], f"is a zero-mass leaf: the joint {spec.name!r} moves nothing "
                                                        "that has mass or inertia (its acceleration is undetermined)")
            continue
        centre = placement.origin + placement.rotation * sp.Matrix(inertial.centre)
        system.add_body(RigidBody(spec.child, mass=sp.Float(inertial.mass), inertia=sp.Matrix(inertial.tensor),
                                  position=centre, rotation=_body_rotation(placement), simplify=False))
    for spec in moving:
        if spec.mimic is not None:
            joint, multiplier, offset = spec.mimic
            system.add_constraint(coordinate_of[spec.name] - sp.Float(multiplier) * coordinate_of[joint]
                                  - sp.Float(offset), name=f"{spec.name}.mimic")
    system.add_generalized_force([torques.get(spec.name, 0) for spec in moving], name="joint torques")
    _add_drawing(system, order, placements)

    visuals = tuple(Visual(name, placements[name].body, shape, size, placements[name].in_body @ pose, filename)
                    for name, element in links.items() for shape, size, pose, filename in _visuals(document, element))
    system.robot = RobotDescription(
        source=document.source, format="urdf", root=root,
        joints=tuple(RobotJoint(spec.name, spec.kind, spec.parent, spec.child, spec.axis, spec.origin,
                                coordinate_of[spec.name].name if spec.name in coordinate_of else None, spec.limits,
                                spec.mimic, torques[spec.name].name if spec.name in torques else None)
                     for spec in order),
        body_of_link={name: placement.body for name, placement in placements.items()},
        visuals=visuals, values={"g": 9.81, **{symbol.name: 0.0 for symbol in torques.values()}},
        q_reference={coordinate_of[spec.name].name: spec.mimic[2] if spec.mimic else 0.0 for spec in moving},
        skipped=document.skipped_summary())
    if system.robot.skipped:
        warnings.warn(f"{document.source}: not used by kronlag (skipped): {system.robot.skipped}", RobotFileWarning,
                      stacklevel=2)
    return system


def _depth_first(root: str, children: dict[str, list[_JointSpec]]) -> list[_JointSpec]:
    """The joints depth-first from the root, siblings in file order (the order Pinocchio numbers them)."""
    order: list[_JointSpec] = []
    stack = list(reversed(children[root]))
    while stack:
        spec = stack.pop()
        order.append(spec)
        stack.extend(reversed(children[spec.child]))
    return order


def _add_drawing(system: System, order: list[_JointSpec], placements: dict[str, _Placement]) -> None:
    """A stick figure for the animation: a polyline through the joint origins from the root to each
    leaf link, each starting where it leaves the branches drawn before."""
    drawn: set[int] = set()
    for spec in order:
        if any(other.parent == spec.child for other in order):
            continue  # not a leaf
        points = placements[spec.child].points + [placements[spec.child].origin]
        start = max((index for index, point in enumerate(points) if id(point) in drawn), default=0)
        line = points[start:]
        drawn.update(id(point) for point in line)
        if len(line) >= 2 and any(point.free_symbols for point in line):
            system.add_drawing_line(line, name=f"{spec.child} branch")
