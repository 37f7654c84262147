"""Robot description files read into a :class:`~kronlag.System`: URDF (:func:`load_urdf`), MJCF
(:func:`load_mjcf`) and SDF (:func:`load_sdf`), through a hardened XML layer (:mod:`.safe_xml`); the
file's extra data is a :class:`~kronlag.model.robot_formats.description.RobotDescription`
(``system.robot``).
:func:`load_robot` chooses the reader by the file's suffix (:data:`ROBOT_READERS`)."""

from pathlib import Path

from ...core.errors import InputError
from ..system import System
from .description import RobotDescription, RobotFileWarning, RobotJoint, Visual
from .mjcf import load_mjcf
from .sdf import load_sdf
from .urdf import load_urdf

__all__ = ["load_urdf", "load_mjcf", "load_sdf", "load_robot", "ROBOT_READERS", "RobotDescription", "RobotFileWarning",
           "RobotJoint", "Visual"]

#: The reader of each suffix (xacro files go to the URDF reader, which refuses them with advice).
ROBOT_READERS = {".urdf": load_urdf, ".xacro": load_urdf, ".xml": load_mjcf, ".mjcf": load_mjcf,
                 ".sdf": load_sdf}


def load_robot(path: str | Path, *, coordinates: str = "joint", floating_base: bool = False) -> System:
    """The robot file ``path`` read by the reader of its suffix (:data:`ROBOT_READERS`).

    ``coordinates`` (``"joint"`` or ``"absolute"``) as every reader takes it; ``floating_base=True``
    joins a URDF's root link to the world by the floating joint ``"root_joint"``
    (:func:`load_urdf`).  MJCF and SDF files say themselves whether the robot floats (a ``freejoint``;
    a model whose root link no joint fixes to the world), so there it is an InputError.
    """
    reader = ROBOT_READERS[Path(path).suffix.lower()]
    if not floating_base:
        return reader(path, coordinates=coordinates)
    if reader is not load_urdf:
        raise InputError(f"{path}: floating_base applies to URDF files only; an MJCF or SDF file says whether the "
                         "robot floats (a <freejoint>; a model whose root link no joint fixes to the world)")
    return load_urdf(path, coordinates=coordinates, floating_base=True)
