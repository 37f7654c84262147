"""Code generation for the numeric model: SymPy matrices -> NumPy or C kernels.

Every kernel evaluates a few matrices of an :class:`~kronlag.equations.Equations`
object at a state ``(t, q, qd, p)`` (``p``: the parameters in the order of
``Equations.parameters``) and writes their entries, row-major and one block
after the other, into a flat output.  The expressions are prepared once, for
both backends (:class:`KernelSource`): SymPy -> SymEngine (memoized, so shared
subexpressions are converted once), common-subexpression elimination with
``symengine.cse``, inputs renamed to ``t``, ``q[i]``, ``qd[i]``, ``p[i]``.
The two backends only print the result:

* ``"numpy"``: a Python function (our own generated source, compiled with
  :func:`compile`) of plain floats using :mod:`math`; no compiler needed;
* ``"c"``: C compiled with the machine's C compiler (``-O2``) into a shared
  library, cached on disk under ``$KRONLAG_CACHE`` or ``~/.cache/kronlag``
  (keyed by a hash of the source and the flags) and called through
  :mod:`ctypes` (forward dynamics through a small CPython extension).  Large kernels are split into functions of
  :data:`C_CHUNK` statements (compilers are superlinear in the size of a
  function) and the source is compiled in parallel parts.

The ``"dynamics"`` kernel holds everything forward dynamics needs, with one
common-subexpression elimination over all of it::

    M (m, m),  h = f_Q - C qd - g (m,),  Phi (r,),  Phi_q (r, m),  gamma (r,),
    A (s, m),  b (s,),  gamma_nh (s,)

with ``gamma = -(dPhi_q/dt) qd`` and ``gamma_nh = -(dA/dt) qd - db/dt``, the
time derivatives taken by Theorem 1 (``dX/dt = dX/dq (I ⊗ qd)``, written as
the sparse sum ``sum_k dX/dq_k qd_k``; the constraints do not depend on ``t``).
The C library of the dynamics kernel also contains the solver of the augmented
system (``kronlag_forward_dynamics``, see :data:`C_SOLVER`).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib.machinery
import importlib.util
import math
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import symengine as se
import sympy as sp

if TYPE_CHECKING:
    from .equations import Equations

__all__ = [
    "Block",
    "Kernel",
    "KernelSource",
    "NumpyLibrary",
    "CLibrary",
    "ACCESSOR_KERNELS",
    "RANK_RTOL",
    "CHOLESKY_RTOL",
    "c_compiler",
    "cache_directory",
]

#: Relative tolerance of the rank decision on ``[Phi_q; A]``: a diagonal entry of R in the
#: pivoted QR (C) or a singular value (NumPy) ``<= RANK_RTOL`` times the largest counts as zero.
RANK_RTOL = 1e-10
#: A Cholesky pivot ``<= CHOLESKY_RTOL * max(diag)`` of ``Z^T M Z`` means M is not
#: positive definite on the constraint null space (a singular configuration).
CHOLESKY_RTOL = 1e-12

#: Kernels that evaluate one public matrix each (``NumericModel.M`` etc.), compiled together.
#: ``"C"``, ``"Cqd"`` and ``"C_christoffel"`` are kernels too, each compiled alone on first use:
#: they are by far the largest and the simulation does not need them.
ACCESSOR_KERNELS = ("M", "g", "Phi", "Phi_q", "A", "b", "f_Q", "gamma", "gamma_nh", "potential_energy")

_CFLAGS = ("-O2", "-fno-math-errno", "-fPIC")


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
    ``outputs`` are the entries of all ``blocks``, row-major, concatenated.
    """

    name: str
    blocks: tuple[Block, ...]
    temporaries: tuple[tuple[se.Symbol, se.Basic], ...]
    outputs: tuple[se.Basic, ...]

    @property
    def size(self) -> int:
        return sum(block.size for block in self.blocks)


