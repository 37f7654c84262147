"""MJCF reader: :func:`load_mjcf` turns a MuJoCo model file into a :class:`~kronlag.System` in joint
coordinates, with its ``<equality>`` constraints exact.

The bodies of ``<worldbody>`` form the tree (:mod:`.tree`): a body without joints is welded to its
parent (merged), each ``hinge`` joint turns its body about its axis through its ``pos``, each
``slide`` joint slides it; several joints of one body act in the order written.  Poses are read
from ``pos`` and one of ``quat``, ``euler`` (``<compiler eulerseq>``), ``axisangle``, ``xyaxes``,
``zaxis``, angles in ``<compiler angle>`` (degrees by default); ``<default>`` classes (nested,
``class`` and ``childclass``) give the attributes an element does not set.  ``<inertial>`` gives
mass, centre of mass and ``diaginertia`` or ``fullinertia``; a body without one has no mass (one
with geoms is refused: inertia from geoms is not computed).  ``<option gravity>`` sets gravity.

``<equality>`` elements become exact holonomic constraints (not MuJoCo's soft ones):

- ``connect`` (``body1``, ``body2``, ``anchor`` on body1): the anchor and the body2 point that
  coincides with it at the reference pose stay together, rows ``"<name>.x"``, ``.y``, ``.z``;
- ``weld``: ``connect`` at body2's ``anchor`` plus the relative orientation of the reference pose
  (or of ``relpose``), rows ``.x .y .z .rx .ry .rz``;
- ``joint`` (``joint1``, ``joint2``, ``polycoef``): ``q1 = c0 + c1 q2 + c2 q2^2 + ...``, row ``"<name>.joint"``.

A row that is identically zero (the out-of-plane row of a planar ``connect``) is dropped and listed
in ``system.robot.redundant``; a row that is a nonzero constant cannot be closed (an error with the
residual).  Hinge and slide joints are read, ``ball`` and ``free`` joints (and ``freejoint``) as the
tree's ``ball`` and ``floating`` joints (Euler parameters, see :mod:`.tree`); a ``ref`` other than 0
is refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np
import sympy as sp

from ...core.kernels import ExpressionFunction
from ..system import System
from .description import JointLimits
from .safe_xml import XmlDocument, numbers, read_xml
from .tree import (NO_MASS, Inertial, TreeJoint, VisualSpec, at_reference, build_system, check_inertia, combine,
                   orientation_rows, report_skipped, robot_of, rpy_of, three)

__all__ = ["load_mjcf", "add_rows"]

#: Elements of a body the reader uses (the others are listed as skipped).
_BODY_USED = {"body", "inertial", "joint", "geom"}
#: Top-level elements the reader uses.
_TOP_USED = {"compiler", "option", "default", "worldbody", "equality", "asset"}
#: MJCF joint types and the tree joints they are (:data:`.tree.JOINT_COORDINATES`).
_JOINT_KINDS = {"hinge": "revolute", "slide": "prismatic", "ball": "ball", "free": "floating"}
#: A constraint row whose value is below this at every coordinate value is identically zero.
_ZERO_ROW = 1e-12
#: A loop is closed when every constraint row is below this; Gauss-Newton steps tried to close it.
_CLOSED, _CLOSING_STEPS = 1e-9, 30


def _quaternion_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    u = axis / np.linalg.norm(axis)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


class _Reader:
    """The state of one file's reading: its document, compiler settings and default classes."""

    def __init__(self, document: XmlDocument):
        self.document = document
        root = document.root
        compiler = root.find("compiler")
        self.degrees = compiler is None or compiler.get("angle", "degree") == "degree"
        self.eulerseq = "xyz" if compiler is None else compiler.get("eulerseq", "xyz")
        if len(self.eulerseq) != 3 or any(c not in "xyzXYZ" for c in self.eulerseq):
            assert compiler is not None  # the default eulerseq is valid
            raise document.error(compiler, f"eulerseq={self.eulerseq!r}: expected three of x, y, z, X, Y, Z")
        self.from_geoms = "auto" if compiler is None else compiler.get("inertiafromgeom", "auto")
        if self.from_geoms not in ("auto", "true", "false"):
            assert compiler is not None
            raise document.error(compiler, f"inertiafromgeom={self.from_geoms!r}: expected auto, true or false")
        self.defaults: dict[str, dict[str, dict[str, str]]] = {}
        for default in root.findall("default"):
            self._read_default(default, {}, "main")

    def _read_default(self, element: Element, inherited: dict, name: str) -> None:
        own = {tag: dict(values) for tag, values in inherited.items()}
        for child in element:
            if child.tag != "default":
                own.setdefault(child.tag, {}).update(child.attrib)
        self.defaults[name] = own
        for child in element.findall("default"):
            self._read_default(child, own, self.document.required(child, "class"))

    def attributes(self, element: Element, childclass: str) -> dict[str, str]:
        """The element's attributes over those of its default class."""
        name = element.get("class", childclass)
        if name not in self.defaults and name != "main":
            raise self.document.error(element, f"class={name!r}: no <default class={name!r}>")
        return {**self.defaults.get(name, {}).get(element.tag, {}), **element.attrib}

    def numbers(self, element: Element, values: dict, key: str, count: int, default=None) -> tuple[float, ...]:
        """``values[key]`` (the element's attributes over its class's) as ``count`` finite numbers."""
        if key not in values:
            if default is None:
                raise self.document.error(element, f"needs the attribute {key}=\"...\" ({count} numbers)")
            return tuple(float(x) for x in default)
        parsed = numbers(values[key])
        if parsed is None or len(parsed) != count:
            raise self.document.error(element, f"{key}={values[key]!r}: expected {count} finite numbers")
        return parsed

    def angle(self, value: float) -> float:
        return math.radians(value) if self.degrees else value

    def orientation(self, element: Element, values: dict) -> np.ndarray:
        """The rotation of an element's frame from ``quat``, ``axisangle``, ``euler``, ``xyaxes`` or ``zaxis``."""
        given = [key for key in ("quat", "axisangle", "euler", "xyaxes", "zaxis") if key in values]
        if len(given) > 1:
            raise self.document.error(element, f"gives the orientation twice: {', '.join(given)}")
        if not given:
            return np.eye(3)
        key = given[0]
        if key == "quat":
            return _quaternion_matrix(*self.numbers(element, values, key, 4))
        if key == "axisangle":
            *vector, angle = self.numbers(element, values, key, 4)
            return _axis_angle_matrix(np.array(vector), self.angle(angle))
        if key == "euler":
            rotation = np.eye(3)
            for letter, angle in zip(self.eulerseq, self.numbers(element, values, key, 3)):
                turn = _axis_angle_matrix(np.eye(3)["xyz".index(letter.lower())], self.angle(angle))
                rotation = rotation @ turn if letter.islower() else turn @ rotation
            return rotation
        if key == "xyaxes":
            values6 = np.array(self.numbers(element, values, key, 6))
            x = values6[:3] / np.linalg.norm(values6[:3])
            y = values6[3:] - (values6[3:] @ x) * x
            y /= np.linalg.norm(y)
            return np.column_stack([x, y, np.cross(x, y)])
        z = np.array(self.numbers(element, values, key, 3))
        z /= np.linalg.norm(z)
        axis = np.cross([0.0, 0.0, 1.0], z)
        if np.linalg.norm(axis) < 1e-15:
            return np.eye(3) if z[2] > 0 else np.diag([1.0, -1.0, -1.0])
        return _axis_angle_matrix(axis, math.acos(np.clip(z[2], -1, 1)))

    def pose(self, element: Element, values: dict) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.numbers(element, values, "pos", 3, default=(0, 0, 0))), self.orientation(element, values)

    def geom_frame(self, geom: Element, values: dict) -> tuple[str, tuple[float, ...], np.ndarray, np.ndarray]:
        """``(type, size, position, rotation)`` of a geom in its body's frame; ``fromto`` (capsule,
        cylinder, box, ellipsoid) gives the position (the middle), the z axis and the half length."""
        shape = values.get("type", "sphere")
        size = self.numbers(geom, values, "size", len((values.get("size") or "0").split()), default=(0.0,))
        if "fromto" in values and shape in ("capsule", "cylinder", "box", "ellipsoid"):
            ends = np.array(self.numbers(geom, values, "fromto", 6)).reshape(2, 3)
            axis = ends[1] - ends[0]
            half = float(np.linalg.norm(axis)) / 2
            if half == 0:
                raise self.document.error(geom, "fromto: the two ends coincide")
            turn = np.cross([0.0, 0.0, 1.0], axis / (2 * half))
            angle = math.atan2(float(np.linalg.norm(turn)), float(axis[2] / (2 * half)))
            rotation = _axis_angle_matrix(turn, angle) if np.linalg.norm(turn) > 1e-15 else (
                np.eye(3) if axis[2] > 0 else np.diag([1.0, -1.0, -1.0]))
            size = (size[0], half) if shape in ("capsule", "cylinder") else (size[0], size[1], half)
            return shape, size, ends.mean(axis=0), rotation
        position, rotation = self.pose(geom, values)
        return shape, size, position, rotation

    def geom_inertial(self, geom: Element, values: dict) -> Inertial | None:
        """A geom's inertial in its body's frame by MuJoCo's rules (uniform density, default 1000, or
        the geom's ``mass``); ``None`` for a geom without volume (a plane)."""
        shape, size, position, rotation = self.geom_frame(geom, values)
        if shape == "plane":
            return None
        needed = _GEOM_SIZES.get(shape)
        if needed is None:
            raise self.document.error(geom, f"type {shape!r}: kronlag computes inertia from sphere, capsule, "
                                            "cylinder, box and ellipsoid geoms; give the body an <inertial>")
        if len(size) < needed or any(x <= 0 for x in size[:needed]):
            raise self.document.error(geom, f"size={values.get('size')!r}: a {shape} needs {needed} positive sizes")
        volume, unit = _geom_volume_inertia(shape, size[:needed])
        mass = (self.numbers(geom, values, "mass", 1)[0] if "mass" in values
                else self.numbers(geom, values, "density", 1, default=(1000.0,))[0] * volume)
        if mass < 0:
            raise self.document.error(geom, f"mass {mass:g}: a mass must not be negative")
        return Inertial(mass, position, rotation @ np.diag(mass * unit) @ rotation.T)

    def inertial(self, body: Element, shift: np.ndarray, childclass: str) -> Inertial:
        """The body's inertial in its link frame, whose origin is ``shift`` in the body frame: its
        ``<inertial>``, else (``<compiler inertiafromgeom>`` ``auto``, the default, or ``true``)
        from its geoms; no mass without either."""
        inertial = body.find("inertial")
        geoms = body.findall("geom")
        if self.from_geoms == "true" or (inertial is None and self.from_geoms == "auto" and geoms):
            parts = [part for geom in geoms
                     if (part := self.geom_inertial(geom, self.attributes(geom, childclass))) is not None]
            combined = combine(parts) if parts else NO_MASS
            check_inertia(self.document, body, combined.mass, combined.tensor)
            return Inertial(combined.mass, combined.centre - shift, combined.tensor)
        if inertial is None:
            return NO_MASS
        values = inertial.attrib
        mass = self.document.number(inertial, "mass")
        if "fullinertia" in values:
            xx, yy, zz, xy, xz, yz = self.document.numbers(inertial, "fullinertia", 6)
            tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        else:
            tensor = np.diag(self.document.numbers(inertial, "diaginertia", 3))
        check_inertia(self.document, body, mass, tensor)
        position, rotation = self.pose(inertial, values)
        return Inertial(mass, position - shift, rotation @ tensor @ rotation.T)


