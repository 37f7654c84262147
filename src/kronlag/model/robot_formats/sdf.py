"""SDF reader: :func:`load_sdf` turns an SDFormat model into a :class:`~kronlag.System` in joint
coordinates, with the joints that close loops as exact constraints.

Poses are resolved in the model frame at the reference pose (every joint at 0): a ``<link>``'s
``<pose>`` is relative to the model unless ``relative_to`` names a link or joint, a ``<joint>``'s to
its child link (SDFormat 1.7); a joint ``<axis><xyz>`` is in the joint frame, or in the model
frame with ``expressed_in="__model__"`` (or the 1.6 ``<use_parent_model_frame>``).  Each link's
frame in the System (``system.robot.frames``) is the frame of the joint that moves it.

Joints are read in file order: the first joint naming a link as its child places it in the tree
(``revolute``, ``continuous``, ``prismatic``: one coordinate; ``ball``: the Euler parameters
``<joint>_e0 .. _e3``; ``universal``: ``<joint>_1`` about ``<axis>`` and ``<joint>_2`` about ``<axis2>``;
``fixed``: merged; see :mod:`.tree`), and a joint
whose child is already in the tree closes a loop: its constraints are added by name -
``"<joint>.x"``, ``.y``, ``.z`` (the joint point of both links stays together, components in the
frame of the loop's nearest common ancestor link; ``ball``; their multipliers are the force on the
parent link at the joint point, in that frame),
``.axis1``, ``.axis2`` (``revolute``: the axis of the child stays along the parent's), ``.cross``
(``universal``: the two axes stay perpendicular), ``.rx .ry .rz`` (``fixed``).  Rows that are
identically zero (the out-of-plane rows of a planar loop) are dropped and listed in
``system.robot.redundant``; ``system.robot.loops`` describes each loop-closing joint
(:class:`~.description.LoopClosure`: its rows, dropped rows and frame).  A model whose root link
no joint fixes to ``world`` has a floating base: the joint ``"root_joint"`` (``root_joint_x, _y, _z`` from the root link's pose in the file
and the Euler parameters ``root_joint_e0 .. _e3``, with ``"root_joint.normalization"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np
import sympy as sp

from ..system import System
from .description import JointLimits, LoopClosure
from .mjcf import add_rows
from .safe_xml import XmlDocument, numbers, read_xml
from .tree import (NO_MASS, Inertial, TreeJoint, VisualSpec, at_reference, build_system, check_inertia,
                   common_ancestor, orientation_rows, relative_frames, report_skipped, robot_of, rpy_matrix, rpy_of)

__all__ = ["load_sdf"]

_TREE_TYPES = {"revolute": "revolute", "continuous": "continuous", "prismatic": "prismatic", "fixed": "fixed",
               "ball": "ball", "universal": "universal"}
#: The floating joint of a model not fixed to the world (Pinocchio's name).
ROOT_JOINT = "root_joint"
_LOOP_TYPES = ("revolute", "continuous", "ball", "universal", "fixed")
_MODEL = "__model__"


def _text(document: XmlDocument, element: Element, tag: str, count: int,
          default: tuple[float, ...] | None = None) -> tuple[float, ...]:
    """The ``count`` numbers of the text of ``element``'s child ``tag`` (``default`` if absent)."""
    child = element.find(tag)
    if child is None:
        if default is None:
            raise document.error(element, f"needs <{tag}> ({count} number{'s' if count > 1 else ''})")
        return tuple(float(x) for x in default)
    values = numbers(child.text or "")
    if values is None or len(values) != count:
        raise document.error(child, f"{(child.text or '').strip()!r}: expected {count} finite number"
                                    f"{'s' if count > 1 else ''}")
    return values


def _matrix(pose: tuple[float, ...]) -> np.ndarray:
    result = np.eye(4)
    result[:3, :3], result[:3, 3] = rpy_matrix(*pose[3:]), pose[:3]
    return result


