"""Code generation for the numeric model: SymPy matrices -> NumPy or C kernels.

Every kernel evaluates a few matrices of an :class:`~kronlag.equations.Equations`
object at a state ``(t, q, qd, p)`` (``p``: the parameters in the order of
``Equations.parameters``) and writes their entries, row-major and one block
after the other, into a flat output.  The expressions are prepared once, for
both backends (:class:`KernelSource`): SymPy -> SymEngine (memoized, so shared
subexpressions are converted once), common-subexpression elimination with
``symengine.cse``, inputs renamed to ``t``, ``q[i]``, ``qd[i]``, ``p[i]``.
The two backends only print the result:

* ``"python"`` (:class:`PythonLibrary`): Python functions (our own generated
  source, compiled with :func:`compile`) run on floats with :mod:`math` for one
  state, on NumPy arrays for a batch of states; no compiler needed;
* ``"c"`` (:class:`CLibrary`): C compiled with the machine's C compiler
  (the solver at ``-O3``, the kernels at ``-O2``, long ones at ``-O1``; see
  :func:`compile_shared_library`) into a shared library, cached on disk under ``$KRONLAG_CACHE`` or
  ``~/.cache/kronlag`` (a private directory; keyed by a hash of the source and
  the flags, content hash checked before loading), loaded with :mod:`ctypes`
  and called through the fixed call layer ``kronlag._call`` built at install
  time (ctypes when it is missing).  Large kernels are split into functions of
  :data:`C_CHUNK` statements (compilers are superlinear in the size of a
  function) and the source is compiled in parallel parts.

Both implement :class:`KernelLibrary`; :data:`BACKENDS` maps the backend names
to them.  Numbers reach the code as exact small integers and fractions or as
correctly rounded floating-point literals (see :class:`_SymengineConverter`).

The ``"dynamics"`` kernel holds everything forward dynamics needs, with one
common-subexpression elimination over all of it::

    M (m, m),  h = f_Q - C qd - g (m,),  Phi (r,),  Phi_q (r, m),  Phi_t (r,),
    gamma (r,),  A (s, m),  b (s,),  gamma_nh (s,)

with ``gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt`` and
``gamma_nh = -(dA/dt) qd - db/dt``, the time derivatives taken by Theorem 1
(``dX/dt = dX/dq (I ⊗ qd) + dX/dt|_q``, written as the sparse sum
``sum_k dX/dq_k qd_k``; the partials in ``t`` are nonzero for drives only).
The C library of the dynamics kernel also contains the solver of the augmented
system (``kronlag_forward_dynamics``, ``src/kronlag/c/augmented.c``).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import math
import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
import symengine as se
import sympy as sp

from .tolerances import RANK_RTOL, c_macros

if TYPE_CHECKING:
    from .equations import Equations

from .system import ModelError

__all__ = [
    "Block",
    "Kernel",
    "KernelSource",
    "KernelLibrary",
    "PythonLibrary",
    "CLibrary",
    "BACKENDS",
    "FAST_CALL",
    "ACCESSOR_KERNELS",
    "LAYOUTS",
    "layout",
    "layout_macros",
    "c_compiler",
    "cache_directory",
    "CompilerError",
]

#: The blocks of the kernels read by the C solvers and integrators, in output order:
#: ``(name, rows, columns)`` with the dimensions named ``"m"``, ``"r"``, ``"s"`` or 1.  Both the
#: Python side (:func:`layout`, ``NumericModel.dynamics_terms``) and the C side (offset macros
#: ``KRONLAG_<KERNEL>_<BLOCK>``, :func:`layout_macros`) derive their offsets from this table.
#:
#: ``"dynamics"``: ``h = f_Q - C qd - g``, ``Phi_t = dPhi/dt`` (drives), ``gamma = -d(Phi_q qd + Phi_t)/dt``
#: and ``gamma_nh = -d(A qd + b)/dt`` at fixed qd, so that ``[Phi_q; A] qdd = [gamma; gamma_nh]``.
#: ``"tangent"``: the derivatives of the dynamic residual
#: ``e = M a + C qd + g - f_Q + Phi_q^T nu + A^T mu`` at given accelerations ``a`` and
#: multipliers ``nu``, ``mu`` (inputs appended to ``p``): ``K = de/dq`` (stiffness, including
#: the multiplier term ``d(Phi_q^T nu)/dq``) and ``D = de/dqd`` (damping and gyroscopic terms).
LAYOUTS: dict[str, tuple[tuple[str, str, str | int], ...]] = {
    "dynamics": (("M", "m", "m"), ("h", "m", 1), ("Phi", "r", 1), ("Phi_q", "r", "m"), ("Phi_t", "r", 1),
                 ("gamma", "r", 1), ("A", "s", "m"), ("b", "s", 1), ("gamma_nh", "s", 1)),
    "tangent": (("K", "m", "m"), ("D", "m", "m")),
}


#: The matrices of :class:`kronlag.Equations` that kernels evaluate as they are.
_EQUATIONS_MATRICES = frozenset(("M", "C", "Cqd", "C_christoffel", "g", "Phi", "Phi_q", "Phi_t", "A", "b", "f_Q",
                                 "gamma", "gamma_nh"))


def layout(kernel: str, m: int, r: int, s: int) -> tuple[tuple[str, int, tuple[int, ...]], ...]:
    """``(block, offset, shape)`` of every block of ``kernel`` (see :data:`LAYOUTS`); vectors have
    shape ``(n,)``, matrices ``(rows, columns)``."""
    dimensions = {"m": m, "r": r, "s": s, 1: 1}
    result, offset = [], 0
    for name, rows, columns in LAYOUTS[kernel]:
        shape = (dimensions[rows],) if columns == 1 else (dimensions[rows], dimensions[columns])
        result.append((name, offset, shape))
        offset += math.prod(shape)
    return tuple(result)


def layout_macros(kernel: str, m: int, r: int, s: int) -> str:
    """``#define KRONLAG_<KERNEL>_<BLOCK> offset`` for every block and ``KRONLAG_<KERNEL>_SIZE``."""
    blocks = layout(kernel, m, r, s)
    prefix = f"KRONLAG_{kernel.upper()}"
    lines = [f"#define {prefix}_{name.upper()} {offset}" for name, offset, _ in blocks]
    name, offset, shape = blocks[-1]
    lines.append(f"#define {prefix}_SIZE {offset + math.prod(shape)}")
    return "\n".join(lines) + "\n"