class _SymengineConverter:
    """SymPy -> SymEngine, memoized; inputs renamed to ``t``, ``q[i]``, ``qd[i]``, ``p[i]``.

    Floats become exact rationals (SymEngine prints floats with 15 digits).
    """

    def __init__(self, renames: dict[sp.Symbol, se.Symbol]):
        self.memo: dict = dict(renames)

    def __call__(self, expr: sp.Basic) -> se.Basic:
        result = self.memo.get(expr)
        if result is None:
            result = self._build(expr)
            self.memo[expr] = result
        return result

    def _build(self, expr: sp.Basic) -> se.Basic:
        if isinstance(expr, sp.Float):
            return se.Rational(*(int(x) for x in float(expr).as_integer_ratio()))
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

    def matrix(self, matrix: sp.MatrixBase) -> list[list[se.Basic]]:
        return [[self(matrix[i, j]) for j in range(matrix.cols)] for i in range(matrix.rows)]


class KernelSource:
    """The expressions of an :class:`Equations` object, prepared for code generation.

    Shared by both backends.  :meth:`kernel` returns a :class:`Kernel` for
    ``"dynamics"``, one of :data:`ACCESSOR_KERNELS`, ``"C"``, ``"Cqd"`` (``C qd``)
    or ``"C_christoffel"``.

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
        if name in ("M", "C", "Cqd", "C_christoffel", "g", "Phi", "Phi_q", "A", "b", "f_Q", "gamma", "gamma_nh"):
            return self.convert.matrix(getattr(eq, name))
        if name == "potential_energy":
            return [[self.convert(sp.sympify(eq.potential_energy))]]
        if name == "h":
            return [[f[0] - c[0] - g[0]] for f, c, g in
                    zip(self.matrix("f_Q"), self.matrix("Cqd"), self.matrix("g"))]
        raise KeyError(name)

    # -- kernels -------------------------------------------------------------------

    def kernel(self, name: str) -> Kernel:
        """The kernel ``name`` with common subexpressions eliminated (``symengine.cse``)."""
        names = ("M", "h", "Phi", "Phi_q", "gamma", "A", "b", "gamma_nh") if name == "dynamics" else (name,)
        matrices = [self.matrix(block) for block in names]
        blocks = tuple(Block(block, (len(rows), len(rows[0]) if rows else self._columns(block)))
                       for block, rows in zip(names, matrices))
        return self._cse_kernel(name, blocks, matrices)

    def expression_kernel(self, name: str, matrices: Mapping[str, sp.MatrixBase]) -> Kernel:
        """A kernel of further expressions of ``(t, q, qd, parameters)`` (body points, joint
        reactions), one block per entry of ``matrices``."""
        blocks = tuple(Block(block, matrix.shape) for block, matrix in matrices.items())
        return self._cse_kernel(name, blocks, [self.convert.matrix(matrix) for matrix in matrices.values()])

    @staticmethod
    def _cse_kernel(name: str, blocks: tuple[Block, ...], matrices: list[list[list[se.Basic]]]) -> Kernel:
        flat = [entry for rows in matrices for row in rows for entry in row]
        temporaries, outputs = se.cse(flat) if flat else ([], [])
        return Kernel(name, blocks, tuple(temporaries), tuple(outputs))

    def _columns(self, name: str) -> int:
        return self.m if name in ("M", "C", "C_christoffel", "Phi_q", "A") else 1


# -- NumPy backend -----------------------------------------------------------------------

_PYTHON_NAMESPACE: dict[str, object] = {
    name: getattr(math, name) for name in (
        "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh",
        "acosh", "atanh", "exp", "log", "sqrt", "floor", "pi", "e")
}
_PYTHON_NAMESPACE.update(E=math.e, ceiling=math.ceil, sign=lambda x: math.copysign(1.0, x) if x else 0.0)


def python_source(kernel: Kernel) -> str:
    """Python source of ``kernel_<name>(t, q, qd, p) -> list[float]`` (q, qd, p: lists)."""
    lines = [f"def kernel_{kernel.name}(t, q, qd, p):"]
    lines += [f"    {symbol} = {expr}" for symbol, expr in kernel.temporaries]
    lines.append("    return [" + ", ".join(str(expr) for expr in kernel.outputs) + "]")
    return "\n".join(lines) + "\n"


class NumpyLibrary:
    """Kernels compiled to Python functions of floats.

    ``evaluate(name, t, q, qd, p)`` returns the flat float64 output of kernel ``name``.
    """

    def __init__(self, kernels: Sequence[Kernel]):
        self.kernels = {kernel.name: kernel for kernel in kernels}
        self.source = "\n\n".join(python_source(kernel) for kernel in kernels)
        namespace = dict(_PYTHON_NAMESPACE)
        code = compile(self.source, "<kronlag generated>", "exec")
        unknown = sorted({name for const in code.co_consts if hasattr(const, "co_names")
                          for name in const.co_names} - set(namespace) - {"abs", "max", "min"})
        if unknown:
            raise NotImplementedError(f"no numeric implementation of the function(s) {', '.join(unknown)}")
        exec(code, namespace)  # our own generated source, never user text
        self.functions: dict[str, Callable] = {name: namespace[f"kernel_{name}"] for name in self.kernels}

    def evaluate(self, name: str, t: float, q: np.ndarray, qd: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Flat output of kernel ``name`` (its blocks row-major, concatenated)."""
        values = self.functions[name](t, q.tolist(), qd.tolist(), p.tolist())
        return np.array(values, dtype=float)


