"""Types of ``kronlag.models``, a former module path that :mod:`kronlag._legacy` keeps working
(``MOVED``): its names now live in the modules below (tests/test_packaging.py checks the two agree)."""

from kronlag.model.builtin import *  # noqa: F403
