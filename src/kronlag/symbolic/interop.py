"""Export for optimization: the equations of motion as CasADi and JAX functions.

From the symbolic matrices of an :class:`~kronlag.equations.Equations` object
(Van Khang 2011, Eq. 23)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0

:func:`casadi_functions` builds ``casadi.Function`` objects on SX symbols and
:func:`jax_functions` plain functions of ``jax.numpy`` arrays (``jax.jit`` and
``jax.vmap`` apply).  Every function takes ``(q, qd, p, t)``: ``q``, ``qd``
(m,), ``p`` (P,) the parameter values in the order of ``Equations.parameters``
(``NumericModel.parameter_vector(t)`` gives them) and the time ``t``:

==================  =========================================================================
name                outputs
==================  =========================================================================
M, C, Cqd, g, f_Q   (m, m), (m, m), (m,), (m,), (m,)
Phi, Phi_q          (r,), (r, m)
A, b                (s, m), (s,)
gamma, gamma_nh     (r,), (s,): ``Phi_q qdd = gamma``, ``A qdd = gamma_nh``
forward_dynamics    ``qdd`` (m,), ``lam`` (r,), ``mu`` (s,): ``[[M, G^T], [G, 0]] [qdd; nu] =
                    [f_Q - C qd - g; gamma; gamma_nh]`` with ``G = [Phi_q; A]`` (full row rank);
                    with JAX, up to :data:`UNROLLED_SIZE` unknowns, by :func:`range_space_solve`
                    in scalar operations (fast under ``jax.vmap``)
inverse_dynamics    input ``qdd`` after ``qd``; ``forces`` (n_a,), ``lam``, ``mu``:
                    ``[B, -Phi_q^T, -A^T] [u; lam; mu] = M qdd + C qd + g - f_Q`` (least squares)
==================  =========================================================================

``B`` selects the ``actuated`` coordinates.  Both backends are printed from the
same kernels as the numeric model (:mod:`kronlag.core.kernels`: common subexpressions
eliminated once, the generated Python run on CasADi or JAX objects; one table of
operations per backend); with CasADi
(``casadi.Function`` calls) the results are ``casadi.DM`` (numbers) or
``casadi.SX``/``MX`` (symbols) column vectors and matrices.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import symengine as se

from ..core.kernels import Kernel, expression_kernel, python_functions, python_source
from ..model.symbols import name_indices
from . import matrices as catalogue

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel
    from .equations import Equations

__all__ = ["casadi_functions", "jax_functions", "MATRICES", "UNROLLED_SIZE", "range_space_solve"]

#: The matrices exported (the catalogue's, :data:`kronlag.symbolic.matrices.INTEROP`), with whether each
#: is a vector.
MATRICES = {name: catalogue.MATRICES[name].vector for name in catalogue.INTEROP}

_FUNCTION_NAMES = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh", "acosh",
                   "atanh", "exp", "log", "sqrt", "floor")


def _namespace(module, renames: dict[str, str], maximum: Callable, minimum: Callable) -> dict[str, Any]:
    """The names the generated kernels call (SymEngine's spelling), in ``module``."""
    names = {name: getattr(module, renames.get(name, name)) for name in _FUNCTION_NAMES}
    names.update(abs=getattr(module, renames.get("abs", "abs")), sign=module.sign,
                 ceiling=getattr(module, renames.get("ceiling", "ceil")), pi=math.pi, E=math.e,
                 max=lambda *values: functools.reduce(maximum, values),
                 min=lambda *values: functools.reduce(minimum, values))
    return names


class _Backend:
    """How one library builds arrays and solves: the only difference between CasADi and JAX."""

    def __init__(self, name: str):
        if name == "casadi":
            import casadi as ca

            self.namespace = _namespace(ca, {"abs": "fabs", "ceiling": "ceil"}, ca.fmax, ca.fmin)
            self.matrix = lambda rows, shape: ca.reshape(ca.vertcat(*rows), shape[1], shape[0]).T \
                if rows else ca.DM.zeros(*shape)
            self.vector = lambda entries: ca.vertcat(*entries) if entries else ca.DM.zeros(0, 1)
            self.stack_rows = ca.vertcat
            self.stack_columns = ca.horzcat
            self.solve = ca.solve
            self.transpose = lambda x: x.T
            self.zeros = ca.DM.zeros
            self.identity_columns = lambda m, columns: ca.DM([[1.0 if i == j else 0.0 for j in columns]
                                                                for i in range(m)])
            self.split = lambda x, sizes: [x[start:start + size] for start, size in _offsets(sizes)]
            self.unrolled = False
        else:
            import jax.numpy as jnp

            self.namespace = _namespace(jnp, {"asin": "arcsin", "acos": "arccos", "atan": "arctan", "atan2": "arctan2",
                                              "asinh": "arcsinh", "acosh": "arccosh", "atanh": "arctanh"},
                                        jnp.maximum, jnp.minimum)
            self.matrix = lambda rows, shape: jnp.reshape(jnp.stack([jnp.asarray(x, dtype=float) for x in rows]),
                                                          shape) if rows else jnp.zeros(shape)
            self.vector = lambda entries: jnp.stack([jnp.asarray(x, dtype=float) for x in entries]) \
                if entries else jnp.zeros(0)
            self.stack_rows = lambda *blocks: jnp.concatenate(blocks, axis=0)
            self.stack_columns = lambda *blocks: jnp.concatenate(blocks, axis=1)
            self.solve = jnp.linalg.solve
            self.transpose = lambda x: x.T
            self.zeros = lambda *shape: jnp.zeros(shape)
            self.identity_columns = lambda m, columns: jnp.eye(m)[:, list(columns)]
            self.split = lambda x, sizes: [x[start:start + size] for start, size in _offsets(sizes)]
            # scalar code for the forward dynamics (its solve unrolled, the kernel's function calls
            # evaluated once, _calls_first): under jax.vmap every scalar is one element-wise operation
            # on the batch, which XLA fuses into loops; a batched jnp.linalg.solve of small systems is
            # a LAPACK call per state, several times slower
            self.unrolled = True


#: The blocks of the forward dynamics, evaluated by one kernel.
_DYNAMICS_BLOCKS = ("M", "f_Q", "Cqd", "g", "Phi_q", "A", "gamma", "gamma_nh")

#: Largest augmented system (m + r + s) that JAX's forward dynamics solves by unrolled scalar code
#: (:func:`range_space_solve`); larger ones by ``jnp.linalg.solve`` of the stacked system (the
#: unrolled code grows like the cube of the size, and so does its compile time).
UNROLLED_SIZE = 24


def _cholesky(A: list[list], sqrt: Callable) -> tuple[list[list], list]:
    """The lower Cholesky factor ``L`` of the symmetric positive definite ``A`` (lists of scalars) and
    the reciprocals of its diagonal (a division costs several multiplications)."""
    n = len(A)
    L: list[list] = [[0.0] * n for _ in range(n)]
    inverse: list = [0.0] * n
    for j in range(n):
        L[j][j] = sqrt(A[j][j] - sum((L[j][k] * L[j][k] for k in range(j)), 0.0))
        inverse[j] = 1.0 / L[j][j]
        for i in range(j + 1, n):
            L[i][j] = (A[i][j] - sum((L[i][k] * L[j][k] for k in range(j)), 0.0)) * inverse[j]
    return L, inverse


def _cholesky_solve(factor: tuple[list[list], list], b: list) -> list:
    """``x`` with ``L L^T x = b`` (``factor`` from :func:`_cholesky`)."""
    L, inverse = factor
    n = len(b)
    y: list = [0.0] * n
    for i in range(n):
        y[i] = (b[i] - sum((L[i][k] * y[k] for k in range(i)), 0.0)) * inverse[i]
    x: list = [0.0] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), 0.0)) * inverse[i]
    return x