# -- C backend ----------------------------------------------------------------------------

def c_compiler() -> str | None:
    """Path of the C compiler (``$CC``, else ``gcc``, else ``cc``), or None."""
    for candidate in (os.environ.get("CC"), "gcc", "cc"):
        if candidate and shutil.which(candidate):
            return shutil.which(candidate)
    return None


def cache_directory() -> Path:
    """Where compiled libraries are cached: ``$KRONLAG_CACHE`` or ``~/.cache/kronlag``."""
    return Path(os.environ.get("KRONLAG_CACHE") or Path.home() / ".cache" / "kronlag")


_C_PREAMBLE = """\
/* Generated by kronlag: Lagrange's equations with multipliers in Kronecker matrix form,
 *   M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q,  f(q) = 0,  A(q) qd + b(q) = 0.
 * Self-contained: needs only <math.h>.  Compiles as one translation unit; kronlag itself
 * compiles it KRONLAG_PARTS times in parallel, with -DKRONLAG_PART=0, 1, ..., and links the parts. */
#include <math.h>
#include <string.h>
#ifdef KRONLAG_PART
#define KRONLAG_IN_PART(i) ((i) % KRONLAG_PARTS == KRONLAG_PART)
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
        # the temporaries of symengine.cse print as x<digits>; no input is named so
        return _TEMPORARY.sub(lambda match: f"w[{index[match.group(0)]}]", se.ccode(expr))

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


#: The solver of the augmented system, appended to the C source of the dynamics
#: kernel (``KRONLAG_M``, ``KRONLAG_R``, ``KRONLAG_S`` defined before it).
#: Null-space method with a rank-revealing QR; see :func:`kronlag.numeric.solve_augmented`
#: for the algorithm (the NumPy backend's twin of ``kronlag_solve``).
C_SOLVER = r"""
#define KRONLAG_K (KRONLAG_R + KRONLAG_S)
#define KRONLAG_TERMS (KRONLAG_M * KRONLAG_M + KRONLAG_M + 2 * KRONLAG_R + (KRONLAG_R + KRONLAG_S) * KRONLAG_M \
                       + 2 * KRONLAG_S + 1)

/* Householder QR of the rows x cols matrix a (row-major, leading dimension lda), in place:
 * R in the upper triangle, reflector j (v_j[j] = 1) below the diagonal of column j, tau[j].
 * With perm != NULL, column pivoting by the largest remaining norm (a P = Q R). */
