"""The kernels of a system's limits (:meth:`kronlag.System.add_limit`): the gaps ``g(q)``, their
Jacobian ``J = dg/dq``, the velocity term ``gamma = (dJ/dq qd) qd`` of the gap acceleration
``gdd = J qdd + gamma`` and the restitution coefficients, generated once per system.

Python callables serve the impacts and the Python-driven integrators; the gaps are also printed as
C (``void kronlag_limit_gaps(const double *q, const double *p, double *g)``) and compiled, for the
root functions of the compiled integrators (``simulation/c/cvode.c``, ``index3.c``).
"""

from __future__ import annotations

import ctypes
import weakref
from functools import cached_property

import numpy as np
import sympy as sp

from .codegen.build import load_shared_library

__all__ = ["LimitKernels", "limit_kernels"]


class LimitKernels:
    """The limit sides of ``system`` (every bound of every limit, lower first) and their kernels.

    The parameter vector is the model's (``NumericModel.parameter_vector``, the order of
    ``system.parameters``).
    """

    def __init__(self, system):
        self.sides = tuple(side for limit in system.limits for side in limit.sides)
        self.names = tuple(side.name for side in self.sides)
        q, qd, p = list(system.coordinates), list(system.speeds), list(system.parameters)
        self._symbols = (q, p)
        self.gaps = sp.Matrix(len(self.sides), 1, [side.gap for side in self.sides])  # (0, 1) without limits
        jacobian = self.gaps.jacobian(q)
        velocity = jacobian * sp.Matrix(qd)
        gamma = velocity.jacobian(q) * sp.Matrix(qd)
        restitution = sp.Matrix(len(self.sides), 1, [side.restitution for side in self.sides])
        bounds = sp.Matrix(len(self.sides), 1, [side.bound for side in self.sides])
        self._python = sp.lambdify((q, qd, p), (self.gaps, jacobian, gamma, restitution, bounds), modules="numpy",
                                   cse=True, dummify=True)
        self._gaps_only = sp.lambdify((q, p), self.gaps, modules="numpy", cse=True, dummify=True)

    def __len__(self) -> int:
        return len(self.sides)

    def gap(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``g(q)``, shape (n,)."""
        return np.asarray(self._gaps_only(q, p), dtype=float).reshape(-1)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
        """``gap`` (n,), ``J`` (n, m), ``gamma`` (n,), ``restitution`` (n,) and ``bound`` (n,) at ``(q, qd)``."""
        n, m = len(self.sides), len(q)
        gaps, jacobian, gamma, restitution, bounds = self._python(q, qd, p)
        return {"gap": np.asarray(gaps, dtype=float).reshape(n), "J": np.asarray(jacobian, dtype=float).reshape(n, m),
                "gamma": np.asarray(gamma, dtype=float).reshape(n),
                "restitution": np.asarray(restitution, dtype=float).reshape(n),
                "bound": np.asarray(bounds, dtype=float).reshape(n)}

    @cached_property
    def c_source(self) -> str:
        """``kronlag_limit_gaps(q, p, g)`` as C (common subexpressions shared)."""
        q, p = self._symbols
        # symbols printed as array entries (names that are no identifier cannot clash with the user's)
        names = ({symbol: sp.Symbol(f"q[{i}]") for i, symbol in enumerate(q)}
                 | {symbol: sp.Symbol(f"p[{i}]") for i, symbol in enumerate(p)})
        temporaries, (reduced,) = sp.cse([self.gaps.xreplace(names)], symbols=sp.numbered_symbols("kl_t"))
        lines = ["#include <math.h>",
                 "void kronlag_limit_gaps(const double *q, const double *p, double *g)", "{"]
        lines += [f"    const double {symbol} = {sp.ccode(value)};" for symbol, value in temporaries]
        lines += [f"    g[{i}] = {sp.ccode(value)};" for i, value in enumerate(reduced)]
        return "\n".join(lines + ["}", ""])

    @cached_property
    def c_address(self) -> int:
        """The address of the compiled ``kronlag_limit_gaps`` (the library stays loaded with this object)."""
        self._library = load_shared_library(self.c_source)
        address = ctypes.cast(self._library.kronlag_limit_gaps, ctypes.c_void_p).value
        assert address is not None  # a symbol the library exports is never at NULL
        return address


#: The kernels per system (shared by every model derived from it and their parameter variants).
_KERNELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def limit_kernels(system) -> LimitKernels:
    """The :class:`LimitKernels` of ``system`` (built on first use)."""
    kernels = _KERNELS.get(system)
    if kernels is None:
        kernels = _KERNELS[system] = LimitKernels(system)
    return kernels
