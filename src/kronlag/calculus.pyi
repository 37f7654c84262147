"""Types of ``kronlag.calculus``, a former module path that :mod:`kronlag._legacy` keeps working
(``MOVED``): its names now live in the modules below (tests/test_packaging.py checks the two agree)."""

from kronlag.symbolic.calculus import *  # noqa: F403