def range_space_solve(M_flat: Sequence, G_flat: Sequence, h: Sequence, c: Sequence, *,
                      sqrt: Callable = math.sqrt) -> tuple[list, list]:
    """``(qdd, nu)`` of ``[[M, G^T], [G, 0]] [qdd; nu] = [h; c]`` in scalar operations (lists of numbers,
    or of JAX scalars with ``sqrt=jnp.sqrt``; row-major ``M`` (m x m) and ``G`` (k x m)).

    ``M`` need only be positive definite on the null space of ``G`` (full row rank): with ``rho =
    trace(M) / trace(G G^T)`` the first block row plus ``rho G^T (G qdd - c) = 0`` gives
    ``M_rho qdd + G^T nu = h + rho G^T c`` with ``M_rho = M + rho G^T G`` positive definite; then
    ``nu = S^-1 (G M_rho^-1 (h + rho G^T c) - c)``, ``S = G M_rho^-1 G^T``, and
    ``qdd = M_rho^-1 (h + rho G^T c - G^T nu)``, by two Cholesky factorizations.
    """
    m, k = len(h), len(c)
    M = [list(M_flat[i * m:(i + 1) * m]) for i in range(m)]
    G = [list(G_flat[i * m:(i + 1) * m]) for i in range(k)]
    b = list(h)
    if k:
        rho = sum(M[i][i] for i in range(m)) / sum(G[i][j] * G[i][j] for i in range(k) for j in range(m))
        M = [[M[a][j] + rho * sum(G[i][a] * G[i][j] for i in range(k)) for j in range(m)] for a in range(m)]
        b = [b[a] + rho * sum(G[i][a] * c[i] for i in range(k)) for a in range(m)]
    L = _cholesky(M, sqrt)
    free = _cholesky_solve(L, b)
    if not k:
        return free, []
    Y = [_cholesky_solve(L, G[i]) for i in range(k)]  # M_rho^-1 G^T, by columns
    S = [[sum(G[i][a] * Y[j][a] for a in range(m)) for j in range(k)] for i in range(k)]
    nu = _cholesky_solve(_cholesky(S, sqrt), [sum(G[i][a] * free[a] for a in range(m)) - c[i] for i in range(k)])
    return [free[a] - sum(Y[i][a] * nu[i] for i in range(k)) for a in range(m)], nu


