"""Robot description files read into a :class:`~kronlag.System`: URDF (:func:`load_urdf`) and MJCF
(:func:`load_mjcf`), through a
hardened XML layer (:mod:`.safe_xml`); the file's extra data is a
:class:`~kronlag.model.robot_formats.description.RobotDescription` (``system.robot``)."""

from .description import RobotDescription, RobotFileWarning, RobotJoint, Visual
from .mjcf import load_mjcf
from .urdf import load_urdf

__all__ = ["load_urdf", "load_mjcf", "RobotDescription", "RobotFileWarning", "RobotJoint", "Visual"]
