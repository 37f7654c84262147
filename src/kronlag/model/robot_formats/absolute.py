"""Absolute body coordinates for a robot file (the loaders' ``coordinates="absolute"``): each body
placed by its own coordinates, the joints as named constraints.

:func:`absolute_system` rewrites the joint-coordinate :class:`~kronlag.System` that
:func:`~kronlag.model.robot_formats.tree.build_system` made.  Every moving body gets the spatial
coordinates of :func:`kronlag.free_body` - its centre of mass ``x_<body> y_<body> z_<body>`` and the
Euler parameters ``e0_<body> .. e3_<body>`` with their norm constraint ``"<body>.normalization"``
(no gimbal lock) - and keeps its mass and inertia tensor.  Each moving joint becomes rows named after
it: a ``revolute`` (``continuous``) joint ``"<joint>.x" .y .z`` (its point on both bodies stays
together) and ``.axis1 .axis2`` (the child's axis stays along the parent's); a ``prismatic`` joint
``.normal1 .normal2`` (the child's joint point stays on the parent's axis line) and ``.rx .ry .rz``
(the relative orientation stays).  A joint's torque (force) ``tau_<coordinate>`` acts on both
bodies; a mimic joint couples the two joint values (the angle ``atan2`` of the axes, the slide
along the axis).  The link frames (``system.robot.frames``), the stick figure and the reference
pose are the same frames in the new coordinates, so loops closed afterwards (MJCF equalities, SDF
loop joints) are written in them too.

The equations have more coordinates and constraints but each body's terms stay small and
independent of the chain's length (no nested rotations), which suits long chains.  Only spatial
bodies are written (a planar robot gets the spatial form too); every moving link must carry mass
(a massless link between two joints has no coordinates of its own: load it in joint coordinates).
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from ..bodies import RigidBody
from ..frames import GROUND, Frame
from ..rotations import (
    euler_parameter_constraint,
    euler_parameters,
    euler_parameters_of,
)
from ..system import System
from .description import RobotDescription, RobotJoint, coordinate_name
from .safe_xml import XmlDocument

__all__ = ["COORDINATE_CHOICES", "absolute_system"]

#: The values of the loaders' ``coordinates=`` option.
COORDINATE_CHOICES = ("joint", "absolute")


def _numeric(expression, at: dict) -> np.ndarray:
    return np.array(sp.Matrix(expression).subs(at).evalf(), dtype=float)


def _pose(frame: Frame, at: dict) -> np.ndarray:
    """The 4x4 transform of ``frame`` at the coordinate values ``at``."""
    result = np.eye(4)
    result[:3, :3], result[:3, 3] = _numeric(frame.rotation, at), _numeric(frame.origin, at).ravel()
    return result


def _perpendiculars(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors that make a right-handed frame ``(u, v, axis)`` with the unit ``axis``."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _matrix(values: np.ndarray) -> sp.Matrix:
    """A constant matrix of the file's numbers (exact zeros and ones kept small)."""
    return sp.Matrix(values.shape[0], values.shape[1] if values.ndim > 1 else 1,
                     [sp.Integer(int(x)) if x in (-1.0, 0.0, 1.0) else sp.Float(x) for x in values.ravel()])