#: C sources shipped with kronlag (``src/kronlag/c``), appended to the generated kernels.
C_DIRECTORY = Path(__file__).with_name("c")


def c_file(name: str) -> str:
    """The text of ``src/kronlag/c/<name>``."""
    return (C_DIRECTORY / name).read_text()


def solver_header(m: int, r: int, s: int, rank_rtol: float) -> str:
    """The macros the C solvers and integrators read: dimensions, block offsets
    (:func:`layout_macros`) and the numerical policy (:func:`kronlag.tolerances.c_macros`)."""
    return (f"#define KRONLAG_M {m}\n#define KRONLAG_R {r}\n#define KRONLAG_S {s}\n#define KRONLAG_K {r + s}\n"
            + layout_macros("dynamics", m, r, s) + layout_macros("tangent", m, r, s) + c_macros(rank_rtol))


#: Kernels that evaluate one public matrix each (``NumericModel.M`` etc.), compiled together.
#: ``"C"``, ``"Cqd"`` and ``"C_christoffel"`` are kernels too (see ``NumericModel`` for how
#: they are grouped into libraries).
ACCESSOR_KERNELS = ("M", "g", "Phi", "Phi_q", "Phi_t", "A", "b", "f_Q", "gamma", "gamma_nh", "potential_energy")

_CFLAGS = ("-fno-math-errno", "-fPIC", "-pthread")
#: Optimization level of the hand-written C (solvers, integrators, batch loops) and of small kernels.
_OPTIMIZATION = "-O2"
#: Part 0 of a library compiled in parts, the solver: -O3 vectorizes its loops of unknown length,
#: KRONLAG_WIDE_LOOPS adds AVX2 clones of them (``src/kronlag/c/linalg.c``); closed_chain(40): 10.4 us
#: at -O2, 6.7 us so.
_SOLVER_FLAGS = ("-O3", "-DKRONLAG_WIDE_LOOPS")
#: Sources longer than this (characters) compile their kernel chunks with :data:`_LARGE_KERNEL_OPTIMIZATION`:
#: on straight-line generated code GCC's -O2 takes 1.6 times as long as -O1 and buys nothing
#: (closed_chain(30, "relative"): 13 s against 8 s, the kernel 15.5 us either way).
C_LARGE_SOURCE = 100_000
_LARGE_KERNEL_OPTIMIZATION = "-O1"


@dataclass(frozen=True)
class Block:
    """One output matrix of a kernel: its name and shape (a vector has ``(n, 1)``)."""

    name: str
    shape: tuple[int, int]

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


@dataclass(frozen=True)
class Kernel:
    """A kernel after common-subexpression elimination, ready to print.

    ``temporaries`` are ``(symbol, expression)`` pairs in evaluation order;
    ``outputs`` are the entries of all ``blocks``, row-major, concatenated;
    ``constants`` maps the placeholder symbols ``K<i>`` standing for numbers
    that are not small exact integers or fractions to their double values
    (printed as correctly rounded floating-point literals, see :func:`literal`).
    """

    name: str
    blocks: tuple[Block, ...]
    temporaries: tuple[tuple[se.Symbol, se.Basic], ...]
    outputs: tuple[se.Basic, ...]
    constants: dict[str, float] = field(default_factory=dict)

    @property
    def size(self) -> int:
        return sum(block.size for block in self.blocks)


#: Integers and the numerators and denominators of fractions up to this size are exact doubles:
#: they stay exact in SymEngine and print as C/Python numbers that the compiler reads exactly.
_EXACT_LIMIT = 2**53

_PLACEHOLDER = re.compile(r"\bK\d+\b")


def literal(value: float) -> str:
    """``value`` as a floating-point literal read back exactly (shortest round trip), parenthesized if negative."""
    text = repr(float(value))
    return f"({text})" if value < 0 else text


