"""Symbolic derivation of the equations of motion (Van Khang 2011, Section 3).

The mass matrix is assembled from the body Jacobians (Eq. 12)::

    M = sum_i (m_i J_Ti^T J_Ti + J_Ri^T I_i J_Ri)

and the Coriolis matrix of Eq. 22::

    C = dM/dq (I ⊗ qd) - 1/2 (dM/dq (qd ⊗ I))^T

is computed without forming ``dM/dq`` or any Kronecker product.  Write every
body term of ``M`` as ``J^T W J`` (``W = m_i I`` or ``I_i``).  Theorem 1 gives
``Md = X + X^T`` with ``X = J^T W Jd`` and ``Jd = sum_k dJ/dq_k qd_k``, and
Theorem 2 gives the second term row by row::

    T2[i, :] = (sum_j dM_:j/dq_i qd_j)^T = (W v)^T dJ/dq_i + (W dJ/dq_i qd)^T J,   v = J qd

so that ``C = Md - T2 / 2`` and the Christoffel form is
``C_christoffel = (Md + T2^T - T2) / 2``.  All heavy algebra runs in SymEngine
on plain symbols; the results are converted to SymPy once at the end.

The terms come from the system's items themselves: each body gives its kinetic-energy terms
``(J, W)`` (:meth:`~kronlag.model.bodies.Body.kinetic_terms`), each load its potential and
generalized force (:class:`~kronlag.model.loads.Load`), computed with the SymEngine calculus
that :func:`derive` lends them (:class:`_SymEngineCalculus`).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable

import symengine as se
import sympy as sp
from sympy.core.add import _addsort
from sympy.core.mul import _mulsort

from ..core.errors import InputError
from ..core.kernels import piecewise_form
from ..model.bodies import RigidBody
from ..model.contributions import KineticTerm, Velocity
from ..model.symbols import t
from ..model.system import System
from .equations import Equations, acceleration_offset
from .matrices import VECTORS

__all__ = ["derive"]


def _se_matrix(matrix: sp.MatrixBase) -> se.DenseMatrix:
    return se.DenseMatrix(matrix.rows, matrix.cols, [_symengine(entry) for entry in matrix])


#: SymPy node types rebuilt node by node in SymEngine (their arguments converted first); the other
#: non-atomic nodes are converted whole.
_REBUILT = {sp.Add: lambda *args: se.Add(*args), sp.Mul: lambda *args: se.Mul(*args), sp.Pow: se.Pow,
            **{getattr(sp, name): getattr(se, name) for name in (
                "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "log", "sinh", "cosh", "tanh")}}


def _symengine(expr: sp.Basic) -> se.Basic:
    """``expr`` in SymEngine, ``Min``, ``Max`` and ``Heaviside`` as ``Piecewise`` (:func:`piecewise_form`).

    Converted over the expression DAG, each shared subexpression once: ``sympify`` (and SymPy's
    ``has``) walk the tree, exponential in the depth of a chain whose poses reuse their parent's.
    """
    converted: dict[int, se.Basic] = {}  # node ids: the nodes stay alive inside ``expr``
    pending = [expr]
    while pending:
        node = pending[-1]
        if id(node) in converted:
            pending.pop()
            continue
        rebuild = _REBUILT.get(type(node))
        if rebuild is None:
            converted[id(node)] = se.sympify(piecewise_form(node))
            pending.pop()
            continue
        missing = [argument for argument in node.args if id(argument) not in converted]
        if missing:
            pending.extend(missing)
            continue
        converted[id(node)] = rebuild(*(converted[id(argument)] for argument in node.args))
        pending.pop()
    return converted[id(expr)]


class _SympyConverter:
    """SymEngine -> SymPy, memoized so that a subexpression shared by many
    entries (a sum of masses, a body velocity) is converted once.

    SymEngine's sums and products are already canonical (like terms
    collected, powers combined), so most nodes are built with SymPy's
    ``_from_args`` in SymPy's canonical argument order, skipping the costly
    ``flatten``; the cases where SymPy would still change the node (a number
    times a sum, nested sums or products, several numbers) go through the
    ordinary constructors.  The result is identical to ``sympy.sympify``.
    """

    def __init__(self, symbols: dict[str, sp.Symbol]):
        self.memo: dict = {}
        self.symbols = symbols  # by name: keeps the assumptions of the user's symbols

    def __call__(self, expr):
        result = self.memo.get(expr)
        if result is None:
            result = self._build(expr)
            self.memo[expr] = result
        return result

    def _build(self, expr):
        if isinstance(expr, se.Symbol) and expr.name in self.symbols:
            return self.symbols[expr.name]
        if not expr.args:
            return expr._sympy_()
        args = [self(arg) for arg in expr.args]
        if isinstance(expr, se.Piecewise):  # SymEngine flattens the (value, condition) pairs
            return sp.Piecewise(*zip(args[::2], args[1::2]))
        if isinstance(expr, se.Add):
            return _canonical_add(args)
        if isinstance(expr, se.Mul):
            return _canonical_mul(args)
        if isinstance(expr, se.Pow):
            return sp.Pow(*args)
        function = getattr(sp, type(expr).__name__, None)
        if function is None:  # an undefined function f(q): let SymEngine convert it
            return expr._sympy_()
        return function(*args)

    def matrix(self, matrix: se.DenseMatrix, shape: tuple[int, int]) -> sp.ImmutableMatrix:
        """Convert ``matrix``; ``shape`` is given because SymEngine drops the column count of 0-row matrices."""
        return sp.ImmutableMatrix(*shape, [self(entry) for entry in matrix])


def _canonical_add(args: list) -> sp.Expr:
    numbers = [arg for arg in args if arg.is_Number]
    terms = [arg for arg in args if not arg.is_Number]
    if len(numbers) > 1 or any(term.is_Add for term in terms):
        return sp.Add(*args)
    _addsort(terms)
    return sp.Add._from_args(numbers + terms)


def _canonical_mul(args: list) -> sp.Expr:
    numbers = [arg for arg in args if arg.is_Number]
    factors = [arg for arg in args if not arg.is_Number]
    if (len(numbers) > 1 or numbers == [sp.S.One] or any(factor.is_Mul for factor in factors)
            or (numbers and len(factors) == 1 and factors[0].is_Add)):
        return sp.Mul(*args)
    _mulsort(factors)
    return sp.Mul._from_args(numbers + factors)


def _jacobian(vector: se.DenseMatrix, variables: list) -> se.DenseMatrix:
    zero = se.Integer(0)
    entries = [vector[i] for i in range(vector.rows)]
    # a derivative by an absent variable is zero (by name: SymEngine's == is slow)
    present = [{symbol.name for symbol in entry.free_symbols} for entry in entries]
    names = [x.name for x in variables]
    return se.DenseMatrix(vector.rows, len(variables),
                          [se.diff(entry, x) if name in free else zero
                           for entry, free in zip(entries, present) for x, name in zip(variables, names)])


def _vee(skew: se.DenseMatrix) -> list:
    """Axial vector of a skew-symmetric 3x3 matrix."""
    return [skew[2, 1], skew[0, 2], skew[1, 0]]


#: Largest operation count of an entry of ``J_R`` that ``RigidBody(simplify=True)`` passes
#: to ``trigsimp``; larger entries are kept unsimplified (trigsimp's cost grows too fast).
TRIGSIMP_MAX_OPERATIONS = 45


def _rotation_jacobian(body: RigidBody, q: list) -> se.DenseMatrix:
    """``J_R`` with ``omega_body = J_R qd``.

    For a :class:`~kronlag.system.RotationSequence` it is ``sum_k w_k d(angle_k)/dq``
    (``w_k`` the axis of factor k in the body frame); for a matrix, column k is
    ``vee(R^T dR/dq_k)`` (Theorem 1), with entries of at most
    :data:`TRIGSIMP_MAX_OPERATIONS` operations trigsimp'd when ``body.simplify``.
    """
    if body.rotation_sequence is not None:
        jacobian = se.zeros(3, len(q))
        for axis, angle in body.rotation_sequence.body_axes():
            angle_gradient = _jacobian(se.DenseMatrix(1, 1, [_symengine(angle)]), q)
            if any(not entry.is_zero for entry in angle_gradient):
                jacobian += _se_matrix(axis) * angle_gradient
        return jacobian
    rotation = _se_matrix(body.rotation)
    rotation_t = rotation.T
    columns = [_vee(rotation_t * rotation.diff(qk)) for qk in q]
    jacobian = se.DenseMatrix(3, len(q), [columns[k][i] for i in range(3) for k in range(len(q))])
    if body.simplify:
        jacobian = jacobian.applyfunc(_bounded_trigsimp)
    return jacobian


def _bounded_trigsimp(entry: se.Basic) -> se.Basic:
    expr = sp.sympify(entry)
    if sp.count_ops(expr) > TRIGSIMP_MAX_OPERATIONS:
        return entry
    return se.sympify(sp.trigsimp(expr))


class _AlongSpeeds:
    """Derivatives of expressions of ``q`` along the speeds: ``D x = sum_k dx/dq_k qd_k`` and
    ``D2 x = sum_jk d2x/dq_j dq_k qd_j qd_k`` (``Jd qd`` for ``J = dx/dq``), by forward
    differentiation over the expression graph, memoized per node.

    Differentiating ``J`` by every coordinate and contracting twice with ``qd`` (Theorem 1) costs
    a term per pair of coordinates; along ``qd`` each node is differentiated once, so the
    acceleration of a link at the end of a chain in relative angles stays a sum over the links
    (``-sum_a l_a cos(theta_a) omega_a^2``) instead of a sum over pairs of joints.
    """

    def __init__(self, q: list, qd: list):
        self.speeds = dict(zip(q, qd))
        self.memo: dict = {}

    def __call__(self, expr: se.Basic) -> tuple[se.Basic, se.Basic]:
        """``(D expr, D2 expr)``."""
        result = self.memo.get(expr)
        if result is None:
            result = self.memo[expr] = self._build(expr)
        return result

    def _build(self, expr: se.Basic) -> tuple[se.Basic, se.Basic]:
        zero = se.Integer(0)
        if not expr.args:
            return self.speeds.get(expr, zero), zero
        if isinstance(expr, se.Add):
            parts = [self(arg) for arg in expr.args]
            return se.Add(*(first for first, _ in parts)), se.Add(*(second for _, second in parts))
        if isinstance(expr, se.Mul):
            value, (first, second) = expr.args[0], self(expr.args[0])
            for factor in expr.args[1:]:
                factor_first, factor_second = self(factor)
                second = second * factor + 2 * first * factor_first + value * factor_second
                first = first * factor + value * factor_first
                value = value * factor
            return first, second
        if isinstance(expr, se.Pow) and self(expr.args[1]) == (zero, zero):
            base, exponent = expr.args
            base_first, base_second = self(base)
            slope, curvature = exponent * base ** (exponent - 1), exponent * (exponent - 1) * base ** (exponent - 2)
            return slope * base_first, curvature * base_first ** 2 + slope * base_second
        if isinstance(expr, se.Function) and len(expr.args) == 1:
            (argument,) = expr.args
            argument_first, argument_second = self(argument)
            dummy = se.Dummy()
            slope = se.diff(expr.func(dummy), dummy)
            curvature = se.diff(slope, dummy).subs({dummy: argument})
            slope = slope.subs({dummy: argument})
            return slope * argument_first, curvature * argument_first ** 2 + slope * argument_second
        # anything else (a function of several arguments, a coordinate in an exponent): by coordinates
        first = se.Add(*(se.diff(expr, q) * qd for q, qd in self.speeds.items()))
        return first, se.Add(*(se.diff(first, q) * qd for q, qd in self.speeds.items()))


class _SymEngineCalculus:
    """The :class:`~kronlag.model.contributions.Calculus` that :func:`derive` lends bodies and loads:
    SymEngine on plain symbols.  Velocities are memoized, so that a body's angular velocity serves
    both its kinetic energy and the torques on it."""

    def __init__(self, q: list, qd: list):
        self.q = q
        self.speeds = se.DenseMatrix(len(qd), 1, qd)
        self.along = _AlongSpeeds(q, qd)
        self.matrices: dict = {}
        self.velocities: dict = {}

    @staticmethod
    def scalar(expression: sp.Expr) -> se.Basic:
        return _symengine(expression)

    def matrix(self, matrix: sp.MatrixBase) -> se.DenseMatrix:
        """``matrix`` in SymEngine, converted once (a body's position serves its velocity and its weight)."""
        key = sp.ImmutableMatrix(matrix)
        if key not in self.matrices:
            self.matrices[key] = _se_matrix(key)
        return self.matrices[key]

    def jacobian(self, vector: se.DenseMatrix) -> se.DenseMatrix:
        return _jacobian(vector, self.q)

    def velocity(self, vector: sp.MatrixBase) -> Velocity:
        """``J = d vector/dq`` and ``Jd qd = D2 vector`` (see :class:`_AlongSpeeds`)."""
        key = sp.ImmutableMatrix(vector)
        if key not in self.velocities:
            entries = self.matrix(key)
            bias = se.DenseMatrix(entries.rows, 1, [self.along(entry)[1] for entry in entries])
            self.velocities[key] = Velocity(self.jacobian(entries), bias)
        return self.velocities[key]

    def angular_velocity(self, body: RigidBody) -> Velocity:
        """``J_R`` (:func:`_rotation_jacobian`) and ``Jd qd = D(J_R qd)`` at fixed ``qd``."""
        if body not in self.velocities:
            jacobian = _rotation_jacobian(body, self.q)
            omega = jacobian * self.speeds
            bias = se.DenseMatrix(3, 1, [self.along(entry)[0] for entry in omega])
            self.velocities[body] = Velocity(jacobian, bias, gradient=False)
        return self.velocities[body]


def _weigh(weight, matrix: se.DenseMatrix) -> se.DenseMatrix:
    """``W matrix`` for a square matrix weight ``W``; a scalar weight is kept apart (see _Accumulator)."""
    return weight * matrix if isinstance(weight, se.DenseMatrix) else matrix


class _Accumulator:
    """Sums the body terms ``J^T W J`` of M, ``C qd``, and on demand ``Md`` and ``T2``.

    A scalar weight (a mass or a planar inertia) is kept apart from the term it
    multiplies, and terms that coincide are merged at the end: in a serial
    chain many bodies share a Jacobian column, and ``(m_3 + m_4 + m_5) c`` is
    far smaller than ``m_3 c + m_4 c + m_5 c``.  Each entry is summed once, at
    the end: adding to a growing symbolic sum body by body would copy it.
    """

    def __init__(self, q: list, qd: list):
        self.q, self.qd = q, qd
        self.mass_terms: dict[tuple[int, int], list] = defaultdict(list)
        self.mass_rate_terms: dict[tuple[int, int], list] = defaultdict(list)
        self.second_terms: dict[tuple[int, int], list] = defaultdict(list)
        self.velocity_terms: dict[tuple[int, int], list] = defaultdict(list)
        self.pending: list[tuple] = []  # the body terms whose Md and T2 terms are not summed yet
        self.products: dict[tuple, se.Basic | None] = {}  # column dot products, None if zero (_add_gram)
        self.interned: dict[se.Basic, se.Basic] = {}
        self._coriolis: tuple[se.DenseMatrix, se.DenseMatrix] | None = None

    def add(self, term: KineticTerm) -> None:
        """Add ``J^T W J`` of a body's kinetic-energy term; ``W`` is a scalar or a symmetric square matrix.

        The term's velocity gives ``J``, ``Jd qd`` (a column, the rows of ``J``; from
        :class:`_AlongSpeeds`) and whether ``J`` is the Jacobian of a position or an angle (its
        columns' derivatives are symmetric, ``dJ_i/dq_k = dJ_k/dq_i``); it is not for the
        angular-velocity Jacobian of a spatial body.  ``M`` and ``C qd`` are summed now, the
        terms of ``Md`` and ``T2`` (only ``C`` needs them) when first asked (:meth:`coriolis`).
        """
        jacobian, weight, bias = term.velocity.jacobian, term.weight, term.velocity.bias
        rows = range(jacobian.rows)
        support = [k for k in range(jacobian.cols) if any(not jacobian[r, k].is_zero for r in rows)]
        if not support:
            return
        factor = se.Integer(1) if isinstance(weight, se.DenseMatrix) else weight
        jacobian = se.DenseMatrix(jacobian.rows, len(support), [jacobian[r, k] for r in rows for k in support])
        qd = se.DenseMatrix(len(support), 1, [self.qd[k] for k in support])
        weighted = _weigh(weight, jacobian)  # W J, so J^T W = weighted^T
        self._add_gram(factor, support, weighted, jacobian)
        self.pending.append((weight, factor, support, jacobian, weighted, qd))
        # Velocity terms C qd = Md qd - dT/dq of this body: J^T W (Jd qd) + [(Jd_i - dJ/dq_i qd) . W v]_i;
        # for a gradient J the bracket vanishes (Jd_i = dJ/dq_i qd).  For the body-frame angular
        # velocity omega = J qd of a rigid body (W its central inertia) the bracket is Euler's
        # gyroscopic term J^T (omega x W omega), far smaller written so.  Summed body by body these
        # stay small where the entries of C, summed over l, would not.
        _scatter(self.velocity_terms, factor, support, [0], weighted.T * bias)
        if not term.velocity.gradient:
            omega, spin = jacobian * qd, weighted * qd
            gyroscopic = se.DenseMatrix(3, 1, [omega[1] * spin[2] - omega[2] * spin[1],
                                               omega[2] * spin[0] - omega[0] * spin[2],
                                               omega[0] * spin[1] - omega[1] * spin[0]])
            _scatter(self.velocity_terms, factor, support, [0], jacobian.T * gyroscopic)

    def _add_gram(self, factor, support: list, weighted: se.DenseMatrix, jacobian: se.DenseMatrix) -> None:
        """The upper triangle of ``weighted^T jacobian`` (``J^T W J``) into the terms of ``M``, each
        entry a dot product of two columns, memoized by the columns: in a chain the bodies beyond a
        joint share the columns of the joints before it (absolute angles: the same expressions), so
        most of the n^3 / 3 products of the bodies' terms are computed once."""
        rows, intern = range(jacobian.rows), self.interned.setdefault
        # equal entries made one object: a tuple compares them by identity first (SymEngine's == is slow)
        columns = [tuple(intern(jacobian[r, b], jacobian[r, b]) for r in rows) for b in range(len(support))]
        weighted_columns = columns if weighted is jacobian else [
            tuple(intern(weighted[r, a], weighted[r, a]) for r in rows) for a in range(len(support))]
        for a, (i, left) in enumerate(zip(support, weighted_columns)):
            for j, right in zip(support[a:], columns[a:]):
                key = (left, right)
                if key in self.products:
                    entry = self.products[key]
                else:
                    entry = se.Add(*(x * y for x, y in zip(left, right)))
                    entry = self.products[key] = None if entry.is_zero else entry
                if entry is not None:
                    self.mass_terms[(i, j)].append((factor, entry))

    def _add_coriolis(self, weight, factor, support: list, jacobian: se.DenseMatrix, weighted: se.DenseMatrix,
                      qd: se.DenseMatrix) -> None:
        """The terms of ``Md`` and ``T2`` of one body term (Theorems 1 and 2)."""
        symbols = set().union(*(entry.free_symbols for entry in jacobian))
        derivatives = {k: jacobian.diff(qk) for k, qk in enumerate(self.q) if qk in symbols}
        if not derivatives:
            return
        jacobian_dot = se.zeros(jacobian.rows, len(support))
        for k, derivative in derivatives.items():
            jacobian_dot += derivative * self.qd[k]
        cross = weighted.T * jacobian_dot  # X = J^T W Jd, Md = X + X^T
        _scatter(self.mass_rate_terms, factor, support, support, cross + cross.T, symmetric=True)
        weighted_velocity = (weighted * qd).T  # (W v)^T
        for i, derivative in derivatives.items():
            _scatter(self.second_terms, factor, [i], support, weighted_velocity * derivative)
            _scatter(self.second_terms, factor, [i], support, _weigh(weight, derivative * qd).T * jacobian)

    def _sum(self, terms: dict, *, columns: int, symmetric: bool = False) -> se.DenseMatrix:
        matrix = se.zeros(len(self.q), columns)
        for (i, j), pairs in terms.items():
            matrix[i, j] = _merge(pairs)
            if symmetric:
                matrix[j, i] = matrix[i, j]
        return matrix

    def mass_and_velocity_terms(self) -> tuple[se.DenseMatrix, se.DenseMatrix]:
        """``(M, C qd)``."""
        return (self._sum(self.mass_terms, columns=len(self.q), symmetric=True),
                self._sum(self.velocity_terms, columns=1))

    def coriolis(self) -> tuple[se.DenseMatrix, se.DenseMatrix]:
        """``(Md, T2)``, computed on the first call."""
        if self._coriolis is None:
            for record in self.pending:
                self._add_coriolis(*record)
            self.pending.clear()
            m = len(self.q)
            self._coriolis = (self._sum(self.mass_rate_terms, columns=m, symmetric=True),
                              self._sum(self.second_terms, columns=m))
        return self._coriolis


def _scatter(terms: dict, factor, rows: list, cols: list, block: se.DenseMatrix, *,
             symmetric: bool = False) -> None:
    """Append ``(factor, entry)`` for the nonzero entries of ``block`` to ``terms[(rows[a], cols[b])]``.

    With ``symmetric`` only the upper triangle (``rows[a] <= cols[b]``) is kept.
    """
    for i, block_row in zip(rows, block.tolist()):
        for j, entry in zip(cols, block_row):
            if not entry.is_zero and (not symmetric or i <= j):
                terms[(i, j)].append((factor, entry))


def _merge(pairs: list) -> se.Basic:
    """``sum factor * term`` with the factors of equal terms added first."""
    factors: dict = defaultdict(list)
    for factor, term in pairs:
        factors[term].append(factor)
    return se.Add(*[se.Add(*group) * term for term, group in factors.items()])


def _simplifier(simplify) -> Callable[[sp.Expr], sp.Expr] | None:
    if simplify is False or simplify is None:
        return None
    if simplify is True or simplify == "trigsimp":
        return sp.trigsimp
    if simplify == "simplify":
        return sp.simplify
    if callable(simplify):
        return simplify
    raise InputError(f"simplify must be False, True, 'trigsimp', 'simplify' or a callable, got {simplify!r}")


def derive(system: System, *, simplify: bool | str | Callable = False) -> Equations:
    """Derive the equations of motion of ``system`` in the Kronecker matrix form.

    Returns the matrices of (Van Khang 2011, Eq. 23)::

        M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
        f(q) = 0,   A(q) qd + b(q) = 0

    Parameters
    ----------
    system : System
    simplify : bool, {'trigsimp', 'simplify'} or callable, optional
        Simplify every entry of the results (``True`` means ``trigsimp``).
        Off by default: simplification can cost far more than the derivation.

    Returns
    -------
    Equations
        ``M`` (m x m), ``C`` (m x m), ``Cqd`` (``C qd``, m x 1), ``g`` (m x 1),
        ``Phi`` (r x 1), ``Phi_q`` (r x m), ``A`` (s x m), ``b`` (s x 1),
        ``f_Q`` (m x 1); on first access ``C_christoffel`` (m x m), ``dM_dq``
        (m x m²), ``Md``, ``gamma`` and ``gamma_nh``.

    References
    ----------
    .. [1] N. Van Khang, "Kronecker product and a new matrix form of Lagrangian equations with
       multipliers for constrained multibody systems", Mechanics Research Communications 38 (2011)
       294-299, https://doi.org/10.1016/j.mechrescom.2011.04.004
    """
    if not isinstance(system, System):
        raise TypeError(f"derive takes a kronlag.System, got {type(system).__name__}")
    q = [se.Symbol(s.name) for s in system.coordinates]
    qd = [se.Symbol(s.name) for s in system.speeds]
    m = len(q)
    calculus = _SymEngineCalculus(q, qd)
    accumulator = _Accumulator(q, qd)
    potential = se.Integer(0)
    gravity = _se_matrix(system.gravity) if system.gravity is not None else None
    for body in system.bodies:
        for term in body.kinetic_terms(calculus):
            accumulator.add(term)
        if gravity is not None:
            potential -= calculus.scalar(body.mass) * (gravity.T * calculus.matrix(body.position))[0, 0]

    generalized_force = se.zeros(m, 1)
    for load in system.loads:
        potential += calculus.scalar(load.potential())
        force = load.generalized_force(calculus)
        if force is not None:
            generalized_force += force
    g = se.DenseMatrix(m, 1, [se.diff(potential, qk) for qk in q])

    constraints = se.DenseMatrix(len(system.constraints), 1,
                                 [_symengine(c.expression) for c in system.constraints])
    constraint_jacobian = _jacobian(constraints, q)
    velocity_constraints = [_symengine(c.expression) for c in system.nonholonomic_constraints]
    nonholonomic_matrix = se.DenseMatrix(len(velocity_constraints), m,
                                         [se.diff(h, v) for h in velocity_constraints for v in qd])
    zero_speeds = {v: 0 for v in qd}
    nonholonomic_offset = se.DenseMatrix(len(velocity_constraints), 1,
                                         [h.subs(zero_speeds) for h in velocity_constraints])

    mass_matrix, velocity_terms = accumulator.mass_and_velocity_terms()
    r, s = len(system.constraints), len(velocity_constraints)
    native = {"M": mass_matrix, "Cqd": velocity_terms, "g": g, "Phi": constraints, "Phi_q": constraint_jacobian,
              "A": nonholonomic_matrix, "b": nonholonomic_offset, "f_Q": generalized_force,
              "potential_energy": se.DenseMatrix(1, 1, [potential])}
    converter = _SympyConverter({symbol.name: symbol for symbol in (
        *system.coordinates, *system.speeds, *system.parameters, t)})
    source = _DerivedMatrices(native, (m, r, s), accumulator, converter, _simplifier(simplify),
                              (q, qd, se.Symbol(t.name)))
    return Equations(system=system, time=t, source=source)


class _DerivedMatrices:
    """The :class:`~kronlag.symbolic.equations.MatrixSource` of :func:`derive`: its SymEngine matrices,
    converted to SymPy (and simplified, if asked) on first access; ``C`` and ``C_christoffel`` are
    computed on first access too (:meth:`_Accumulator.coriolis`).  Simplified equations give the
    numeric model no SymEngine form: its kernels then read the simplified SymPy matrices."""

    _SCALARS = ("potential_energy",)

    def __init__(self, native: dict[str, se.DenseMatrix], shape: tuple[int, int, int], accumulator: _Accumulator,
                 converter: _SympyConverter, simplifier: Callable[[sp.Expr], sp.Expr] | None,
                 variables: tuple[list, list, se.Symbol]):
        self.native, self.shape, self.accumulator = native, shape, accumulator
        self.converter, self.simplifier = converter, simplifier
        self.coordinates, self.speeds, self.time = variables

    def _native(self, name: str) -> se.DenseMatrix | None:
        if name in self.native:
            return self.native[name]
        if name in ("C", "C_christoffel"):
            mass_rate, second = self.accumulator.coriolis()
            self.native["C"] = mass_rate - second / 2
            self.native["C_christoffel"] = (mass_rate + second.T - second) / 2
            return self.native[name]
        if name == "Phi_t":
            self.native[name] = self.native["Phi"].diff(self.time) if self.shape[1] else se.zeros(0, 1)
        elif name in ("gamma", "gamma_nh"):
            jacobian, offset = (self._native("Phi_q"), self._native("Phi_t")) if name == "gamma" else (
                self.native["A"], self.native["b"])
            self.native[name] = acceleration_offset(jacobian, offset, self.coordinates, self.speeds, self.time)
        else:
            return None
        return self.native[name]

    def symengine(self, name: str) -> se.DenseMatrix | None:
        return None if self.simplifier else self._native(name)

    def sympy(self, name: str):
        matrix = self._native(name)
        if matrix is None:
            raise KeyError(f"the derivation has no matrix {name!r}")
        if name in self._SCALARS:
            converted = self.converter(matrix[0, 0])
            return self.simplifier(converted) if self.simplifier else converted
        m, r, s = self.shape
        rows = {"Phi": r, "Phi_q": r, "A": s, "b": s}.get(name, m)
        columns = 1 if name in VECTORS else m
        converted = self.converter.matrix(matrix, (rows, columns))
        return converted.applyfunc(self.simplifier) if self.simplifier else converted