#: The number of sizes each geom type's volume needs (MJCF sizes are radii and half lengths).
_GEOM_SIZES = {"sphere": 1, "capsule": 2, "cylinder": 2, "box": 3, "ellipsoid": 3}


def _geom_volume_inertia(shape: str, size: tuple[float, ...]) -> tuple[float, np.ndarray]:
    """A geom's volume and its central principal moments per unit mass (MuJoCo's formulas; a capsule
    is a cylinder and two hemispheres, as MuJoCo's compiler sums them)."""
    if shape == "sphere":
        (r,) = size
        return 4 / 3 * math.pi * r ** 3, np.full(3, 2 / 5 * r * r)
    if shape == "box":
        a, b, c = size
        return 8 * a * b * c, np.array([b * b + c * c, a * a + c * c, a * a + b * b]) / 3
    if shape == "ellipsoid":
        a, b, c = size
        return 4 / 3 * math.pi * a * b * c, np.array([b * b + c * c, a * a + c * c, a * a + b * b]) / 5
    r, half = size
    h = 2 * half
    cylinder = math.pi * r * r * h
    if shape == "cylinder":
        return cylinder, np.array([(3 * r * r + h * h) / 12, (3 * r * r + h * h) / 12, r * r / 2])
    sphere = 4 / 3 * math.pi * r ** 3
    volume = cylinder + sphere
    side = (cylinder * (3 * r * r + h * h) / 12 + 2 / 5 * sphere * r * r + sphere * h * (3 * r + 2 * h) / 8)
    return volume, np.array([side, side, cylinder * r * r / 2 + 2 / 5 * sphere * r * r]) / volume