class _SymengineConverter:
    """SymPy -> SymEngine, memoized; inputs renamed to ``t``, ``q[i]``, ``qd[i]``, ``p[i]``.

    Numbers: integers and fractions whose parts are at most 2**53 stay exact
    (they print as ``3`` or ``1.0/3.0``, exact doubles divided once, so correctly
    rounded); floats become such fractions when they can.  Every other real
    number (``10**20``, ``2**64``, ``1e-300``, ``1/3`` of huge parts) becomes a
    placeholder symbol ``K<i>`` whose value, ``float(number)`` (correctly
    rounded), is kept in :attr:`constants` and printed as a literal: an integer
    literal never reaches C, where a large one would overflow.  Complex and
    non-finite numbers are a :class:`~kronlag.system.ModelError`.
    """

    def __init__(self, renames: dict[sp.Symbol, se.Symbol]):
        self.memo: dict = dict(renames)
        self.constants: dict[str, float] = {}
        self._placeholders: dict[float, se.Symbol] = {}

    def __call__(self, expr: sp.Basic) -> se.Basic:
        result = self.memo.get(expr)
        if result is None:
            result = self._build(expr)
            self.memo[expr] = result
        return result

    def _build(self, expr: sp.Basic) -> se.Basic:
        if expr.is_Number or expr in (sp.I, sp.zoo):
            return self._number(expr)
        if isinstance(expr, sp.Symbol):
            raise ValueError(f"symbol {expr} is neither a coordinate, a speed, a parameter nor t")
        if not expr.args:
            return se.sympify(expr)
        args = [self(arg) for arg in expr.args]
        if expr.is_Add:
            return se.Add(*args)
        if expr.is_Mul:
            return se.Mul(*args)
        if expr.is_Pow:
            return se.Pow(*args)
        function = getattr(se, type(expr).__name__, None)
        if function is None:
            raise NotImplementedError(f"cannot generate code for {type(expr).__name__}: {expr}")
        return function(*args)

    def _number(self, number: sp.Basic) -> se.Basic:
        if number.is_extended_real is False or number is sp.zoo:
            raise ModelError(f"the complex constant {number} has no numeric value in real arithmetic")
        if not number.is_finite:
            raise ModelError(f"the non-finite constant {number} has no numeric value")
        if number.is_Float:
            value = float(number)
            if not math.isfinite(value):
                raise ModelError(f"the constant {number} overflows a double")
            number = sp.Rational(*value.as_integer_ratio())
        if max(abs(number.p), number.q) <= _EXACT_LIMIT:
            return se.Rational(int(number.p), int(number.q))
        value = float(number)  # correctly rounded: SymPy divides Python integers
        if not math.isfinite(value):
            raise ModelError(f"the constant {number} overflows a double")
        symbol = self._placeholders.get(value)
        if symbol is None:
            symbol = self._placeholders[value] = se.Symbol(f"K{len(self._placeholders)}")
            self.constants[symbol.name] = value
        return symbol

    def matrix(self, matrix: sp.MatrixBase, name: str = "matrix") -> list[list[se.Basic]]:
        """The entries of ``matrix`` (called ``name`` in errors) converted."""
        return [[self.entry(matrix[i, j], f"{name}[{i}, {j}]") for j in range(matrix.cols)]
                for i in range(matrix.rows)]

    def entry(self, expr: sp.Basic, where: str) -> se.Basic:
        """``expr`` converted; a :class:`ModelError` names ``where`` it stands."""
        try:
            return self(expr)
        except ModelError as error:
            raise ModelError(f"{where} = {expr}: {error}") from None


class KernelSource:
    """The expressions of an :class:`Equations` object, prepared for code generation.

    Shared by both backends.  :meth:`kernel` returns a :class:`Kernel` for a
    kernel of :data:`LAYOUTS` (``"dynamics"``, ``"tangent"``), one of
    :data:`ACCESSOR_KERNELS`, ``"C"``, ``"Cqd"`` (``C qd``) or ``"C_christoffel"``.

    Parameters
    ----------
    equations : Equations
    """

    def __init__(self, equations: Equations):
        self.equations = equations
        self.m = equations.shape[0]
        renames = {equations.time: se.Symbol("t")}
        for prefix, symbols in (("q", equations.coordinates), ("qd", equations.speeds),
                                ("p", equations.parameters)):
            renames.update({symbol: se.Symbol(f"{prefix}[{i}]") for i, symbol in enumerate(symbols)})
        self.convert = _SymengineConverter(renames)
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
        if name in _EQUATIONS_MATRICES:
            return self.convert.matrix(getattr(eq, name), name)
        if name == "potential_energy":
            return [[self.convert.entry(sp.sympify(eq.potential_energy), "potential energy")]]
        if name == "h":
            return [[f[0] - c[0] - g[0]] for f, c, g in
                    zip(self.matrix("f_Q"), self.matrix("Cqd"), self.matrix("g"))]
        if name in ("K", "D"):
            variables = self.q if name == "K" else self.qd
            return [[se.diff(entry, variable) for variable in variables] for entry in self._dynamic_residual()]
        raise KeyError(name)

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

    def kernel(self, name: str) -> Kernel:
        """The kernel ``name`` with common subexpressions eliminated (``symengine.cse``)."""
        names = tuple(block for block, _, _ in LAYOUTS[name]) if name in LAYOUTS else (name,)
        matrices = [self.matrix(block) for block in names]
        blocks = tuple(Block(block, (len(rows), len(rows[0]) if rows else self._columns(block)))
                       for block, rows in zip(names, matrices))
        return self._cse_kernel(name, blocks, matrices)

    def expression_kernel(self, name: str, matrices: Mapping[str, sp.MatrixBase]) -> Kernel:
        """A kernel of further expressions of ``(t, q, qd, parameters)`` (body points, joint
        reactions), one block per entry of ``matrices``."""
        blocks = tuple(Block(block, matrix.shape) for block, matrix in matrices.items())
        return self._cse_kernel(name, blocks, [self.convert.matrix(matrix) for matrix in matrices.values()])

    def _cse_kernel(self, name: str, blocks: tuple[Block, ...], matrices: list[list[list[se.Basic]]]) -> Kernel:
        flat = [entry for rows in matrices for row in rows for entry in row]
        temporaries, outputs = se.cse(flat) if flat else ([], [])
        return Kernel(name, blocks, tuple(temporaries), tuple(outputs), dict(self.convert.constants))

    def _columns(self, name: str) -> int:
        return self.m if name in ("M", "C", "C_christoffel", "Phi_q", "A", "K", "D") else 1