static void house_qr(double *a, int rows, int cols, int lda, int *perm, double *tau)
{
    int steps = rows < cols ? rows : cols;
    if (perm)
        for (int j = 0; j < cols; ++j) perm[j] = j;
    for (int j = 0; j < steps; ++j) {
        if (perm) {
            int best = j; double best_norm = -1.0;
            for (int c = j; c < cols; ++c) {
                double norm = 0.0;
                for (int i = j; i < rows; ++i) norm += a[i * lda + c] * a[i * lda + c];
                if (norm > best_norm) { best_norm = norm; best = c; }
            }
            if (best != j) {
                for (int i = 0; i < rows; ++i) {
                    double swap = a[i * lda + j]; a[i * lda + j] = a[i * lda + best]; a[i * lda + best] = swap;
                }
                int swap = perm[j]; perm[j] = perm[best]; perm[best] = swap;
            }
        }
        double alpha = a[j * lda + j], xnorm = 0.0;
        for (int i = j + 1; i < rows; ++i) xnorm += a[i * lda + j] * a[i * lda + j];
        if (xnorm == 0.0) { tau[j] = 0.0; continue; }
        double beta = -copysign(sqrt(alpha * alpha + xnorm), alpha);
        tau[j] = (beta - alpha) / beta;
        for (int i = j + 1; i < rows; ++i) a[i * lda + j] /= alpha - beta;
        a[j * lda + j] = beta;
        for (int c = j + 1; c < cols; ++c) {
            double w = a[j * lda + c];
            for (int i = j + 1; i < rows; ++i) w += a[i * lda + j] * a[i * lda + c];
            w *= tau[j];
            a[j * lda + c] -= w;
            for (int i = j + 1; i < rows; ++i) a[i * lda + c] -= w * a[i * lda + j];
        }
    }
}

/* x <- H_j x for the reflector stored in column j of a (rows x ., leading dimension lda). */
static void house_apply(const double *a, int rows, int lda, int j, double tau, double *x, int stride)
{
    if (tau == 0.0) return;
    double w = x[j * stride];
    for (int i = j + 1; i < rows; ++i) w += a[i * lda + j] * x[i * stride];
    w *= tau;
    x[j * stride] -= w;
    for (int i = j + 1; i < rows; ++i) x[i * stride] -= w * a[i * lda + j];
}

/* Solve [[M, G^T], [G, 0]] [qdd; nu] = [h; c] with G = [Phi_q; A] (K x m), rank-revealing.
 * terms: the output of kronlag_dynamics (M, h, Phi, Phi_q, gamma, A, b, gamma_nh).
 * Returns 0, or 1 when M is not positive definite on the null space of G. */
