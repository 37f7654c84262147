"""Builds kronlag's fixed call layer, the C extension ``kronlag.numeric.codegen._call`` (everything else is
in pyproject.toml).

The extension is optional: where it cannot be built, kronlag calls its generated kernels through ctypes.
"""

import numpy
from setuptools import Extension, setup

setup(ext_modules=[Extension("kronlag.numeric.codegen._call", ["src/kronlag/numeric/codegen/_call.c"],
                             include_dirs=[numpy.get_include()], extra_compile_args=["-O2"], optional=True)])