def _origin(position: np.ndarray, rotation: np.ndarray) -> tuple[float, ...]:
    return (*map(float, position), *rpy_of(rotation))


def load_mjcf(path: str | Path, *, coordinates: str = "joint", package_paths: Sequence[str | Path] = ()) -> System:
    """Read an MJCF (MuJoCo XML) file into a :class:`~kronlag.System` (see the module docstring).

    Parameters
    ----------
    path : str or Path
    coordinates : {"joint", "absolute"}
        Joint coordinates (default) or absolute body coordinates (:mod:`.absolute`).
    package_paths : sequence of paths
        Folders searched first for mesh files (:mod:`.meshes`).

    Returns
    -------
    System
        Named after the model; ``system.robot`` holds the joints with their ranges, damping and
        friction loss, the link frames, ``redundant`` (dropped rows) and the skipped elements.

    Raises
    ------
    ModelFileError
        One line naming the file, the line and the element.
    """
    document = read_xml(path)
    root = document.root
    if root.tag != "mujoco":
        raise document.error(root, "the root element of an MJCF file must be <mujoco>")
    for child in root:
        if child.tag not in _TOP_USED:
            document.skip(child, "mujoco")
    reader = _Reader(document)
    meshes = _mesh_assets(document)
    option = root.find("option")
    gravity = (0.0, 0.0, -9.81) if option is None else three(document.numbers(option, "gravity", 3,
                                                                              default=(0, 0, -9.81)))
    worldbody = root.find("worldbody")
    if worldbody is None:
        raise document.error(root, "has no <worldbody>")
    links: dict[str, Element] = {"world": worldbody}
    inertials: dict[str, Inertial] = {"world": NO_MASS}
    specs: list[TreeJoint] = []
    shifts: dict[str, np.ndarray] = {"world": np.zeros(3)}
    joint_elements: dict[str, Element] = {}
    visuals: list[VisualSpec] = []

    def read_body(body: Element, parent: str, childclass: str) -> None:
        values = reader.attributes(body, childclass)
        name = document.required(body, "name") if "name" in body.attrib else f"body{len(links)}"
        if name in links:
            raise document.error(body, "a second body of this name")
        childclass = body.get("childclass", childclass)
        position, rotation = reader.pose(body, values)
        position = position - shifts[parent]  # the parent's link frame is at its last joint's anchor
        previous, anchor, link = parent, np.zeros(3), parent
        joints = [child for child in body if child.tag in ("joint", "freejoint")]
        for index, joint in enumerate(joints):
            attributes = reader.attributes(joint, childclass)
            kind = "free" if joint.tag == "freejoint" else attributes.get("type", "hinge")
            if kind not in _JOINT_KINDS:
                raise document.error(joint, f"unknown joint type {kind!r}; MJCF joint types are "
                                            f"{', '.join(_JOINT_KINDS)}")
            if float(attributes.get("ref", "0")) != 0:
                raise document.error(joint, "ref other than 0 is not supported (the reference pose is q = 0)")
            joint_name = joint.get("name") or f"{name}_joint{index}"
            at = np.array(reader.numbers(joint, attributes, "pos", 3, default=(0, 0, 0)))
            axis = np.array(reader.numbers(joint, attributes, "axis", 3, default=(0, 0, 1)))
            if not np.linalg.norm(axis):
                raise document.error(joint, "axis is the zero vector")
            link = name if index == len(joints) - 1 else f"{name}:{joint_name}"
            step = rotation @ at + position if index == 0 else at - anchor
            origin = _origin(step, rotation if index == 0 else np.eye(3))
            low_high = reader.numbers(joint, attributes, "range", 2, default=(0, 0))
            limited = attributes.get("limited", "auto") == "true" or (
                attributes.get("limited", "auto") == "auto" and low_high != (0.0, 0.0))
            converted = tuple(reader.angle(x) for x in low_high) if kind in ("hinge", "ball") else low_high
            limits = JointLimits(lower=converted[0] if limited else None, upper=converted[1] if limited else None,
                                 damping=float(attributes.get("damping", 0)) or None,
                                 friction=float(attributes.get("frictionloss", 0)) or None)
            specs.append(TreeJoint(joint, joint_name, _JOINT_KINDS[kind], previous, link,
                                   origin, tuple(axis / np.linalg.norm(axis)), limits))
            joint_elements[joint_name] = joint
            links[link], inertials[link], shifts[link] = body, NO_MASS, np.zeros(3)
            previous, anchor = link, at
        if not joints:
            specs.append(TreeJoint(body, f"{name}:weld", "fixed", parent, name, _origin(position, rotation),
                                   (1.0, 0.0, 0.0)))
        links[name], shifts[name] = body, anchor
        inertials[name] = reader.inertial(body, anchor, childclass)
        for geom in body.findall("geom"):
            read_geom(geom, name, childclass, anchor)
        for child in body:
            if child.tag not in _BODY_USED and child.tag != "freejoint":
                document.skip(child, "body")
        for child in body.findall("body"):
            read_body(child, name, childclass)

    def read_geom(geom: Element, link: str, childclass: str, anchor: np.ndarray) -> None:
        attributes = reader.attributes(geom, childclass)
        shape, size, position, rotation = reader.geom_frame(geom, attributes)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation, position - anchor
        full = {"box": lambda: tuple(2 * x for x in size[:3]), "sphere": lambda: size[:1],  # MJCF: half sizes
                "cylinder": lambda: (size[0], 2 * size[1]), "capsule": lambda: (size[0], 2 * size[1])}
        if shape in full and len(size) >= {"box": 3, "sphere": 1}.get(shape, 2):
            visuals.append((link, shape, full[shape](), pose, None))
        elif shape == "mesh":
            file, scale = meshes.get(attributes.get("mesh", ""), (attributes.get("mesh"), (1.0, 1.0, 1.0)))
            visuals.append((link, "mesh", scale, pose, file))

    for child in worldbody:
        if child.tag == "body":
            read_body(child, "world", "main")
        elif child.tag == "geom":
            read_geom(child, "world", "main", np.zeros(3))
        else:
            document.skip(child, "worldbody")
    system = build_system(document, name=root.get("model") or Path(path).stem, file_format="mjcf", links=links,
                          inertials=inertials, specs=specs, visuals=visuals, gravity=gravity,
                          coordinates=coordinates, package_paths=package_paths)
    equality = root.find("equality")
    for index, element in enumerate(() if equality is None else list(equality)):
        _add_equality(document, system, element, index, shifts)
    report_skipped(document, system)
    return system