# -- Python backend ---------------------------------------------------------------------

def _maximum(*values):
    return functools.reduce(np.maximum, values)


def _minimum(*values):
    return functools.reduce(np.minimum, values)


#: The generated Python source runs in one of two namespaces: :mod:`math` on floats (one
#: state: fastest in pure Python), or NumPy on arrays (many states at once, vectorised).
_FUNCTION_NAMES = ("sin", "cos", "tan", "sinh", "cosh", "tanh", "exp", "log", "sqrt", "floor", "pi", "e")
_SCALAR_NAMESPACE: dict[str, object] = {name: getattr(math, name) for name in _FUNCTION_NAMES}
_SCALAR_NAMESPACE.update({name: getattr(math, name) for name in ("asin", "acos", "atan", "atan2", "asinh",
                                                                 "acosh", "atanh")},
                         E=math.e, ceiling=math.ceil, abs=abs, max=max, min=min,
                         sign=lambda x: math.copysign(1.0, x) if x else 0.0)
_ARRAY_NAMESPACE: dict[str, object] = {name: getattr(np, name) for name in _FUNCTION_NAMES}
_ARRAY_NAMESPACE.update(asin=np.arcsin, acos=np.arccos, atan=np.arctan, atan2=np.arctan2, asinh=np.arcsinh,
                        acosh=np.arccosh, atanh=np.arctanh, E=np.e, ceiling=np.ceil, abs=np.abs,
                        max=_maximum, min=_minimum, sign=np.sign)


def dynamics_shape(kernel: Kernel) -> tuple[int, int, int]:
    """``(m, r, s)`` from the blocks of the ``"dynamics"`` kernel (see :data:`LAYOUTS`)."""
    rows = {block.name: block.shape[0] for block in kernel.blocks}
    return rows["M"], rows["Phi"], rows["A"]


def python_source(kernel: Kernel) -> str:
    """Python source of ``kernel_<name>(t, q, qd, p) -> list``: ``q[i]``, ``qd[i]``, ``p[i]`` and ``t``
    may be floats (one state) or equally shaped arrays (many states, the NumPy namespace)."""
    def code(expr: se.Basic) -> str:
        return _PLACEHOLDER.sub(lambda match: literal(kernel.constants[match.group(0)]), str(expr))

    lines = [f"def kernel_{kernel.name}(t, q, qd, p):"]
    lines += [f"    {symbol} = {code(expr)}" for symbol, expr in kernel.temporaries]
    lines.append("    return [" + ", ".join(code(expr) for expr in kernel.outputs) + "]")
    return "\n".join(lines) + "\n"


def _vector(value, n: int, what: str) -> np.ndarray:
    """``value`` as a float64 vector of length ``n``; ValueError naming ``what`` otherwise."""
    vector = np.ascontiguousarray(value, dtype=float)
    if vector.shape != (n,):
        raise ValueError(f"{what} must have shape ({n},), got {vector.shape}")
    return vector