static int kronlag_solve(const double *terms, const double *qd, double alpha, double beta,
                         double *qdd, double *nu, int *rank)
{
    enum { m = KRONLAG_M, r = KRONLAG_R, s = KRONLAG_S, k = KRONLAG_K };
    const double *M = terms, *h = terms + m * m, *Phi = h + m, *Phi_q = Phi + r, *gamma = Phi_q + r * m;
    const double *A = gamma + r, *b = A + s * m, *gamma_nh = b + s;
    double X[m * (k + 1)], tau[k + 1], c[k + 1], B[m * m], y[m];
    int perm[k + 1];
    /* X = G^T (m x k), c = [gamma - 2 alpha Phi_q qd - beta^2 Phi; gamma_nh - alpha (A qd + b)] */
    for (int j = 0; j < k; ++j) {
        const double *row = j < r ? Phi_q + j * m : A + (j - r) * m;
        double velocity = 0.0;
        for (int i = 0; i < m; ++i) { X[i * k + j] = row[i]; velocity += row[i] * qd[i]; }
        c[j] = j < r ? gamma[j] - 2.0 * alpha * velocity - beta * beta * Phi[j]
                     : gamma_nh[j - r] - alpha * (velocity + b[j - r]);
    }
    house_qr(X, m, k, k, perm, tau);
    int rho = 0;
    int steps = m < k ? m : k;
    while (rho < steps && fabs(X[rho * k + rho]) > KRONLAG_RANK_RTOL * fabs(X[0])) ++rho;
    *rank = rho;
    /* B = Q^T M Q, y = Q^T h with Q = H_0 ... H_{rho-1}; Z = Q[:, rho:] spans the null space of G. */
    memcpy(B, M, sizeof B);
    memcpy(y, h, sizeof y);
    for (int j = 0; j < rho; ++j) {
        for (int col = 0; col < m; ++col) house_apply(X, m, k, j, tau[j], B + col, m);
        for (int row = 0; row < m; ++row) house_apply(X, m, k, j, tau[j], B + row * m, 1);
        house_apply(X, m, k, j, tau[j], y, 1);
    }
    /* R1^T = W T (second QR, K x rho), so that G = P R1^T Q1^T. Constraint part y1 = Q1^T qdd:
     * T y1 = W^T P^T c (least squares when redundant rows are inconsistent). */
    double W[(k + 1) * (k + 1)], wtau[k + 1], cp[k + 1];
    for (int i = 0; i < k; ++i) {
        cp[i] = c[perm[i]];
        for (int j = 0; j < rho; ++j) W[i * k + j] = i >= j ? X[j * k + i] : 0.0;
    }
    house_qr(W, k, rho, k, NULL, wtau);
    for (int j = 0; j < rho; ++j) house_apply(W, k, k, j, wtau[j], cp, 1);
    double qt[m];
    for (int i = rho - 1; i >= 0; --i) {
        double sum = cp[i];
        for (int j = i + 1; j < rho; ++j) sum -= W[i * k + j] * qt[j];
        qt[i] = sum / W[i * k + i];
    }
    /* Null-space part y2: (Z^T M Z) y2 = Z^T h - Z^T M Q1 y1, Cholesky (fails if singular). */
    int n = m - rho;
    double L[m * m], z[m];
    double largest = 0.0;
    for (int i = 0; i < n; ++i) if (B[(rho + i) * m + rho + i] > largest) largest = B[(rho + i) * m + rho + i];
    for (int i = 0; i < n; ++i) {
        double sum = y[rho + i];
        for (int j = 0; j < rho; ++j) sum -= B[(rho + i) * m + j] * qt[j];
        z[i] = sum;
        for (int j = 0; j <= i; ++j) {
            double entry = B[(rho + i) * m + rho + j];
            for (int l = 0; l < j; ++l) entry -= L[i * m + l] * L[j * m + l];
            if (i == j) {
                if (!(entry > KRONLAG_CHOLESKY_RTOL * largest)) return 1;
                L[i * m + i] = sqrt(entry);
            } else {
                L[i * m + j] = entry / L[j * m + j];
            }
        }
    }
    for (int i = 0; i < n; ++i) {
        for (int l = 0; l < i; ++l) z[i] -= L[i * m + l] * z[l];
        z[i] /= L[i * m + i];
    }
    for (int i = n - 1; i >= 0; --i) {
        for (int l = i + 1; l < n; ++l) z[i] -= L[l * m + i] * z[l];
        z[i] /= L[i * m + i];
    }
    for (int i = 0; i < n; ++i) qt[rho + i] = z[i];
    /* Multipliers, minimum norm: R1 P^T nu = Q1^T (h - M qdd) = y1 - B[:rho, :] qt,
     * R1 = T^T W^T, so P^T nu = W T^{-T} (Q1^T (h - M qdd)). */
    double a[k + 1];
    for (int i = 0; i < rho; ++i) {
        double sum = y[i];
        for (int j = 0; j < m; ++j) sum -= B[i * m + j] * qt[j];
        for (int j = 0; j < i; ++j) sum -= W[j * k + i] * a[j];
        a[i] = sum / W[i * k + i];
    }
    for (int i = rho; i < k; ++i) a[i] = 0.0;
    for (int j = rho - 1; j >= 0; --j) house_apply(W, k, k, j, wtau[j], a, 1);
    for (int i = 0; i < k; ++i) nu[perm[i]] = a[i];
    /* qdd = Q qt */
    for (int j = rho - 1; j >= 0; --j) house_apply(X, m, k, j, tau[j], qt, 1);
    memcpy(qdd, qt, sizeof qt);
    return 0;
}