def _calls_first(kernel: Kernel) -> str:
    """:func:`python_source` of ``kernel`` with the function calls of its inputs alone (``sin(q[0])``,
    ``cos(q[0] + q[1])``, ...) evaluated first and passed together through :func:`_materialize`: XLA's
    fusion on the CPU copies such calls into every consumer otherwise (on the four-bar, eight
    evaluations of each sine in the forward dynamics; ``jax.lax.optimization_barrier`` does not stop it)."""
    names = {symbol for symbol, _ in kernel.temporaries}
    calls = [(symbol, expr) for symbol, expr in kernel.temporaries
             if isinstance(expr, se.Function) and not expr.free_symbols & names]
    if not calls:
        return python_source(kernel)
    rest = [pair for pair in kernel.temporaries if pair not in calls]
    lines = python_source(replace(kernel, temporaries=(*calls, *rest))).splitlines()
    joined = ", ".join(str(symbol) for symbol, _ in calls) + ","
    lines.insert(1 + len(calls), f"    {joined} = _materialize({joined})")
    return "\n".join(lines) + "\n"


def _materialize(*values) -> tuple:
    """``values`` (JAX scalars) through a product with the identity, which XLA evaluates once and does
    not fuse into its consumers."""
    import jax.numpy as jnp

    product = jnp.stack([jnp.asarray(value, dtype=float) for value in values]) @ jnp.eye(len(values))
    return tuple(product[i] for i in range(len(values)))


def _offsets(sizes: Sequence[int]):
    start = 0
    for size in sizes:
        yield start, size
        start += size