def _origin(transform: np.ndarray) -> tuple[float, ...]:
    return (*map(float, transform[:3, 3]), *rpy_of(transform[:3, :3]))


class _Poses:
    """The model-frame transforms of the links and joints at the reference pose."""

    def __init__(self, document: XmlDocument, links: dict[str, Element], joints: dict[str, Element]):
        self.document, self.links, self.joints = document, links, joints
        self.known: dict[str, np.ndarray] = {_MODEL: np.eye(4), "world": np.eye(4)}
        self.pending: set[str] = set()

    def of(self, name: str, element: Element) -> np.ndarray:
        if name in self.known:
            return self.known[name]
        if name in self.pending:
            raise self.document.error(element, f"the poses relative_to {name!r} form a cycle")
        self.pending.add(name)
        target = self.links.get(name, self.joints.get(name))
        if target is None:
            raise self.document.error(element, f"relative_to={name!r} is not a link or joint of the model")
        pose = target.find("pose")
        default = _MODEL if target.tag == "link" else (target.findtext("child") or "").strip()
        base = (pose.get("relative_to") if pose is not None else None) or default
        local = _matrix(_text(self.document, target, "pose", 6, default=(0,) * 6))
        self.known[name] = self.of(base, target) @ local
        return self.known[name]


def _inertial(document: XmlDocument, link: Element, frame: np.ndarray, link_pose: np.ndarray) -> Inertial:
    """The link's inertial in ``frame`` (the frame of its joint, model coordinates)."""
    inertial = link.find("inertial")
    if inertial is None:
        return NO_MASS
    mass = _text(document, inertial, "mass", 1)[0]
    tensor_element = inertial.find("inertia")
    if tensor_element is None:
        raise document.error(link, "<inertial> has no <inertia>")
    xx, xy, xz, yy, yz, zz = (_text(document, tensor_element, key, 1, default=(0,))[0]
                              for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
    tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    check_inertia(document, link, mass, tensor)
    placed = np.linalg.inv(frame) @ link_pose @ _matrix(_text(document, inertial, "pose", 6, default=(0,) * 6))
    rotation = placed[:3, :3]
    return Inertial(mass, placed[:3, 3], rotation @ tensor @ rotation.T)


def _axis(document: XmlDocument, joint: Element, frame: np.ndarray, tag: str = "axis") -> np.ndarray:
    """The joint's axis in the joint frame (unit)."""
    axis = joint.find(tag)
    if axis is None:
        raise document.error(joint, f"needs <{tag}><xyz>...</xyz></{tag}>")
    vector = np.array(_text(document, axis, "xyz", 3))
    xyz = axis.find("xyz")
    in_model = (xyz is not None and xyz.get("expressed_in") == _MODEL) or (
        (axis.findtext("use_parent_model_frame") or "").strip() in ("1", "true"))
    if in_model:
        vector = frame[:3, :3].T @ vector
    if not np.linalg.norm(vector):
        raise document.error(axis, "the axis is the zero vector")
    return vector / np.linalg.norm(vector)


def _limits(document: XmlDocument, joint: Element) -> JointLimits:
    axis = joint.find("axis")
    if axis is None:
        return JointLimits()
    limit, dynamics = axis.find("limit"), axis.find("dynamics")

    def value(parent: Element | None, tag: str) -> float | None:
        return None if parent is None or parent.find(tag) is None else _text(document, parent, tag, 1)[0]

    return JointLimits(lower=value(limit, "lower"), upper=value(limit, "upper"), effort=value(limit, "effort"),
                       velocity=value(limit, "velocity"), damping=value(dynamics, "damping"),
                       friction=value(dynamics, "friction"))


#: The children of each element the reader uses (the others are listed as skipped).
_USED = {"model": {"link", "joint", "pose", "static"}, "link": {"pose", "inertial", "visual"},
         "joint": {"parent", "child", "pose", "axis", "axis2"},
         "axis": {"xyz", "limit", "dynamics", "use_parent_model_frame"}, "axis2": {"xyz", "limit", "dynamics"},
         "visual": {"pose", "geometry"}, "inertial": {"pose", "mass", "inertia"}}


def _note_skipped(document: XmlDocument, element: Element) -> None:
    for child in element:
        if child.tag not in _USED[element.tag]:
            document.skip(child, element.tag)
        elif child.tag in _USED:
            _note_skipped(document, child)


def load_sdf(path: str | Path, *, coordinates: str = "joint",
             package_paths: Sequence[str | Path] = ()) -> System:
    """Read an SDFormat file (its first ``<model>``) into a :class:`~kronlag.System` (see the module
    docstring); ``coordinates`` and ``package_paths`` as for :func:`~.urdf.load_urdf`.

    Raises
    ------
    ModelFileError
        One line naming the file, the line and the element.
    """
    document = read_xml(path)
    root = document.root
    if root.tag != "sdf":
        raise document.error(root, "the root element of an SDF file must be <sdf>")
    model = root.find("model")
    if model is None and root.find("world") is not None:
        model = root.find("world")
        assert model is not None  # checked just above
        model = model.find("model")
    if model is None:
        raise document.error(root, "has no <model>")
    links = {document.required(link, "name"): link for link in model.findall("link")}
    joints = {document.required(joint, "name"): joint for joint in model.findall("joint")}
    _note_skipped(document, model)
    poses = _Poses(document, links, joints)
    parent_joint: dict[str, str] = {}
    loops: list[str] = []
    for name, joint in joints.items():
        kind = document.required(joint, "type")
        parent, child = ((joint.findtext(tag) or "").strip() for tag in ("parent", "child"))
        for tag, link in (("parent", parent), ("child", child)):
            if link != "world" and link not in links:
                raise document.error(joint, f"<{tag}>{link}</{tag}> is not a link of the model")
        if child in parent_joint or child == "world":
            if kind not in _LOOP_TYPES:
                raise document.error(joint, f"closes a loop with type {kind!r}; loops close with "
                                            f"{', '.join(_LOOP_TYPES)} joints")
            loops.append(name)
        elif kind not in _TREE_TYPES:
            raise document.error(joint, f"type {kind!r} in the tree: supported are {', '.join(_TREE_TYPES)}")
        else:
            parent_joint[child] = name
    roots = [link for link in links if link not in parent_joint]
    floating = "world" not in {(joints[j].findtext("parent") or "").strip() for j in parent_joint.values()}
    if floating and len(roots) > 1:
        raise document.error(links[roots[1]], f"a second root link: {len(roots)} links ({', '.join(roots)}) have "
                                              "no parent joint; a model has one root, joined to every other link")

    frames = {"world": np.eye(4)}
    for link in links:
        frames[link] = poses.of(parent_joint[link], joints[parent_joint[link]]) if link in parent_joint \
            else poses.of(link, links[link])
    specs = []
    for link, name in parent_joint.items():
        joint = joints[name]
        parent = (joint.findtext("parent") or "").strip()
        kind = _TREE_TYPES[document.required(joint, "type")]
        axis = (1.0, 0.0, 0.0) if kind in ("fixed", "ball") else tuple(_axis(document, joint, frames[link]))
        axis2 = tuple(_axis(document, joint, frames[link], "axis2")) if kind == "universal" else None
        specs.append(TreeJoint(joint, name, kind, parent, link, _origin(np.linalg.inv(frames[parent]) @ frames[link]),
                               axis, _limits(document, joint), axis2=axis2))
    order = {name: index for index, name in enumerate(joints)}
    specs.sort(key=lambda spec: order[spec.name])
    if floating:
        specs.insert(0, TreeJoint(model, ROOT_JOINT, "floating", "world", roots[0], _origin(frames[roots[0]]),
                                  (1.0, 0.0, 0.0)))
    visuals: list[VisualSpec] = []
    for link, element in links.items():
        for visual in element.findall("visual"):
            geometry = visual.find("geometry")
            shape = None if geometry is None else next(iter(geometry), None)
            if shape is None:
                continue
            pose = np.linalg.inv(frames[link]) @ poses.of(link, element) @ _matrix(
                _text(document, visual, "pose", 6, default=(0,) * 6))
            sizes = {"box": lambda s=shape: _text(document, s, "size", 3),
                     "sphere": lambda s=shape: _text(document, s, "radius", 1),
                     "cylinder": lambda s=shape: _text(document, s, "radius", 1) + _text(document, s, "length", 1),
                     "capsule": lambda s=shape: _text(document, s, "radius", 1) + _text(document, s, "length", 1)}
            if shape.tag in sizes:
                visuals.append((link, shape.tag, sizes[shape.tag](), pose, None))
            elif shape.tag == "mesh":
                visuals.append((link, "mesh", _text(document, shape, "scale", 3, default=(1, 1, 1)), pose,
                                (shape.findtext("uri") or "").strip()))
    inertials = {"world": NO_MASS, **{link: _inertial(document, element, frames[link], poses.of(link, element))
                                      for link, element in links.items()}}
    system = build_system(document, name=model.get("name") or Path(path).stem, file_format="sdf",
                          links={"world": model, **links}, inertials=inertials, specs=specs, visuals=visuals,
                          coordinates=coordinates, package_paths=package_paths)
    for name in loops:
        _close(document, system, joints[name], name, poses, frames)
    report_skipped(document, system)
    return system


def _close(document: XmlDocument, system: System, joint: Element, name: str, poses: _Poses,
           frames: dict[str, np.ndarray]) -> None:
    """Add the constraints of the loop-closing ``joint``."""
    kind = joint.get("type")
    parent, child = ((joint.findtext(tag) or "").strip() for tag in ("parent", "child"))
    at = poses.of(name, joint)  # the joint frame, model coordinates at the reference
    rows = []
    frame_p, frame_c = relative_frames(system, parent, child)
    origin_p, rotation_p = sp.Matrix(frame_p.origin), sp.Matrix(frame_p.rotation)
    origin_c, rotation_c = sp.Matrix(frame_c.origin), sp.Matrix(frame_c.rotation)
    in_parent = np.linalg.inv(frames[parent]) @ at
    in_child = np.linalg.inv(frames[child]) @ at
    point_p = origin_p + rotation_p * sp.Matrix(in_parent[:3, 3])
    point_c = origin_c + rotation_c * sp.Matrix(in_child[:3, 3])
    rows += list(zip(("x", "y", "z"), point_c - point_p))
    if kind in ("revolute", "continuous", "universal"):
        axis = _axis(document, joint, at)
        axis_p = rotation_p * sp.Matrix(in_parent[:3, :3] @ axis)
        if kind == "universal":
            axis_c = rotation_c * sp.Matrix(in_child[:3, :3] @ _axis(document, joint, at, "axis2"))
            rows.append(("cross", axis_p.dot(axis_c)))
        else:
            helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
            normals = [np.cross(axis, helper)]
            normals[0] /= np.linalg.norm(normals[0])
            normals.append(np.cross(axis, normals[0]))
            axis_c = rotation_c * sp.Matrix(in_child[:3, :3] @ axis)
            rows += [(f"axis{k + 1}", (rotation_p * sp.Matrix(in_parent[:3, :3] @ n)).dot(axis_c))
                     for k, n in enumerate(normals)]
    elif kind == "fixed":
        relative = at_reference(system, rotation_p).T @ at_reference(system, rotation_c)
        rows += orientation_rows(rotation_p, relative, rotation_c)
    robot = robot_of(system)
    dropped_before = len(robot.redundant)
    add_rows(document, system, joint, name, rows)
    dropped = tuple(robot.redundant[dropped_before:])
    robot.loops += (LoopClosure(name, str(kind), parent, child, common_ancestor(system, parent, child),
                                tuple(f"{name}.{suffix}" for suffix, _ in rows if f"{name}.{suffix}" not in dropped),
                                dropped),)