/* Forward dynamics with multipliers (Baumgarte alpha, beta); 0 on success, 1 if singular. */
int kronlag_forward_dynamics(double t, const double *q, const double *qd, const double *p,
                             double alpha, double beta, double *qdd, double *lam, double *mu)
{
    double terms[KRONLAG_TERMS], nu[KRONLAG_K + 1];
    int rank;
    kronlag_dynamics(t, q, qd, p, terms);
    int status = kronlag_solve(terms, qd, alpha, beta, qdd, nu, &rank);
    for (int j = 0; j < KRONLAG_R; ++j) lam[j] = nu[j];
    for (int j = 0; j < KRONLAG_S; ++j) mu[j] = nu[KRONLAG_R + j];
    return status;
}

/* Entry point for Python: in = [t, alpha, beta, q (m), qd (m), p (P)], out = [qdd (m), lambda (r), mu (s)];
 * returns the rank of [Phi_q; A], or -1 when the configuration is singular. */
int kronlag_forward_dynamics_packed(const double *in, double *out)
{
    double terms[KRONLAG_TERMS];
    int rank;
    const double *q = in + 3, *qd = q + KRONLAG_M;
    kronlag_dynamics(in[0], q, qd, qd + KRONLAG_M, terms);
    return kronlag_solve(terms, qd, in[1], in[2], out, out + KRONLAG_M, &rank) ? -1 : rank;
}
"""


class CLibrary:
    """Kernels compiled with the C compiler into a shared library, loaded with :mod:`ctypes`.

    With ``solver=True`` the library also holds ``kronlag_forward_dynamics``
    (needs a ``"dynamics"`` kernel).  ``evaluate(name, t, q, qd, p)`` returns the
    flat float64 output of kernel ``name``.
    """

    def __init__(self, kernels: Sequence[Kernel], *, solver: bool = False):
        self.kernels = {kernel.name: kernel for kernel in kernels}
        parts, chunks = [_C_PREAMBLE], 1
        for kernel in kernels:
            code, count = c_kernel(kernel, chunks)
            parts.append(code)
            chunks += count
        if solver:
            dynamics = self.kernels["dynamics"]
            m, r, s = (dynamics.blocks[i].shape[0] for i in (0, 2, 6))
            parts.append(f"#if KRONLAG_IN_PART(0)\n#define KRONLAG_M {m}\n#define KRONLAG_R {r}\n"
                         f"#define KRONLAG_S {s}\n"
                         f"#define KRONLAG_RANK_RTOL {RANK_RTOL!r}\n#define KRONLAG_CHOLESKY_RTOL {CHOLESKY_RTOL!r}\n")
            parts.append(C_SOLVER + "#endif\n")
        self.source = "\n".join(parts)
        self.path = compile_shared_library(self.source, parts=min(chunks, os.cpu_count() or 1, 8))
        self.library = ctypes.CDLL(str(self.path))
        pointer = ctypes.c_void_p
        self.functions = {}
        for name in self.kernels:
            function = getattr(self.library, f"kronlag_{name}")
            function.argtypes = [ctypes.c_double, pointer, pointer, pointer, pointer]
            function.restype = None
            self.functions[name] = function
        if solver:
            packed = self.library.kronlag_forward_dynamics_packed
            packed.argtypes = [pointer, pointer]
            packed.restype = ctypes.c_int
            self.forward_dynamics_packed = packed
            self.shape = (m, r, s)

    def forward_dynamics_caller(self, inputs: np.ndarray) -> Callable:
        """``call(q, qd, t, alpha, beta) -> (qdd, lam, mu, rank)`` for ``kronlag_forward_dynamics_packed``.

        ``inputs`` is the packed input buffer ``[t, alpha, beta, q, qd, p]`` (the
        caller keeps ``p`` up to date; the call writes the rest); ``rank < 0``
        (and None for the arrays) means a singular configuration.  Through a
        small CPython extension (:func:`call_extension`) when it builds,
        else through :mod:`ctypes`.
        """
        address = ctypes.cast(self.forward_dynamics_packed, ctypes.c_void_p).value
        extension = call_extension()
        if extension is not None:
            return functools.partial(extension.call, (address, inputs.ctypes.data, *self.shape))
        out = np.zeros(sum(self.shape))
        return functools.partial(_ctypes_call, self.forward_dynamics_packed, inputs, out, self.shape[0],
                                 self.shape[1], (inputs.ctypes.data, out.ctypes.data))

    def evaluate(self, name: str, t: float, q: np.ndarray, qd: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Flat output of kernel ``name`` (its blocks row-major, concatenated)."""
        out = np.empty(self.kernels[name].size)
        arrays = [np.ascontiguousarray(x, dtype=float) for x in (q, qd, p)]
        self.functions[name](t, *(x.ctypes.data for x in arrays), out.ctypes.data)
        return out


