"""Types of ``kronlag.joints``, a former module path that :mod:`kronlag._legacy` keeps working
(``MOVED``): its names now live in the modules below (tests/test_packaging.py checks the two agree)."""

from kronlag.model.joints import *  # noqa: F403
from kronlag.model.free_bodies import *  # noqa: F403