def _mesh_assets(document: XmlDocument) -> dict[str, tuple[str, tuple[float, ...]]]:
    """``<asset><mesh>`` by name (default: the file's stem): its file (in ``<compiler meshdir>`` or
    ``assetdir``, relative to the model file) and scale; the other assets are skipped."""
    compiler = document.root.find("compiler")
    folder = "" if compiler is None else compiler.get("meshdir", compiler.get("assetdir", ""))
    meshes = {}
    for asset in document.root.findall("asset"):
        for child in asset:
            if child.tag != "mesh" or child.get("file") is None:
                document.skip(child, "asset")
                continue
            file = child.get("file", "")
            name = child.get("name") or Path(file).stem
            path = file if Path(file).is_absolute() or not folder else str(Path(folder) / file)
            meshes[name] = (path, document.numbers(child, "scale", 3, default=(1, 1, 1)))
    return meshes


def _frame_of(document: XmlDocument, system: System, element: Element, key: str) -> tuple[str, sp.Matrix, sp.Matrix]:
    """``(link, origin, rotation)`` of the link named by ``element``'s attribute ``key`` (``world``: the ground)."""
    link = document.required(element, key)
    frames = robot_of(system).frames
    if link not in frames:
        raise document.error(element, f"{key}={link!r} is not a body of the file")
    frame = frames[link]
    return link, sp.Matrix(frame.origin), sp.Matrix(frame.rotation)