def _ctypes_call(function, inputs: np.ndarray, out: np.ndarray, m: int, r: int, pointers: tuple[int, int],
                 q, qd, t: float, alpha: float, beta: float) -> tuple:
    """The :mod:`ctypes` twin of ``call`` in :data:`_CALL_EXTENSION`."""
    inputs[0] = t
    inputs[1] = alpha
    inputs[2] = beta
    inputs[3:3 + m] = q
    inputs[3 + m:3 + 2 * m] = qd
    rank = function(*pointers)
    if rank < 0:
        return None, None, None, rank
    values = out.copy()
    return values[:m], values[m:m + r], values[m + r:], rank


#: A CPython extension that calls ``kronlag_forward_dynamics_packed`` through its
#: address: ``call(spec, q, qd, t, alpha, beta) -> (qdd, lam, mu, rank)`` with
#: ``spec = (function address, input buffer address, m, r, s)``.  It saves the
#: microsecond that ctypes and the NumPy slicing cost per call.
_CALL_EXTENSION = r"""
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <string.h>

typedef int (*kronlag_packed)(const double *in, double *out);

static int read_vector(PyObject *object, double *target, Py_ssize_t n)
{
    PyArrayObject *array = (PyArrayObject *)PyArray_FROMANY(object, NPY_DOUBLE, 1, 1, NPY_ARRAY_IN_ARRAY);
    if (!array) return -1;
    int ok = PyArray_DIM(array, 0) == n;
    if (ok) memcpy(target, PyArray_DATA(array), n * sizeof(double));
    else PyErr_Format(PyExc_ValueError, "expected a vector of length %zd, got %zd", n,
                      (Py_ssize_t)PyArray_DIM(array, 0));
    Py_DECREF(array);
    return ok ? 0 : -1;
}

static PyObject *new_vector(const double *data, npy_intp n)
{
    PyObject *array = PyArray_SimpleNew(1, &n, NPY_DOUBLE);
    if (array) memcpy(PyArray_DATA((PyArrayObject *)array), data, n * sizeof(double));
    return array;
}

static PyObject *call(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 6 || !PyTuple_Check(args[0]) || PyTuple_GET_SIZE(args[0]) != 5) {
        PyErr_SetString(PyExc_TypeError, "call(spec, q, qd, t, alpha, beta)");
        return NULL;
    }
    kronlag_packed function = (kronlag_packed)PyLong_AsVoidPtr(PyTuple_GET_ITEM(args[0], 0));
    double *in = (double *)PyLong_AsVoidPtr(PyTuple_GET_ITEM(args[0], 1));
    Py_ssize_t m = PyLong_AsSsize_t(PyTuple_GET_ITEM(args[0], 2));
    Py_ssize_t r = PyLong_AsSsize_t(PyTuple_GET_ITEM(args[0], 3));
    Py_ssize_t s = PyLong_AsSsize_t(PyTuple_GET_ITEM(args[0], 4));
    double t = PyFloat_AsDouble(args[3]), alpha = PyFloat_AsDouble(args[4]), beta = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) return NULL;
    in[0] = t; in[1] = alpha; in[2] = beta;
    if (read_vector(args[1], in + 3, m) || read_vector(args[2], in + 3 + m, m)) return NULL;
    double *out = PyMem_Malloc((m + r + s + 1) * sizeof(double));
    if (!out) return PyErr_NoMemory();
    int rank = function(in, out);
    PyObject *items[4] = {NULL, NULL, NULL, PyLong_FromLong(rank)};
    for (int i = 0; i < 3; ++i)
        items[i] = rank < 0 ? Py_NewRef(Py_None)
                            : new_vector(out + (i > 0 ? m : 0) + (i > 1 ? r : 0), i == 0 ? m : i == 1 ? r : s);
    PyMem_Free(out);
    PyObject *result = items[0] && items[1] && items[2] && items[3]
                       ? PyTuple_Pack(4, items[0], items[1], items[2], items[3]) : NULL;
    for (int i = 0; i < 4; ++i) Py_XDECREF(items[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"call", (PyCFunction)(void (*)(void))call, METH_FASTCALL, "call(spec, q, qd, t, alpha, beta)"},
    {NULL, NULL, 0, NULL}
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kronlag_call", NULL, -1, methods};

PyMODINIT_FUNC PyInit__kronlag_call(void)
{
    import_array();
    return PyModule_Create(&module);
}
"""


