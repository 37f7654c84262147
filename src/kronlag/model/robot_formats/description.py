"""What a robot file holds beyond the :class:`~kronlag.System`: its joints with their limits, its
visual geometry, the parameter values and the reference pose, and the elements it skipped.

Every reader (:mod:`.urdf`) returns a System whose ``robot`` attribute is a
:class:`RobotDescription`; :func:`kronlag.load_model` turns it into a model file's numbers.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...core.errors import KronlagWarning
from ..frames import Frame

__all__ = ["RobotFileWarning", "JointLimits", "RobotJoint", "LoopClosure", "Visual", "TreeBody", "RobotDescription",
           "coordinate_name"]


class RobotFileWarning(KronlagWarning):
    """A robot file holds something kronlag does not use (listed once per file) or a mesh it cannot find."""


@dataclass(frozen=True)
class JointLimits:
    """A joint's limits and losses as the file gives them (``None``: not given); kept as data, not
    applied to the dynamics (an issue on joint friction and limits will use them)."""

    lower: float | None = None
    upper: float | None = None
    effort: float | None = None
    velocity: float | None = None
    damping: float | None = None
    friction: float | None = None


@dataclass(frozen=True)
class RobotJoint:
    """A joint of the file.

    Attributes
    ----------
    name, kind : str
        The file's name and type (``revolute``, ``continuous``, ``prismatic``, ``fixed``).
    parent, child : str
        Link names.
    axis : tuple of 3 floats
        Unit axis in the joint frame.
    origin : tuple of 6 floats
        ``x y z roll pitch yaw`` of the joint frame in the parent link's frame.
    coordinate : str or None
        The (first) coordinate the joint moves (``None`` for a fixed joint, merged into its parent).
    limits : JointLimits
    mimic : (joint, multiplier, offset) or None
        ``q = multiplier * q_joint + offset``, added as the holonomic constraint ``"<name>.mimic"``.
    torque : str or None
        The parameter of the joint's actuator torque or force (``"tau_<coordinate>"``).
    coordinates : tuple of str
        All its coordinates: one, or those of a floating, ball, planar or universal joint
        (``<name>_x``, ..., ``<name>_e0 .. _e3``; see :mod:`.tree`).
    """

    name: str
    kind: str
    parent: str
    child: str
    axis: tuple[float, float, float]
    origin: tuple[float, ...]
    coordinate: str | None
    limits: JointLimits = JointLimits()
    mimic: tuple[str, float, float] | None = None
    torque: str | None = None
    coordinates: tuple[str, ...] = ()


@dataclass(frozen=True)
class LoopClosure:
    """A joint of the file that closes a loop (an SDF joint whose child is already in the tree).

    Attributes
    ----------
    joint, kind, parent, child : str
        The joint's name and type, its parent and child links.
    frame : str
        The link in whose frame the rows' components are (the loop's nearest common ancestor link):
        the multipliers of ``.x .y .z`` are the force on the parent link at the joint point, the
        negative of the force on the child link, in that frame.
    rows : tuple of str
        The constraints added (``"<joint>.x"``, ...).
    dropped : tuple of str
        Its rows dropped as identically zero (also in :attr:`RobotDescription.redundant`).
    """

    joint: str
    kind: str
    parent: str
    child: str
    frame: str
    rows: tuple[str, ...]
    dropped: tuple[str, ...] = ()


@dataclass(frozen=True)
class Visual:
    """Visual geometry of a link: ``shape`` is ``box`` (``size`` = 3 edge lengths), ``cylinder``
    (radius, length), ``sphere`` (radius), ``capsule`` (radius, length) or ``mesh`` (a named
    placeholder: ``filename`` and ``size`` = its scale); ``pose`` is the 4x4 transform from the
    link frame; ``body`` the System body that carries it (``"ground"`` for the fixed root)."""

    link: str
    body: str
    shape: str
    size: tuple[float, ...]
    pose: np.ndarray
    filename: str | None = None


@dataclass(frozen=True)
class TreeBody:
    """A moving body as the reader made it in joint coordinates: the System's body (a
    :class:`~kronlag.RigidBody`) and its centre of mass in its own frame, the frame of the link it
    is named after (the recursive dynamics kernels, :mod:`kronlag.numeric.codegen.recursive`)."""

    body: Any
    centre: tuple[float, float, float]


@dataclass
class RobotDescription:
    """The file's data kept with its System (``system.robot``).

    Attributes
    ----------
    source, format : str
    root : str
        The root link, fixed to the world (the ``ground``).
    joints : tuple of RobotJoint
    body_of_link : dict
        The System body each link moves with (links joined by fixed joints share one; the
        root and links fixed to it: ``"ground"``).
    visuals : tuple of Visual
    frames : dict of str to Frame
        Every link's frame (origin and rotation, expressions of the coordinates) in the world.
    local_frames : dict of str to (str, Frame)
        Every link but the root: its parent link and its frame in the parent link's frame
        (expressions of its joint's coordinates only).
    values : dict of str to float
        Default parameter values: ``g`` (9.81, or the magnitude of the file's gravity) and every
        actuator torque 0.
    q_reference : dict of str to float
        The reference pose of the file (every joint at 0, mimic joints at their offset).
    skipped : str
        The elements the reader did not use, with their counts.
    redundant : list of str
        Constraint rows of the file dropped as identically zero (a planar MJCF ``connect``'s
        out-of-plane row).
    loops : tuple of LoopClosure
        The joints that close loops (SDF), in file order.
    joint_values : dict of str to sympy.Expr
        Each moving joint's value (angle or slide) as an expression of the coordinates: its
        coordinate in joint coordinates; in absolute body coordinates (:mod:`.absolute`) the angle
        or slide between its bodies.
    tree_bodies : dict of str to TreeBody
        The moving bodies with mass or inertia, by name, as :func:`~.tree.build_system` made them in
        joint coordinates (empty in absolute body coordinates).
    """

    source: str
    format: str
    root: str
    joints: tuple[RobotJoint, ...] = ()
    body_of_link: dict[str, str] = field(default_factory=dict)
    visuals: tuple[Visual, ...] = ()
    frames: dict[str, Frame] = field(default_factory=dict)
    local_frames: dict[str, tuple[str, Frame]] = field(default_factory=dict)
    values: dict[str, float] = field(default_factory=dict)
    q_reference: dict[str, float] = field(default_factory=dict)
    skipped: str = ""
    redundant: list[str] = field(default_factory=list)
    loops: tuple[LoopClosure, ...] = ()
    joint_values: dict[str, Any] = field(default_factory=dict)
    tree_bodies: dict[str, TreeBody] = field(default_factory=dict)

    def joint(self, name: str) -> RobotJoint:
        """The joint called ``name``."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(name)


_RESERVED = re.compile(r"^(lambda\d+|mu\d+|t|g|tau_.*)$")


def coordinate_name(joint: str, taken: set[str]) -> str:
    """A coordinate name for ``joint``: the joint's name where it is an identifier that no other
    symbol uses, else one made of it (``"joint-1"`` -> ``"joint_1"``, ``"g"`` -> ``"q_g"``).

    >>> coordinate_name("panda_joint1", set())
    'panda_joint1'
    >>> coordinate_name("leg.knee", {"leg_knee"})
    'q_leg_knee'
    """
    name = re.sub(r"\W", "_", joint)
    if not name.isidentifier():
        name = "q_" + name
    while _RESERVED.match(name) or name in taken or name + "d" in taken or name + "dd" in taken:
        name = "q_" + name
    return name