class _Exported:
    """The expressions of ``equations`` as functions ``(q, qd, p, t) -> backend array``."""

    def __init__(self, equations: Equations, backend: _Backend):
        eq = self.equations = equations
        self.backend, self.shape = backend, eq.shape
        inputs = self.inputs = [("t", eq.time), ("q", eq.coordinates), ("qd", eq.speeds), ("p", eq.parameters)]
        kernels = [expression_kernel({name: getattr(eq, name)}, inputs, name=name) for name in MATRICES]
        source = "\n\n".join(python_source(kernel) for kernel in kernels)
        functions = python_functions(source, list(MATRICES), backend.namespace)
        self.functions: dict[str, tuple[Callable, tuple[int, int], bool]] = {
            name: (functions[name], kernel.blocks[0].shape, is_vector)
            for kernel, (name, is_vector) in zip(kernels, MATRICES.items())}

    def __call__(self, name: str, q, qd, p, t):
        function, shape, is_vector = self.functions[name]
        entries = function(t, q, qd, p) if shape[0] * shape[1] else []
        return self.backend.vector(entries) if is_vector else self.backend.matrix(entries, shape)

    @functools.cached_property
    def _terms(self) -> tuple[Callable, tuple[tuple[str, int], ...]]:
        """The blocks of the forward dynamics in one kernel (common subexpressions shared by all of
        them): its function and the blocks' names and sizes."""
        eq = self.equations
        kernel = expression_kernel({name: getattr(eq, name) for name in _DYNAMICS_BLOCKS}, self.inputs,
                                   name="dynamics_terms")
        source = _calls_first(kernel) if self.backend.unrolled else python_source(kernel)
        namespace = dict(self.backend.namespace, _materialize=_materialize)
        function = python_functions(source, ["dynamics_terms"], namespace)
        return function["dynamics_terms"], tuple((block.name, block.size) for block in kernel.blocks)

    def forward_dynamics(self, q, qd, p, t):
        """``(qdd, lam, mu)`` from the augmented system (full-rank constraints)."""
        bk, (m, r, s) = self.backend, self.shape
        function, sizes = self._terms
        flat = function(t, q, qd, p)
        blocks = dict(zip((name for name, _ in sizes), bk.split(flat, [size for _, size in sizes])))
        h = [f - c - g for f, c, g in zip(blocks["f_Q"], blocks["Cqd"], blocks["g"])]
        G, c = blocks["Phi_q"] + blocks["A"], blocks["gamma"] + blocks["gamma_nh"]
        if bk.unrolled and m + r + s <= UNROLLED_SIZE:
            qdd, nu = range_space_solve(blocks["M"], G, h, c, sqrt=bk.namespace["sqrt"])
            return bk.vector(qdd), bk.vector(nu[:r]), bk.vector(nu[r:])
        M, h = bk.matrix(blocks["M"], (m, m)), bk.vector(h)
        if r + s == 0:
            return bk.solve(M, h), bk.zeros(0), bk.zeros(0)
        G, c = bk.matrix(G, (r + s, m)), bk.vector(c)
        augmented = bk.stack_rows(bk.stack_columns(M, bk.transpose(G)),
                                  bk.stack_columns(G, bk.zeros(r + s, r + s)))
        solution = bk.solve(augmented, bk.stack_rows(h, c))
        return tuple(bk.split(solution, (m, r, s)))

    def inverse_dynamics(self, columns: Sequence[int], q, qd, qdd, p, t):
        """``(forces, lam, mu)``: least squares of ``[B, -Phi_q^T, -A^T] x = M qdd + C qd + g - f_Q``."""
        bk, (m, r, s) = self.backend, self.shape
        rhs = (self("M", q, qd, p, t) @ qdd + self("Cqd", q, qd, p, t) + self("g", q, qd, p, t)
               - self("f_Q", q, qd, p, t))
        system = bk.stack_columns(bk.identity_columns(m, columns), -bk.transpose(self("Phi_q", q, qd, p, t)),
                                  -bk.transpose(self("A", q, qd, p, t)))
        normal = bk.transpose(system) @ system
        solution = bk.solve(normal, bk.transpose(system) @ rhs)
        return tuple(bk.split(solution, (len(columns), r, s)))


def _equations_of(source: Equations | NumericModel) -> Equations:
    return getattr(source, "equations", source)