@functools.cache
def call_extension():
    """The compiled :data:`_CALL_EXTENSION` module, or None where it cannot be built
    (no Python headers, say): callers then use :mod:`ctypes`."""
    include = [sysconfig.get_paths()["include"], np.get_include()]
    version = f"/* Python {sys.version}, NumPy {np.__version__} */\n"
    try:
        path = compile_shared_library(version + _CALL_EXTENSION, include=include)
        loader = importlib.machinery.ExtensionFileLoader("_kronlag_call", str(path))
        spec = importlib.util.spec_from_file_location("_kronlag_call", str(path), loader=loader)
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
    except (RuntimeError, OSError, ImportError):
        return None
    return module


def compile_shared_library(source: str, *, parts: int = 1, include: Sequence[str] = ()) -> Path:
    """Compile C ``source`` into a shared library in :func:`cache_directory` (reused when present).

    With ``parts > 1`` the source is compiled ``parts`` times in parallel with
    ``-DKRONLAG_PART=i -DKRONLAG_PARTS=parts`` (each keeps the chunks
    ``KRONLAG_IN_PART`` selects) and the objects are linked.  ``include``:
    header directories.
    """
    compiler = c_compiler()
    if compiler is None:
        raise RuntimeError("the C backend needs a C compiler (gcc or cc on PATH, or $CC); "
                           "use backend='numpy'")
    flags = (*_CFLAGS, *(f"-I{directory}" for directory in include))
    key = hashlib.sha256("\0".join((compiler, *flags, source)).encode()).hexdigest()[:32]
    directory = cache_directory()
    directory.mkdir(parents=True, exist_ok=True)
    target = directory / f"kronlag_{key}.so"
    if target.exists():
        return target
    with tempfile.TemporaryDirectory(dir=directory) as work:
        source_path = Path(work) / "model.c"
        source_path.write_text(source)
        objects = [Path(work) / f"part{i}.o" for i in range(parts)]
        defines = [[f"-DKRONLAG_PART={i}", f"-DKRONLAG_PARTS={parts}"] if parts > 1 else [] for i in range(parts)]
        processes = [subprocess.Popen([compiler, *flags, *define, "-c", "-o", str(obj), str(source_path)],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                     for define, obj in zip(defines, objects)]
        errors = [process.communicate()[1] for process in processes]
        failed = [error for process, error in zip(processes, errors) if process.returncode]
        built = Path(work) / "model.so"
        if not failed:
            undefined = ["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []
            link = subprocess.run([compiler, "-shared", *undefined, "-o", str(built), *map(str, objects), "-lm"],
                                  capture_output=True, text=True)
            failed = [link.stderr] if link.returncode else []
        if failed:
            raise RuntimeError(f"compiling the generated C code failed:\n{failed[0][-4000:]}")
        os.replace(built, target)  # atomic: concurrent builders of the same source agree
    return target