def _identically_zero(expression: sp.Expr, at: np.ndarray, symbols: list) -> bool:
    """Whether a row is zero at the reference and at random coordinates (then it is zero everywhere,
    but for a set of measure zero that random points do not hit)."""
    evaluate = ExpressionFunction({"row": sp.Matrix([expression])}, [("q", symbols)], name="constraint_row")
    points = np.vstack([at, np.random.default_rng(21).uniform(-np.pi, np.pi, (4, len(symbols)))])
    return bool(np.all(np.abs(evaluate.batch(points)["row"]) <= _ZERO_ROW))


def add_rows(document: XmlDocument, system: System, element: Element, name: str, rows) -> None:
    """Add the rows ``(suffix, expression)``; drop those identically zero (listed in
    ``system.robot.redundant``), refuse a nonzero constant (the loop cannot be closed)."""
    symbols = list(system.coordinates)
    at = np.array([robot_of(system).q_reference.get(q.name, 0.0) for q in symbols])
    for suffix, expression in rows:
        row = f"{name}.{suffix}"
        if not expression.free_symbols and abs(float(expression)) > _ZERO_ROW:
            raise document.error(element, f"row {suffix}: the constraint cannot be closed at the reference pose: "
                                          f"residual {float(expression):.3g}")
        if _identically_zero(expression, at, symbols):
            robot_of(system).redundant.append(row)
        else:
            system.add_constraint(expression, name=row)
    _check_closure(document, system, element, at)