def _actuated_columns(equations: Equations, actuated: Sequence | None) -> list[int]:
    """Indices of the actuated coordinates (default: the first coordinate)."""
    index = {q.name: i for i, q in enumerate(equations.coordinates)}
    return name_indices(list(actuated) if actuated is not None else [equations.coordinates[0].name], index,
                        "actuated coordinate(s)")


def casadi_functions(source: Equations | NumericModel, *, actuated: Sequence | None = None) -> dict[str, Any]:
    """The matrices and dynamics as ``casadi.Function`` objects on SX (see the module table).

    Parameters
    ----------
    source : Equations or NumericModel
    actuated : sequence of coordinate names, optional
        Coordinates driven by the ``inverse_dynamics`` forces (default: the first coordinate).

    Returns
    -------
    dict of str -> casadi.Function
        Inputs ``q`` (m), ``qd`` (m), ``p`` (P), ``t`` (1) -- ``inverse_dynamics`` has
        ``qdd`` after ``qd``; vectors are columns.
    """
    try:
        import casadi as ca
    except ImportError as error:
        raise ImportError("casadi_functions needs CasADi: pip install casadi (or kronlag[casadi])") from error
    equations = _equations_of(source)
    m, _, _ = equations.shape
    exported = _Exported(equations, _Backend("casadi"))
    columns = _actuated_columns(equations, actuated)
    q, qd, qdd = ca.SX.sym("q", m), ca.SX.sym("qd", m), ca.SX.sym("qdd", m)
    p, t = ca.SX.sym("p", len(equations.parameters)), ca.SX.sym("t")
    entries = ([q[i] for i in range(m)], [qd[i] for i in range(m)], [p[i] for i in range(p.numel())], t)
    functions = {name: ca.Function(name, [q, qd, p, t], [exported(name, *entries)], ["q", "qd", "p", "t"], [name])
                 for name in MATRICES}
    functions["forward_dynamics"] = ca.Function(
        "forward_dynamics", [q, qd, p, t], list(exported.forward_dynamics(*entries)), ["q", "qd", "p", "t"],
        ["qdd", "lam", "mu"])
    functions["inverse_dynamics"] = ca.Function(
        "inverse_dynamics", [q, qd, qdd, p, t],
        list(exported.inverse_dynamics(columns, entries[0], entries[1], qdd, entries[2], t)),
        ["q", "qd", "qdd", "p", "t"], ["forces", "lam", "mu"])
    return functions


def jax_functions(source: Equations | NumericModel, *, actuated: Sequence | None = None) -> dict[str, Callable]:
    """The matrices and dynamics as functions of ``jax.numpy`` arrays (see the module table).

    Every function is ``f(q, qd, p, t)`` (``inverse_dynamics``: ``f(q, qd, qdd, p, t)``) of
    arrays ``q``, ``qd`` (m,), ``p`` (P,) and a scalar ``t``; ``jax.jit`` and ``jax.vmap``
    apply (enable float64 with ``jax.config.update("jax_enable_x64", True)`` for double
    precision).  ``forward_dynamics`` and ``inverse_dynamics`` return tuples of arrays;
    ``actuated`` as for :func:`casadi_functions`.
    """
    try:
        import jax  # noqa: F401
    except ImportError as error:
        raise ImportError("jax_functions needs JAX: pip install jax (or kronlag[jax])") from error
    equations = _equations_of(source)
    exported = _Exported(equations, _Backend("jax"))
    columns = _actuated_columns(equations, actuated)

    def matrix_function(name: str) -> Callable:
        def evaluate(q, qd, p, t):
            return exported(name, q, qd, p, t)

        evaluate.__name__ = name
        evaluate.__doc__ = f"``{name}(q, qd, p, t)``, see :mod:`kronlag.interop`."
        return evaluate

    functions: dict[str, Callable] = {name: matrix_function(name) for name in MATRICES}
    functions["forward_dynamics"] = exported.forward_dynamics
    functions["inverse_dynamics"] = lambda q, qd, qdd, p, t: exported.inverse_dynamics(columns, q, qd, qdd, p, t)
    return functions