def absolute_system(document: XmlDocument, joint_system: System) -> System:
    """``joint_system`` (a robot file's System in joint coordinates) in absolute body coordinates
    (see the module docstring).

    Raises
    ------
    ModelFileError
        A moving link without mass, or a joint of several coordinates (floating, ball, planar,
        universal), at the file's element.
    """
    robot: RobotDescription = joint_system.robot  # type: ignore[assignment]
    zero = {q: 0 for q in joint_system.coordinates}
    reference = {q: robot.q_reference.get(q.name, 0.0) for q in joint_system.coordinates}
    bodies = {body.name: body for body in joint_system.bodies}
    moving = [joint for joint in robot.joints if joint.coordinate is not None]
    for joint in moving:
        if len(joint.coordinates) > 1:
            raise document.error(document.root, f"coordinates='absolute': the {joint.kind} joint {joint.name!r} has "
                                                f"{len(joint.coordinates)} coordinates; absolute coordinates take "
                                                "revolute, continuous and prismatic joints only: load this file in "
                                                "joint coordinates")
        if joint.child not in bodies:
            raise document.error(document.root, f"coordinates='absolute': the link {joint.child!r} (moved by the "
                                                f"joint {joint.name!r}) has no mass, so no coordinates of its own; "
                                                "load this file in joint coordinates")
    taken = {symbol.name for symbol in joint_system.parameters}
    coordinates, new_bodies, normalizations = [], [], []
    link_frames: dict[str, Frame] = {GROUND: Frame((0, 0, 0), sp.eye(3))}
    start: dict[str, float] = {}
    for body in joint_system.bodies:
        assert isinstance(body, RigidBody)  # build_system adds rigid bodies only
        label = coordinate_name(body.name, taken)
        names = [f"{axis}_{label}" for axis in "xyz"] + [f"e{k}_{label}" for k in range(4)]
        symbols = sp.symbols(" ".join(names))
        taken.update(names)
        coordinates.extend(symbols)
        position, parameters = sp.Matrix(symbols[:3]), symbols[3:]
        rotation = euler_parameters(*parameters)
        link = _pose(robot.frames[body.name], zero)
        centre = link[:3, :3].T @ (_numeric(body.position, zero).ravel() - link[:3, 3])  # in the link frame
        new_bodies.append(RigidBody(body.name, mass=body.mass, inertia=body.inertia, position=position,
                                    rotation=rotation, simplify=False))
        normalizations.append((f"{body.name}.normalization", euler_parameter_constraint(*parameters)))
        link_frames[body.name] = Frame(position - rotation * _matrix(centre), rotation)
        placed = _pose(robot.frames[body.name], reference)
        start.update(zip(names, map(float, [*(placed[:3, :3] @ centre + placed[:3, 3]),
                                            *euler_parameters_of(placed[:3, :3])])))
    system = System(coordinates, parameters=joint_system.parameters, gravity=joint_system.gravity,
                    name=joint_system.name)
    for body in new_bodies:
        system.add_body(body)
    for name, expression in normalizations:
        system.add_constraint(expression, name=name)

    def frame_of(link: str) -> Frame:
        """A link's frame in the new coordinates: its body's, moved by the constant offset of q = 0."""
        body = robot.body_of_link[link]
        outer = link_frames[body]
        offset = np.linalg.inv(_pose(robot.frames[body], zero)) @ _pose(robot.frames[link], zero) \
            if body != GROUND else _pose(robot.frames[link], zero)
        return Frame(sp.Matrix(outer.origin) + sp.Matrix(outer.rotation) * _matrix(offset[:3, 3]),
                     sp.Matrix(outer.rotation) * _matrix(offset[:3, :3]))

    frames = {link: frame_of(link) for link in robot.frames}
    values: dict[str, sp.Expr] = {}
    forces = sp.zeros(len(coordinates), 1)
    for joint in moving:
        # the joint frame is the child's link frame at q = 0
        placement = np.linalg.inv(_pose(robot.frames[joint.parent], zero)) @ _pose(robot.frames[joint.child], zero)
        value = _add_joint(system, joint, frames, placement)
        values[joint.name] = value
        if joint.torque is not None and joint.kind != "prismatic":
            axis = sp.Matrix(frames[joint.child].rotation) * _matrix(np.array(joint.axis))
            system.add_torque(joint.child, sp.Symbol(joint.torque) * axis, name=f"{joint.name} torque")
            parent = robot.body_of_link[joint.parent]
            if parent != GROUND:
                system.add_torque(parent, -sp.Symbol(joint.torque) * axis, name=f"{joint.name} reaction torque")
        elif joint.torque is not None:
            forces += sp.Symbol(joint.torque) * sp.Matrix([value]).jacobian(coordinates).T
    if any(forces):
        system.add_generalized_force(list(forces), name="joint forces")
    for joint in moving:
        if joint.mimic is not None:
            leader, multiplier, offset = joint.mimic
            system.add_constraint(values[joint.name] - sp.Float(multiplier) * values[leader] - sp.Float(offset),
                                  name=f"{joint.name}.mimic")
    _add_drawing(system, robot, frames)
    system.robot = RobotDescription(
        source=robot.source, format=robot.format, root=robot.root,
        joints=tuple(RobotJoint(j.name, j.kind, j.parent, j.child, j.axis, j.origin, None, j.limits, j.mimic,
                                j.torque) for j in robot.joints),
        body_of_link=robot.body_of_link, visuals=robot.visuals, frames=frames, values=robot.values,
        q_reference=start, skipped=robot.skipped, redundant=list(robot.redundant), joint_values=values)
    return system


def _add_joint(system: System, joint: RobotJoint, frames: dict[str, Frame],
               placement: np.ndarray) -> sp.Expr:
    """Add the rows of a moving joint whose frame is ``placement`` (4x4) in its parent link's frame;
    its value (angle or slide) as an expression of the coordinates."""
    parent, child = frames[joint.parent], frames[joint.child]
    joint_rotation = sp.Matrix(parent.rotation) * _matrix(placement[:3, :3])
    joint_point = sp.Matrix(parent.origin) + sp.Matrix(parent.rotation) * _matrix(placement[:3, 3])
    axis = np.array(joint.axis)
    u, v = _perpendiculars(axis)
    along, across1, across2 = (joint_rotation * _matrix(x) for x in (axis, u, v))
    offset = sp.Matrix(child.origin) - joint_point
    rotation = sp.Matrix(child.rotation)
    if joint.kind == "prismatic":
        rows = [("normal1", across1.dot(offset)), ("normal2", across2.dot(offset))]
        rows += [(label, (joint_rotation * sp.eye(3)[:, i]).dot(rotation * sp.eye(3)[:, j]))
                 for label, i, j in (("rx", 1, 2), ("ry", 2, 0), ("rz", 0, 1))]
        value = along.dot(offset)
    else:
        child_axis = rotation * _matrix(axis)
        rows = [*zip(("x", "y", "z"), offset), ("axis1", across1.dot(child_axis)), ("axis2", across2.dot(child_axis))]
        turned = rotation * _matrix(u)
        value = sp.atan2(across2.dot(turned), across1.dot(turned))
    for suffix, expression in rows:
        system.add_constraint(expression, name=f"{joint.name}.{suffix}")
    return value


def _add_drawing(system: System, robot: RobotDescription, frames: dict[str, Frame]) -> None:
    """A stick figure through the link origins from the root to each leaf link (the joint-coordinate
    drawing's branches, in the new coordinates)."""
    parent_of = {joint.child: joint.parent for joint in robot.joints}
    leaves = [joint.child for joint in robot.joints if not any(other.parent == joint.child for other in robot.joints)]
    drawn: set[str] = set()
    for leaf in leaves:
        path = [leaf]
        while path[-1] in parent_of and path[-1] not in drawn:
            path.append(parent_of[path[-1]])
        drawn.update(path)
        points = [sp.Matrix(frames[link].origin) for link in reversed(path)]
        unique = [point for k, point in enumerate(points) if k == 0 or point != points[k - 1]]
        if len(unique) >= 2 and any(point.free_symbols for point in unique):
            system.add_drawing_line(unique, name=f"{leaf} branch")
