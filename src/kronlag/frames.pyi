"""Types of ``kronlag.frames``, a former module path that :mod:`kronlag._legacy` keeps working
(``MOVED``): its names now live in the modules below (tests/test_packaging.py checks the two agree)."""

from kronlag.model.frames import *  # noqa: F403
from kronlag.model.rotations import *  # noqa: F403
from kronlag.symbolic.kinematics import *  # noqa: F403
