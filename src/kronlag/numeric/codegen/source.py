"""The expressions of an :class:`~kronlag.symbolic.equations.Equations` object, prepared once for
both backends: the kernels of :data:`~kronlag.numeric.codegen.layouts.LAYOUTS`, of every matrix of the
catalogue (:mod:`kronlag.symbolic.matrices`) and of further expressions (points, reactions)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import symengine as se
import sympy as sp

from ...core.kernels import Block, ExpressionConverter, Kernel, cse_kernel, expression_kernel, input_renames
from ...symbolic import matrices
from .layouts import LAYOUTS
from .recursive import RECURSIVE_KERNELS, recursive_kernel
from .recursive_tangent import recursive_tangent_kernel

if TYPE_CHECKING:
    from ...symbolic.equations import Equations

__all__ = ["KernelSource"]

#: Kernels computed here rather than read off the equations.
_COMPUTED = frozenset({"potential_energy", "h", "K", "D"})


class KernelSource:
    """The expressions of an :class:`Equations` object, prepared for code generation.

    Shared by both backends.  :meth:`kernel` returns a :class:`~kronlag.core.kernels.Kernel` for a
    kernel of :data:`LAYOUTS` (``"dynamics"``, ``"tangent"``) or a matrix of the catalogue
    :data:`kronlag.symbolic.matrices.MATRICES`; :meth:`expression_kernel` for further expressions.
    The inputs are renamed ``t``, ``q[i]``, ``qd[i]`` and ``p[i]`` (the parameters, then any extra
    inputs of an expression kernel).

    Parameters
    ----------
    equations : Equations
    """

    def __init__(self, equations: Equations):
        self.equations = equations
        self.m = equations.shape[0]
        renames = input_renames(self._inputs())
        self.convert = ExpressionConverter(renames)
        self.q = [renames[symbol] for symbol in equations.coordinates]
        self.qd = [renames[symbol] for symbol in equations.speeds]
        self._cache: dict[str, list[list[se.Basic]]] = {}

    # -- matrices as nested lists of SymEngine expressions --------------------

    def matrix(self, name: str) -> list[list[se.Basic]]:
        """Matrix ``name`` as rows of SymEngine expressions (vectors as (n, 1))."""
        if name not in self._cache:
            self._cache[name] = self._compute(name)
        return self._cache[name]

    def _compute(self, name: str) -> list[list[se.Basic]]:
        eq = self.equations
        if name not in matrices.MATRICES:
            raise KeyError(name)
        native = eq.symengine(name) if name != "h" else None
        if native is not None:  # the derivation's own SymEngine form: no round trip through SymPy
            return self.convert.native_matrix(native, name)
        if name not in _COMPUTED:
            return self.convert.matrix(getattr(eq, name), name)
        if name == "potential_energy":
            return [[self.convert.entry(sp.sympify(eq.potential_energy), "potential energy")]]
        if name == "h":
            return [[f[0] - c[0] - g[0]] for f, c, g in
                    zip(self.matrix("f_Q"), self.matrix("Cqd"), self.matrix("g"))]
        variables = self.q if name == "K" else self.qd
        return [[se.diff(entry, variable) for variable in variables] for entry in self._dynamic_residual()]

    def _dynamic_residual(self) -> list[se.Basic]:
        """``e = M a + C qd + g - f_Q + Phi_q^T nu + A^T mu`` with the accelerations ``a`` and the
        multipliers ``nu``, ``mu`` read from ``p`` after the parameters: ``p[P + i]`` is ``a_i``,
        ``p[P + m + j]`` is ``nu_j``, ``p[P + m + r + k]`` is ``mu_k`` (the "tangent" kernel)."""
        m, r, s = self.equations.shape
        extra = [se.Symbol(f"p[{len(self.equations.parameters) + i}]") for i in range(m + r + s)]
        a, nu, mu = extra[:m], extra[m:m + r], extra[m + r:]
        M, h, Phi_q, A = (self.matrix(name) for name in ("M", "h", "Phi_q", "A"))
        return [se.Add(*(M[i][j] * a[j] for j in range(m)), -h[i][0],
                       *(Phi_q[k][i] * nu[k] for k in range(r)), *(A[k][i] * mu[k] for k in range(s)))
                for i in range(m)]

    # -- kernels -------------------------------------------------------------------

    @property
    def has_friction(self) -> bool:
        """Some joint has friction: the ``"friction"`` kernel (its records) joins the dynamics library."""
        return any(joint.friction is not None for joint in self.equations.system.joints)

    def kernel(self, name: str) -> Kernel:
        """The kernel ``name`` with common subexpressions eliminated (``symengine.cse``)."""
        if name == "friction":
            from ..friction import friction_kernel_matrices

            return self.expression_kernel(name, friction_kernel_matrices(self.equations.system))
        names = LAYOUTS.get(name, (name,))
        blocks = tuple(Block(block, _rows_and_columns(block, self.equations.shape)) for block in names)
        if name in RECURSIVE_KERNELS or name == "tangent":  # a tree's by recursive algorithms (None: not a tree)
            recursive = recursive_kernel(self, name, blocks) if name != "tangent" else recursive_tangent_kernel(
                self, blocks)
            if recursive is not None:
                return recursive
        return cse_kernel(name, blocks, [self.matrix(block) for block in names], self.convert.constants)

    def _inputs(self, extra: Sequence[sp.Symbol] = ()) -> list[tuple[str, object]]:
        """The inputs of every kernel, ``(t, q, qd, p)``; ``extra`` symbols are read from ``p`` after
        the parameters."""
        eq = self.equations
        return [("t", eq.time), ("q", eq.coordinates), ("qd", eq.speeds), ("p", (*eq.parameters, *extra))]

    def expression_kernel(self, name: str, expressions: Mapping[str, sp.MatrixBase],
                          extra: Sequence[sp.Symbol] = ()) -> Kernel:
        """A kernel of further expressions of ``(t, q, qd, parameters, extra)`` (body points, joint
        reactions, the Jacobians of a linearization), one block per entry of ``expressions``."""
        return expression_kernel(expressions, self._inputs(extra), name=name)


def _rows_and_columns(name: str, shape: tuple[int, int, int]) -> tuple[int, int]:
    """The (rows, columns) of catalogue matrix ``name`` (a vector is (n, 1))."""
    numpy_shape = matrices.shape(name, *shape)
    return (numpy_shape[0], numpy_shape[1] if len(numpy_shape) == 2 else 1)