class KernelLibrary(Protocol):
    """What :class:`~kronlag.numeric.NumericModel` needs from a backend (see :data:`BACKENDS`).

    Inputs: ``t`` float, ``q``/``qd`` (m,), ``p`` (P,); batched: ``t`` (N,), ``q``/``qd`` (N, m),
    ``p`` (N, P) or (P,) for all states.
    """

    kernels: dict[str, Kernel]
    source: str

    def evaluator(self, name: str, shape: tuple[int, ...]) -> Callable[..., np.ndarray]:
        """``f(t, q, qd, p)`` -> the output of kernel ``name`` shaped ``shape`` (``qd`` may be None)."""

    def evaluate_batch(self, name: str, t: np.ndarray, q: np.ndarray, qd: np.ndarray | None,
                       p: np.ndarray) -> np.ndarray:
        """(N, size): the flat output of kernel ``name`` at every state."""

    def forward_dynamics_function(self) -> Callable[..., tuple]:
        """``f(t, q, qd, p, alpha, beta) -> (qdd, lam, mu, rank)``, all None but rank (-1) if singular."""

    def forward_dynamics_batch(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, p: np.ndarray,
                               alpha: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
        """``(out (N, m + r + s) = [qdd, lam, mu], rank (N,))``; rank -1 marks a singular state."""


class PythonLibrary:
    """Kernels as generated Python functions, no compiler needed (:class:`KernelLibrary`).

    One state runs on floats with :mod:`math`; a batch of states runs the same
    source on NumPy arrays, vectorised over the states.  Forward dynamics solves
    the output of the ``"dynamics"`` kernel with
    :func:`kronlag.numeric.solve_dynamics_terms`.
    """

    def __init__(self, kernels: Sequence[Kernel], *, m: int, n_parameters: int, rank_rtol: float = RANK_RTOL):
        self.kernels = {kernel.name: kernel for kernel in kernels}
        self.m, self.n_parameters, self.rank_rtol = m, n_parameters, rank_rtol
        self.source = "\n\n".join(python_source(kernel) for kernel in kernels)
        code = compile(self.source, "<kronlag generated>", "exec")
        unknown = sorted({name for const in code.co_consts if hasattr(const, "co_names")
                          for name in const.co_names} - set(_SCALAR_NAMESPACE))
        if unknown:
            raise NotImplementedError(f"no numeric implementation of the function(s) {', '.join(unknown)}")
        self.scalar: dict[str, Callable] = {}
        self.vectorised: dict[str, Callable] = {}
        for functions, namespace in ((self.scalar, _SCALAR_NAMESPACE), (self.vectorised, _ARRAY_NAMESPACE)):
            namespace = dict(namespace, __builtins__={})
            exec(code, namespace)  # our own generated source, never user text
            functions.update({name: namespace[f"kernel_{name}"] for name in self.kernels})

    def evaluator(self, name: str, shape: tuple[int, ...]) -> Callable[..., np.ndarray]:
        return functools.partial(self._evaluate, self.scalar[name], shape)

    def _evaluate(self, function: Callable, shape: tuple[int, ...], t: float, q, qd, p: np.ndarray) -> np.ndarray:
        q = _vector(q, self.m, "q").tolist()
        qd = [0.0] * self.m if qd is None else _vector(qd, self.m, "qd").tolist()
        return np.array(function(float(t), q, qd, p.tolist()), dtype=float).reshape(shape)

    def evaluate_batch(self, name: str, t: np.ndarray, q: np.ndarray, qd: np.ndarray | None,
                       p: np.ndarray) -> np.ndarray:
        n = len(q)
        qd = np.zeros_like(q) if qd is None else qd
        parameters = p.T if p.ndim == 2 else p
        values = self.vectorised[name](t, q.T, qd.T, parameters)
        out = np.empty((self.kernels[name].size, n))
        for row, value in zip(out, values):
            row[...] = value
        return out.T.copy()

    def forward_dynamics_function(self) -> Callable[..., tuple]:
        return self._forward_dynamics

    def _forward_dynamics(self, t: float, q, qd, p: np.ndarray, alpha: float, beta: float) -> tuple:
        from .numeric import solve_dynamics_terms  # numeric builds on this module

        qd = _vector(qd, self.m, "qd")
        kernel = self.kernels["dynamics"]
        return solve_dynamics_terms(kernel, self._evaluate(self.scalar[kernel.name], (kernel.size,), t, q, qd, p),
                                    qd, alpha, beta, rank_rtol=self.rank_rtol)

    def forward_dynamics_batch(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, p: np.ndarray,
                               alpha: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
        from .numeric import solve_dynamics_terms  # numeric builds on this module

        kernel = self.kernels["dynamics"]
        terms = self.evaluate_batch(kernel.name, t, q, qd, p)
        out = np.full((len(q), sum(dynamics_shape(kernel))), np.nan)
        ranks = np.empty(len(q), dtype=np.int32)
        for i, (row, velocity) in enumerate(zip(terms, qd)):
            qdd, lam, mu, ranks[i] = solve_dynamics_terms(kernel, row, velocity, alpha, beta, rank_rtol=self.rank_rtol)
            if ranks[i] >= 0:
                out[i] = np.concatenate([qdd, lam, mu])
        return out, ranks


# -- C backend ----------------------------------------------------------------------------

def c_compiler() -> str | None:
    """Path of the C compiler (``$CC``, else ``gcc``, else ``cc``), or None."""
    for candidate in (os.environ.get("CC"), "gcc", "cc"):
        if candidate and shutil.which(candidate):
            return shutil.which(candidate)
    return None


class CompilerError(RuntimeError):
    """The C compiler is missing or failed on the generated code (the message has its output)."""


def cache_directory() -> Path:
    """Where compiled libraries are cached: ``$KRONLAG_CACHE`` or ``~/.cache/kronlag``.

    :func:`compile_shared_library` creates it with mode 0700 and refuses to use it
    (PermissionError) unless it belongs to the user and no one else can write to it.
    """
    return Path(os.environ.get("KRONLAG_CACHE") or Path.home() / ".cache" / "kronlag")


def _private_cache_directory() -> Path:
    """:func:`cache_directory`, created 0700; PermissionError naming it unless it is the user's alone.

    A library there is loaded into the process: a directory another user can
    write to would let that user run code as whoever runs kronlag.
    """
    directory = cache_directory()
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    status = directory.stat()
    problems = []
    if not stat.S_ISDIR(status.st_mode):
        problems.append("not a directory")
    if hasattr(os, "geteuid") and status.st_uid != os.geteuid():
        problems.append(f"owned by uid {status.st_uid}, not by you (uid {os.geteuid()})")
    writers = [who for who, bit in (("its group", stat.S_IWGRP), ("others", stat.S_IWOTH)) if status.st_mode & bit]
    if writers:
        problems.append(f"writable by {' and '.join(writers)} (mode {stat.S_IMODE(status.st_mode):o})")
    for parent in directory.resolve().parents:  # anyone could rename the directory away and plant another
        mode = parent.stat().st_mode
        if mode & stat.S_IWOTH and not mode & stat.S_ISVTX:
            problems.append(f"inside {parent}, which everyone may write to "
                            f"(mode {stat.S_IMODE(mode):o}, no sticky bit)")
    if problems:
        raise PermissionError(
            f"refusing to use the kronlag cache directory {directory}: it is {'; '.join(problems)}. Compiled "
            "code loaded from there runs in this process, so it must be yours alone: run "
            f"`chmod 700 {directory}` if it is yours, or point $KRONLAG_CACHE to a private directory")
    return directory


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _digest_path(library: Path) -> Path:
    """The sidecar recording the SHA-256 of ``library``, written after the library."""
    return library.with_name(library.name + ".sha256")


def _intact(library: Path) -> bool:
    """Whether ``library`` exists with the content hash recorded when it was built."""
    try:
        return _digest_path(library).read_text().strip() == _digest(library)
    except OSError:
        return False


def _write_atomically(target: Path, data: bytes, work: Path) -> None:
    """Write ``data`` to ``target`` through a file in ``work`` renamed over it (readers never see a part)."""
    temporary = work / (target.name + ".part")
    temporary.write_bytes(data)
    os.replace(temporary, target)


_C_PREAMBLE = """\
/* Generated by kronlag: Lagrange's equations with multipliers in Kronecker matrix form,
 *   M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q,  f(q) = 0,  A(q) qd + b(q) = 0.
 * Self-contained: needs only <math.h>.  Compiles as one translation unit; kronlag itself
 * compiles it KRONLAG_PARTS times in parallel, with -DKRONLAG_PART=0, 1, ..., and links the parts:
 * part 0 the code outside the generated kernels' chunks (IN_PART(0)), the others chunks 1, 2, ... */
#include <math.h>
#include <string.h>
#ifdef KRONLAG_PART
#define KRONLAG_IN_PART(i) ((i) == 0 ? KRONLAG_PART == 0 : ((i) - 1) % (KRONLAG_PARTS - 1) + 1 == KRONLAG_PART)
#else
#define KRONLAG_IN_PART(i) 1
#endif
#if defined(__GNUC__)
#define KRONLAG_INTERNAL __attribute__((visibility("hidden"), noinline))
#else
#define KRONLAG_INTERNAL
#endif
"""

_TEMPORARY = re.compile(r"\bx\d+\b")

#: Statements per generated C function: compilers are superlinear in the size of a function.
C_CHUNK = 250


def c_kernel(kernel: Kernel, first_chunk: int) -> tuple[str, int]:
    """C code of ``void kronlag_<name>(t, q, qd, p, out)`` writing the kernel's flat output.

    The temporaries live in a workspace ``w``; the statements are split into
    functions of :data:`C_CHUNK` statements, chunk ``c`` guarded by
    ``KRONLAG_IN_PART(first_chunk + c)`` so that parts compile in parallel.
    Returns the code and the number of chunks.
    """
    index = {symbol.name: i for i, (symbol, _) in enumerate(kernel.temporaries)}

    def code(expr: se.Basic) -> str:
        # the temporaries of symengine.cse print as x<digits>, the constants as K<digits>;
        # no input is named so
        text = _TEMPORARY.sub(lambda match: f"w[{index[match.group(0)]}]", se.ccode(expr))
        return _PLACEHOLDER.sub(lambda match: literal(kernel.constants[match.group(0)]), text)

    statements = [f"{code(symbol)} = {code(expr)};" for symbol, expr in kernel.temporaries]
    statements += [f"out[{k}] = {code(expr)};" for k, expr in enumerate(kernel.outputs)]
    arguments = ("double t, const double *restrict q, const double *restrict qd, const double *restrict p, "
                 "double *restrict w, double *restrict out")
    names = [f"kronlag_{kernel.name}_{c}" for c in range(max(1, -(-len(statements) // C_CHUNK)))]
    lines = [f"KRONLAG_INTERNAL void {name}({arguments});" for name in names]
    for c, name in enumerate(names):
        lines += [f"#if KRONLAG_IN_PART({first_chunk + c})",
                  f"KRONLAG_INTERNAL void {name}({arguments})", "{",
                  "    (void)t; (void)q; (void)qd; (void)p; (void)w;"]
        lines += [f"    {statement}" for statement in statements[c * C_CHUNK:(c + 1) * C_CHUNK]]
        lines += ["}", "#endif"]
    lines += ["#if KRONLAG_IN_PART(0)",
              f"void kronlag_{kernel.name}(double t, const double *q, const double *qd, const double *p, double *out)",
              "{", f"    double w[{len(kernel.temporaries) + 1}];"]
    lines += [f"    {name}(t, q, qd, p, w, out);" for name in names]
    lines += ["}", "#endif"]
    return "\n".join(lines) + "\n", len(names)


def batch_threads() -> int:
    """Threads of a batched C call: ``$KRONLAG_THREADS``, else the CPUs this process may use."""
    configured = os.environ.get("KRONLAG_THREADS", "").strip()
    if configured.isdigit() and int(configured) > 0:
        return int(configured)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _fast_call_module():
    """The fixed call layer ``kronlag._call`` (built with the package), or None: then ctypes."""
    try:
        from . import _call
    except ImportError:
        return None
    return _call


#: ``kronlag._call`` when it was built at install time, else None (ctypes is used instead).
FAST_CALL = _fast_call_module()

_POINTER = ctypes.c_void_p
_LONG = ctypes.c_long


class CLibrary:
    """Kernels compiled with the C compiler into one shared library (:class:`KernelLibrary`).

    Single calls go through :data:`FAST_CALL` (arrays read in place), else through
    :mod:`ctypes` with per-call buffers (so both are safe from several threads);
    batched calls through :mod:`ctypes` (which releases the GIL) into
    ``src/kronlag/c/kernel_batch.c``.  With a ``"dynamics"`` kernel the library also holds the
    solver of the augmented system (``src/kronlag/c/augmented.c``).
    """

    def __init__(self, kernels: Sequence[Kernel], *, m: int, n_parameters: int, rank_rtol: float = RANK_RTOL):
        self.kernels = {kernel.name: kernel for kernel in kernels}
        self.m, self.n_parameters = m, n_parameters
        parts, chunks = [_C_PREAMBLE], 1
        for kernel in kernels:
            code, count = c_kernel(kernel, chunks)
            parts.append(code)
            chunks += count
        parts.append(c_file("kernel_batch.c"))
        solver = "dynamics" in self.kernels
        if solver:
            self.shape = dynamics_shape(self.kernels["dynamics"])
            m, r, s = self.shape
            parts.append("#if KRONLAG_IN_PART(0)\n" + solver_header(m, r, s, rank_rtol))
            parts.append(c_file("linalg.c") + c_file("augmented.c") + c_file("forward_dynamics_batch.c") + "#endif\n")
        self.source = "\n".join(parts)
        # part 0 (the solver) is small: one process per core for the kernel chunks besides it
        self.path = compile_shared_library(self.source, parts=1 + min(chunks - 1, os.cpu_count() or 1, 8))
        self.library = ctypes.CDLL(str(self.path))
        self.functions = {}
        for name in self.kernels:
            function = getattr(self.library, f"kronlag_{name}")
            function.argtypes = [ctypes.c_double, _POINTER, _POINTER, _POINTER, _POINTER]
            function.restype = None
            self.functions[name] = function
        self._kernel_batch = self.library.kronlag_kernel_batch
        self._kernel_batch.argtypes = [_POINTER, _LONG, _LONG, _LONG, _POINTER, _LONG, _POINTER, _POINTER, _LONG,
                                       _POINTER, _LONG, _POINTER, ctypes.c_int]
        self._kernel_batch.restype = None
        if solver:
            self._packed = self.library.kronlag_forward_dynamics_packed
            self._packed.argtypes = [_POINTER, _POINTER]
            self._packed.restype = ctypes.c_int
            self._forward_batch = self.library.kronlag_forward_dynamics_batch
            self._forward_batch.argtypes = [_LONG, _LONG, _POINTER, _LONG, _POINTER, _POINTER, _POINTER, _LONG,
                                            ctypes.c_double, ctypes.c_double, _POINTER, _POINTER, ctypes.c_int]
            self._forward_batch.restype = None

    @staticmethod
    def _address(function) -> int:
        return ctypes.cast(function, ctypes.c_void_p).value

    def evaluator(self, name: str, shape: tuple[int, ...]) -> Callable[..., np.ndarray]:
        if FAST_CALL is not None:
            columns = shape[1] if len(shape) == 2 else -1
            spec = (self._address(self.functions[name]), self.m, self.n_parameters, shape[0], columns)
            return functools.partial(FAST_CALL.evaluate, spec)
        return functools.partial(self._ctypes_evaluate, self.functions[name], shape)

    def _ctypes_evaluate(self, function, shape: tuple[int, ...], t: float, q, qd, p: np.ndarray) -> np.ndarray:
        q = _vector(q, self.m, "q")
        qd = np.zeros(self.m) if qd is None else _vector(qd, self.m, "qd")
        out = np.empty(shape)
        function(t, q.ctypes.data, qd.ctypes.data, _vector(p, self.n_parameters, "p").ctypes.data, out.ctypes.data)
        return out

    def evaluate_batch(self, name: str, t: np.ndarray, q: np.ndarray, qd: np.ndarray | None,
                       p: np.ndarray) -> np.ndarray:
        n, size = len(q), self.kernels[name].size
        out = np.empty((n, size))
        zero = np.zeros(self.m)
        self._kernel_batch(self._address(self.functions[name]), n, self.m, size, t.ctypes.data, t.ndim,
                           q.ctypes.data, zero.ctypes.data if qd is None else qd.ctypes.data,
                           0 if qd is None else self.m, p.ctypes.data, self.n_parameters if p.ndim == 2 else 0,
                           out.ctypes.data, batch_threads())
        return out

    def forward_dynamics_function(self) -> Callable[..., tuple]:
        if FAST_CALL is not None:
            return functools.partial(FAST_CALL.forward_dynamics,
                                     (self._address(self._packed), *self.shape, self.n_parameters))
        return self._ctypes_forward_dynamics

    def _ctypes_forward_dynamics(self, t: float, q, qd, p: np.ndarray, alpha: float, beta: float) -> tuple:
        m, r, s = self.shape
        inputs = np.concatenate([(t, alpha, beta), _vector(q, m, "q"), _vector(qd, m, "qd"),
                                 _vector(p, self.n_parameters, "p")])
        out = np.empty(m + r + s + 1)
        rank = self._packed(inputs.ctypes.data, out.ctypes.data)
        if rank < 0:
            return None, None, None, rank
        return out[:m], out[m:m + r], out[m + r:m + r + s], rank

    def forward_dynamics_batch(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, p: np.ndarray,
                               alpha: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
        n = len(q)
        out = np.empty((n, sum(self.shape)))
        ranks = np.empty(n, dtype=np.int32)
        self._forward_batch(n, self.n_parameters, t.ctypes.data, t.ndim, q.ctypes.data, qd.ctypes.data,
                            p.ctypes.data, self.n_parameters if p.ndim == 2 else 0, alpha, beta, out.ctypes.data,
                            ranks.ctypes.data, batch_threads())
        out[ranks < 0] = np.nan
        return out, ranks


#: The backends :class:`~kronlag.numeric.NumericModel` can use, by the name users pass.
BACKENDS: dict[str, type] = {"c": CLibrary, "python": PythonLibrary}


def compile_shared_library(source: str, *, parts: int = 1) -> Path:
    """Compile C ``source`` into a shared library in :func:`cache_directory` (reused when intact).

    With ``parts > 1`` the source is compiled ``parts`` times in parallel with
    ``-DKRONLAG_PART=i -DKRONLAG_PARTS=parts`` (each keeps the chunks
    ``KRONLAG_IN_PART`` selects) and the objects are linked; part 0, the
    hand-written C, with :data:`_SOLVER_FLAGS` (``-O3``), the others, the generated
    kernel chunks, at ``-O2``, or ``-O1`` when the source is longer than
    :data:`C_LARGE_SOURCE` characters.  A single part is compiled at ``-O2``.  The library is
    renamed into place, then its SHA-256 is written next to it
    (``<library>.sha256``); a library whose content does not match its recorded
    hash (truncated, replaced, or its build interrupted) is rebuilt, never returned.

    Raises
    ------
    CompilerError
        No compiler, or it failed.
    PermissionError
        The cache directory is not the user's alone (see :func:`cache_directory`).
    """
    compiler = c_compiler()
    if compiler is None:
        raise CompilerError("the C backend needs a C compiler (gcc or cc on PATH, or $CC); "
                            "use backend='python'")
    kernel_level = _LARGE_KERNEL_OPTIMIZATION if len(source) > C_LARGE_SOURCE else _OPTIMIZATION
    levels = [_SOLVER_FLAGS] + [(kernel_level,)] * (parts - 1) if parts > 1 else [(_OPTIMIZATION,)]
    key = hashlib.sha256("\0".join((compiler, *_CFLAGS, *map(" ".join, levels), source)).encode()).hexdigest()[:32]
    directory = _private_cache_directory()
    target = directory / f"kronlag_{key}.so"
    if _intact(target):
        return target
    with tempfile.TemporaryDirectory(dir=directory) as work:
        source_path = Path(work) / "model.c"
        source_path.write_text(source)
        objects = [Path(work) / f"part{i}.o" for i in range(parts)]
        defines = [[f"-DKRONLAG_PART={i}", f"-DKRONLAG_PARTS={parts}"] if parts > 1 else [] for i in range(parts)]
        try:
            processes = [subprocess.Popen([compiler, *level, *_CFLAGS, *define, "-c", "-o", str(obj), str(source_path)],
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                         for level, define, obj in zip(levels, defines, objects)]
        except OSError as error:
            raise CompilerError(f"cannot run the C compiler {compiler}: {error}") from None
        errors = [process.communicate()[1] for process in processes]
        failed = [f"exit status {process.returncode}\n{error[-4000:]}"
                  for process, error in zip(processes, errors) if process.returncode]
        built = Path(work) / "model.so"
        if not failed:
            undefined = ["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []
            link = subprocess.run([compiler, "-shared", "-pthread", *undefined, "-o", str(built), *map(str, objects),
                                   "-lm"], capture_output=True, text=True)
            failed = [f"exit status {link.returncode} (linking)\n{link.stderr[-4000:]}"] if link.returncode else []
        if failed or not built.is_file():
            output = failed[0] if failed else "no library was written"
            raise CompilerError(f"compiling the generated C code with {compiler} failed: {output}".rstrip())
        # the library first, its hash after: a library without a matching hash is never loaded
        digest = _digest(built)
        os.replace(built, target)
        _write_atomically(_digest_path(target), digest.encode(), Path(work))
    return target