def _check_closure(document: XmlDocument, system: System, element: Element, at: np.ndarray) -> None:
    """Refuse a loop that cannot be closed near the reference pose ``at``: unless every constraint
    row vanishes there, Gauss-Newton steps (finite-difference Jacobian) from ``at`` must close them
    all; the error gives the residual before and after."""
    symbols = list(system.coordinates)
    expressions = [constraint.expression for constraint in system.constraints]
    if not expressions or set().union(*(e.free_symbols for e in expressions)) - set(symbols):
        return
    evaluate = ExpressionFunction({"rows": sp.Matrix(expressions)}, [("q", symbols)], name="loop_constraints")

    def residual(q: np.ndarray) -> np.ndarray:
        return evaluate(q)["rows"].ravel()

    q, values = at.astype(float), residual(at.astype(float))
    start = float(np.abs(values).max())
    if start <= _CLOSED:
        return
    step = 1e-7
    for _ in range(_CLOSING_STEPS):
        jacobian = np.column_stack([(residual(q + step * unit) - residual(q - step * unit)) / (2 * step)
                                    for unit in np.eye(len(q))])
        q = q - np.linalg.lstsq(jacobian, values, rcond=None)[0]
        values = residual(q)
        if np.abs(values).max() <= _CLOSED:
            return
    worst = system.constraints[int(np.argmax(np.abs(values)))].name
    raise document.error(element, f"the loop cannot be closed near the reference pose: constraint residual "
                                  f"{start:.3g} there, {float(np.abs(values).max()):.3g} (row {worst}) after "
                                  f"{_CLOSING_STEPS} Gauss-Newton steps")


