"""URDF reader: :func:`load_urdf` turns a URDF file into a :class:`~kronlag.System` in joint coordinates.

The root link is fixed to the world (the ``ground``) unless ``floating_base=True``; every revolute,
continuous and prismatic joint moves one coordinate named after it; a ``floating`` joint moves seven
(``<name>_x _y _z`` and the Euler parameters ``<name>_e0 .. _e3``, with the constraint
``"<name>.normalization"``), a ``planar`` one three (``<name>_x _y`` in the plane normal to its
axis, ``<name>_theta`` about it; see :mod:`.tree`); fixed joints are merged (their child's mass and
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

from collections.abc import Sequence
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np

from ..system import System
from .description import JointLimits
from .safe_xml import XmlDocument, read_xml
from .tree import (NO_MASS, Inertial, TreeJoint, build_system, check_inertia, report_skipped, rpy_matrix, three,
                   transform)

__all__ = ["load_urdf", "JOINT_TYPES"]

#: The URDF joint types the reader turns into coordinates (``fixed`` merges its links).
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")

#: The name of the floating joint ``load_urdf(..., floating_base=True)`` adds (Pinocchio's).
ROOT_JOINT = "root_joint"

_USED = {"robot": {"link", "joint"}, "link": {"inertial", "visual"}, "inertial": {"origin", "mass", "inertia"},
         "visual": {"origin", "geometry"}, "geometry": {"box", "cylinder", "sphere", "capsule", "mesh"},
         "joint": {"origin", "parent", "child", "axis", "limit", "dynamics", "mimic"}}



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



def _inertial(document: XmlDocument, link: Element, allow_nonphysical: bool) -> Inertial:
    """The link's inertial in its frame, checked physical (mass >= 0, tensor positive semidefinite with
    the triangle inequality, which ``allow_nonphysical`` turns into a warning); no ``<inertial>``: no mass."""
    inertial = link.find("inertial")
    if inertial is None:
        return NO_MASS
    mass_element, tensor_element = inertial.find("mass"), inertial.find("inertia")
    if mass_element is None:
        raise document.error(link, "<inertial> has no <mass value=...>")
    mass = document.number(mass_element, "value")
    if tensor_element is None:
        raise document.error(link, "<inertial> has no <inertia ixx=... ixy=... ixz=... iyy=... iyz=... izz=...>")
    xx, xy, xz, yy, yz, zz = (document.number(tensor_element, key)
                              for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
    tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    check_inertia(document, link, mass, tensor, allow_nonphysical=allow_nonphysical)
    origin = _origin(document, inertial)
    rotation = rpy_matrix(*origin[3:])
    return Inertial(mass, np.array(origin[:3]), rotation @ tensor @ rotation.T)



def _visuals(document: XmlDocument, link: Element) -> list[tuple[str, tuple[float, ...], np.ndarray, str | None]]:
    """``(shape, size, pose in the link frame, filename)`` of each ``<visual>`` with a geometry."""
    found: list[tuple[str, tuple[float, ...], np.ndarray, str | None]] = []
    for visual in link.findall("visual"):
        geometry = visual.find("geometry")
        shape = None if geometry is None else next(iter(geometry), None)
        if shape is None:
            continue
        pose = transform(_origin(document, visual))
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



def _joint(document: XmlDocument, element: Element) -> TreeJoint:
    name = document.required(element, "name")
    kind = document.required(element, "type")
    if kind not in JOINT_TYPES:
        raise document.error(element, f"unknown joint type {kind!r}; URDF joint types are {', '.join(JOINT_TYPES)}")
    links = []
    for role in ("parent", "child"):
        tag = element.find(role)
        if tag is None:
            raise document.error(element, f"has no <{role} link=...>")
        links.append(document.required(tag, "link"))
    axis_element = element.find("axis")
    axis = (1.0, 0.0, 0.0) if axis_element is None else document.numbers(axis_element, "xyz", 3)
    if kind not in ("fixed", "floating"):
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
    return TreeJoint(element, name, kind, links[0], links[1], _origin(document, element), three(axis), limits, mimic,
                     mimic_element)



def load_urdf(path: str | Path, *, coordinates: str = "joint", package_paths: Sequence[str | Path] = (),
              floating_base: bool = False, allow_nonphysical_inertia: bool = False) -> System:
    """Read a URDF file into a :class:`~kronlag.System` in joint coordinates (see the module docstring).

    Parameters
    ----------
    path : str or Path
        A ``.urdf`` file (xacro files are refused: run ``xacro`` first).
    coordinates : {"joint", "absolute"}
        Joint coordinates (default) or absolute body coordinates (:mod:`.absolute`).
    package_paths : sequence of paths
        Folders searched first for ``package://`` meshes (:mod:`.meshes`).
    floating_base : bool
        Join the root link to the world by a ``floating`` joint named ``"root_joint"`` (as
        Pinocchio's ``JointModelFreeFlyer``; legged robots' files leave it out); its coordinates
        ``root_joint_x, _y, _z`` are the root link's origin in the world and ``root_joint_e0 ..
        _e3`` its orientation.
    allow_nonphysical_inertia : bool
        Keep an ``<inertial>`` whose principal moments violate the triangle inequality, with a
        :class:`~.description.RobotFileWarning` naming the link, instead of refusing the file
        (example-robot-data's Go1, ANYmal and HyQ have such a placeholder on a massless ``base``
        link, merged by a fixed joint into the trunk).  The bodies are checked again when the
        numeric model is built: a body that is still not physical is refused there.

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
    if floating_base:
        children = {spec.child for spec in specs}
        roots = [name for name in links if name not in children]
        world = "world" if "world" not in links else "world_"
        if len(roots) == 1:  # several roots: build_system names them
            specs.append(TreeJoint(robot, ROOT_JOINT, "floating", world, roots[0], (0.0,) * 6, (1.0, 0.0, 0.0)))
            links = {world: robot, **links}
    system = build_system(document, name=robot.get("name") or Path(path).stem, file_format="urdf", links=links,
                          inertials={name: _inertial(document, element, allow_nonphysical_inertia)
                                     if element.tag == "link" else NO_MASS
                                     for name, element in links.items()},
                          specs=specs, visuals=[(name, *visual) for name, element in links.items()
                                                for visual in _visuals(document, element)],
                          coordinates=coordinates, package_paths=package_paths)
    report_skipped(document, system)
    return system
