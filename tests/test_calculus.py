"""Matrix calculus of Van Khang (2011), Section 2, against element-wise SymPy
differentiation, and the Coriolis matrix of ``derive`` against the literal
Kronecker formula of Eq. 22."""

import random

import pytest
import sympy as sp
from helpers import assert_numerically_equal, derived, state_symbols
from sympy.physics.mechanics import dynamicsymbols

from kronlag.symbolic.calculus import kron, matrix_derivative, product_derivative, time_derivative

PARAMETER = sp.Symbol("p")


def variables(k: int) -> list[sp.Symbol]:
    return list(sp.symbols(f"x1:{k + 1}"))


def random_entry(rng: random.Random, x: list[sp.Symbol]) -> sp.Expr:
    """A random sum of products of polynomial, trigonometric and exponential factors of ``x``."""
    factors = [lambda v: v, lambda v: v**2, lambda v: v**3, sp.sin, sp.cos, sp.exp, lambda v: sp.sin(2 * v)]
    terms = []
    for _ in range(rng.randint(0, 3)):
        coefficient = sp.Rational(rng.randint(-5, 5), rng.randint(1, 4)) * rng.choice([1, PARAMETER])
        first, second = rng.choice(factors), rng.choice(factors)
        terms.append(coefficient * first(rng.choice(x)) * second(rng.choice(x)))
    return sp.Add(*terms)


def random_matrix(seed: int, shape: tuple[int, int], x: list[sp.Symbol]) -> sp.Matrix:
    rng = random.Random(seed)
    return sp.Matrix(*shape, lambda i, j: random_entry(rng, x))


def elementwise_derivative(A: sp.Matrix, x: list[sp.Symbol]) -> sp.Matrix:
    """Definition 1 written differently: the Jacobians of the columns of ``A``, side by side."""
    return sp.Matrix.hstack(*[A[:, j].jacobian(x) for j in range(A.cols)])


def assert_same(actual: sp.Matrix, expected: sp.Matrix) -> None:
    assert actual.shape == expected.shape
    assert (actual - expected).applyfunc(sp.expand) == sp.zeros(*expected.shape)


SHAPES = [((2, 3), 4), ((3, 1), 2), ((1, 4), 3), ((3, 3), 3), ((2, 2), 1)]


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(("shape", "k"), SHAPES)
def test_matrix_derivative_matches_elementwise_diff(shape, k, seed):
    x = variables(k)
    A = random_matrix(seed, shape, x)
    result = matrix_derivative(A, x)
    assert result.shape == (shape[0], shape[1] * k)
    assert_same(result, elementwise_derivative(A, x))


def test_matrix_derivative_small_example():
    """Definition 1 by hand: each entry becomes its row gradient."""
    x1, x2 = sp.symbols("x1 x2")
    A = sp.Matrix([[x1 * x2, x1**2], [sp.sin(x2), 7]])
    expected = sp.Matrix([[x2, x1, 2 * x1, 0], [0, sp.cos(x2), 0, 0]])
    assert matrix_derivative(A, [x1, x2]) == expected


@pytest.mark.parametrize(("shape_a", "shape_b"), [((2, 3), (3, 2)), ((1, 1), (3, 4)), ((3, 1), (1, 3)),
                                                  ((2, 2), (2, 2))])
def test_kron_is_the_block_matrix_of_products(shape_a, shape_b):
    rng = random.Random(1)
    A = sp.Matrix(*shape_a, lambda i, j: rng.choice([0, rng.randint(-9, 9), sp.Symbol(f"a{i}{j}")]))
    B = sp.Matrix(*shape_b, lambda i, j: rng.choice([rng.randint(-9, 9), sp.Symbol(f"b{i}{j}")]))
    result = kron(A, B)
    assert result == sp.kronecker_product(A, B)
    rows_b, cols_b = shape_b
    for i in range(result.rows):
        for j in range(result.cols):
            assert result[i, j] == A[i // rows_b, j // cols_b] * B[i % rows_b, j % cols_b]


def test_kron_small_example():
    a, b = sp.symbols("a b")
    assert kron(sp.Matrix([[1, a]]), sp.Matrix([[b], [2]])) == sp.Matrix([[b, a * b], [2, 2 * a]])


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize(("shape", "k"), SHAPES)
def test_time_derivative_is_the_chain_rule(shape, k, seed):
    """Theorem 1 (with I_b, b the column count of A) against d/dt of A(x(t))."""
    x = variables(k)
    xd = list(sp.symbols(f"x1:{k + 1}d"))
    A = random_matrix(seed + 10, shape, x)
    trajectory = dynamicsymbols(f"x1:{k + 1}")
    t = dynamicsymbols._t
    along_trajectory = A.subs(dict(zip(x, trajectory))).diff(t)
    chain_rule = along_trajectory.subs({f.diff(t): v for f, v in zip(trajectory, xd)}).subs(dict(zip(trajectory, x)))
    assert_same(time_derivative(A, x, xd), chain_rule)


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize(("shape_a", "shape_b", "k"), [((2, 3), (3, 2), 4), ((1, 3), (3, 1), 2), ((3, 3), (3, 3), 3),
                                                       ((2, 1), (1, 4), 2)])
def test_product_derivative_is_the_derivative_of_the_product(shape_a, shape_b, k, seed):
    """Theorem 2 against the element-wise derivative of ``A B``."""
    x = variables(k)
    A = random_matrix(seed + 20, shape_a, x)
    B = random_matrix(seed + 30, shape_b, x)
    assert_same(product_derivative(A, B, x), elementwise_derivative(A * B, x))


@pytest.mark.parametrize(("call", "message"), [
    (lambda x: time_derivative(sp.eye(2), x, x[:1]), "length"),
    (lambda x: product_derivative(sp.ones(2, 3), sp.ones(2, 3), x), "conformable"),
    (lambda x: matrix_derivative(sp.eye(2), sp.Matrix(2, 2, x * 2)), "vector"),
])
def test_calculus_rejects_bad_shapes(call, message):
    with pytest.raises(ValueError, match=message):
        call(variables(2))


KRONECKER_MODELS = ["four_bar", "quick_return", "closed_chain_4_relative", "heavy_top"]


@pytest.mark.parametrize("name", KRONECKER_MODELS)
def test_dM_dq_is_definition_1(name):
    equations = derived(name)
    assert_same(equations.dM_dq, elementwise_derivative(sp.Matrix(equations.M), list(equations.coordinates)))


@pytest.mark.parametrize("name", KRONECKER_MODELS)
def test_coriolis_matrix_is_the_literal_kronecker_formula(name):
    """``C == dM/dq (I ⊗ qd) - 1/2 (dM/dq (qd ⊗ I))^T`` (Eq. 22) and ``Md == dM/dq (I ⊗ qd)``."""
    equations = derived(name)
    m = equations.M.rows
    qd = sp.Matrix(equations.speeds)
    dM = elementwise_derivative(sp.Matrix(equations.M), list(equations.coordinates))
    mass_rate = dM * kron(sp.eye(m), qd)
    literal = mass_rate - (dM * kron(qd, sp.eye(m))).T / 2
    signed = state_symbols(equations)
    assert_numerically_equal(equations.C, literal, signed)
    assert_numerically_equal(equations.Md, mass_rate, signed)