def _add_equality(document: XmlDocument, system: System, element: Element, index: int,
                  shifts: dict[str, np.ndarray]) -> None:
    if element.get("active", "true") == "false":
        document.skip(element, "equality (inactive)")
        return
    name = element.get("name") or f"{element.tag}{index}"
    if element.tag == "joint":
        coordinates = robot_of(system).joint_values
        first = document.required(element, "joint1")
        second = element.get("joint2")
        for joint in (first, second):
            if joint is not None and joint not in coordinates:
                raise document.error(element, f"names the joint {joint!r}, which is not a hinge or slide of the file")
        coefficients = document.numbers(element, "polycoef", 5, default=(0, 1, 0, 0, 0))
        leader = coordinates[second] if second is not None else sp.Integer(0)
        polynomial = sum(sp.Float(c) * leader ** k for k, c in enumerate(coefficients) if c != 0) \
            if second is not None else sp.Float(coefficients[0])
        add_rows(document, system, element, name, [("joint", coordinates[first] - polynomial)])
        return
    if element.tag not in ("connect", "weld"):
        document.skip(element, "equality")
        return
    link1, origin1, rotation1 = _frame_of(document, system, element, "body1")
    link2, origin2, rotation2 = (_frame_of(document, system, element, "body2") if element.get("body2")
                                 else ("world", sp.zeros(3, 1), sp.eye(3)))
    if link1 == link2:
        raise document.error(element, f"joins body {link1!r} to itself")
    if element.tag == "connect":
        anchor1 = np.array(document.numbers(element, "anchor", 3)) - shifts[link1]
        point1 = origin1 + rotation1 * sp.Matrix(anchor1)
        reference2 = (at_reference(system, rotation2).T
                      @ (at_reference(system, point1) - at_reference(system, origin2)))
        point2 = origin2 + rotation2 * sp.Matrix(reference2.ravel())
    else:
        anchor2 = np.array(document.numbers(element, "anchor", 3, default=(0, 0, 0))) - shifts[link2]
        point2 = origin2 + rotation2 * sp.Matrix(anchor2)
        relpose = document.numbers(element, "relpose", 7, default=(0, 1, 0, 0, 0, 0, 0))
        if any(relpose[3:]):
            relative = _quaternion_matrix(*relpose[3:])  # body2 in body1
        else:
            relative = at_reference(system, rotation1).T @ at_reference(system, rotation2)
        reference1 = (at_reference(system, rotation1).T
                      @ (at_reference(system, point2) - at_reference(system, origin1)))
        point1 = origin1 + rotation1 * sp.Matrix(reference1.ravel())
    rows = list(zip(("x", "y", "z"), point2 - point1))
    if element.tag == "weld":
        rows += orientation_rows(rotation1, relative, rotation2)
    add_rows(document, system, element, name, rows)
