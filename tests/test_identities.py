"""Structural identities of the derived matrices, for every built-in model.

The Coriolis matrix of Eq. 22 and the Christoffel form share ``C qd``; only
the Christoffel form makes ``Md - 2C`` skew-symmetric (checked here as
``Md = C + C^T``, which is the same statement for a symmetric ``Md``).
Comparisons are numeric at random points (see conftest); ``C(q, 0) = 0`` is exact.
"""

import random

import numpy as np
import pytest
import sympy as sp
from helpers import (
    MODEL_BUILDERS,
    assert_numerically_equal,
    derived,
    evaluate,
    random_values,
    state_symbols,
)

from kronlag.symbolic.calculus import time_derivative

MODELS = list(MODEL_BUILDERS)


@pytest.fixture(params=MODELS)
def equations(request):
    return derived(request.param)


def test_shapes(equations):
    m = len(equations.coordinates)
    r, s = len(equations.system.constraints), len(equations.system.nonholonomic_constraints)
    assert equations.M.shape == equations.C.shape == equations.C_christoffel.shape == (m, m)
    assert equations.g.shape == equations.f_Q.shape == (m, 1)
    assert (equations.Phi.shape, equations.Phi_q.shape) == ((r, 1), (r, m))
    assert (equations.A.shape, equations.b.shape) == ((s, m), (s, 1))
    assert equations.dM_dq.shape == (m, m * m)
    assert equations.residual.shape == (m + r + s, 1)


def test_mass_matrix_is_symmetric(equations):
    assert_numerically_equal(equations.M, equations.M.T, state_symbols(equations))


def test_mass_matrix_depends_on_q_only(equations):
    assert not equations.M.free_symbols & (set(equations.speeds) | set(equations.accelerations))


def test_coriolis_matrix_vanishes_at_rest(equations):
    at_rest = dict.fromkeys(equations.speeds, 0)
    for matrix in (equations.C, equations.C_christoffel):
        assert matrix.subs(at_rest).applyfunc(sp.expand) == sp.zeros(*matrix.shape)


def test_coriolis_forms_have_the_same_product(equations):
    qd = sp.Matrix(equations.speeds)
    assert_numerically_equal(equations.C * qd, equations.C_christoffel * qd, state_symbols(equations))


def test_body_by_body_velocity_terms_equal_C_qd(equations):
    """``eom.Cqd`` (summed body by body) is the product ``C qd`` of Eq. 22."""
    assert equations.Cqd.shape == (equations.M.rows, 1)
    assert_numerically_equal(equations.Cqd, equations.C * sp.Matrix(equations.speeds), state_symbols(equations))


def test_gamma_is_theorem_1(equations):
    """``Phi_q qdd = gamma`` with ``gamma = -(dPhi_q/dq (I ⊗ qd)) qd``, the literal Theorem 1."""
    qd = sp.Matrix(equations.speeds)
    if equations.Phi.rows:
        expected = -time_derivative(equations.Phi_q, equations.coordinates, equations.speeds) * qd
        assert_numerically_equal(equations.gamma, expected, state_symbols(equations))
    if equations.A.rows:
        rate = time_derivative(equations.A, equations.coordinates, equations.speeds) * qd
        rate += time_derivative(equations.b, equations.coordinates, equations.speeds)
        assert_numerically_equal(equations.gamma_nh, -rate, state_symbols(equations))


def test_christoffel_form_makes_Md_minus_2C_skew_symmetric(equations):
    christoffel = equations.C_christoffel
    assert_numerically_equal(equations.Md, christoffel + christoffel.T, state_symbols(equations))


def test_energy_identity_of_eq22(equations):
    """``qd^T (Md - 2C) qd = 0`` for the C of Eq. 22."""
    qd = sp.Matrix(equations.speeds)
    assert_numerically_equal(qd.T * equations.Md * qd, 2 * qd.T * equations.C * qd, state_symbols(equations))


def test_Md_is_theorem_1(equations):
    """``Md = dM/dq (I ⊗ qd)``, built here with explicit Kronecker blocks."""
    m = equations.M.rows
    qd = sp.Matrix(equations.speeds)
    identity_kron_qd = sp.diag(*[qd] * m)  # I_m ⊗ qd is block diagonal
    assert_numerically_equal(equations.Md, equations.dM_dq * identity_kron_qd, state_symbols(equations))


def test_mass_matrix_is_positive_definite(equations):
    rng = random.Random(7)
    for _ in range(5):
        values = random_values(sorted(equations.M.free_symbols, key=str), rng, state_symbols(equations))
        mass = np.array(evaluate(equations.M, values), dtype=float).reshape(equations.M.shape)
        assert np.linalg.eigvalsh(mass).min() > 0


def test_velocity_terms_of_unusual_expressions_equal_C_qd():
    """The accelerations along the speeds (``Jd qd``) through every kind of node: powers with a
    coordinate in the exponent, functions of several arguments, square roots, an Euler-angle
    rigid body (its gyroscopic term); ``eom.Cqd`` against the product ``C qd`` of Eq. 22 and against ``d/dt (M qd) - dT/dq``."""
    import kronlag

    q1, q2, q3 = kronlag.coordinates("q1 q2 q3")
    m, inertia = sp.symbols("m J")
    system = kronlag.System([q1, q2, q3], parameters=[m, inertia], name="unusual")
    system.add_body(kronlag.PointMass("a", mass=m, position=(
        sp.atan2(q1, 2 + q2 ** 2), sp.sqrt(1 + q1 ** 2 * q3 ** 2), sp.exp(q2) ** q1)))
    system.add_body(kronlag.RigidBody("c", mass=m, inertia=sp.diag(inertia, 2 * inertia, 2 * inertia),
                                      position=(q1 * sp.cos(q2), sp.sin(q1 * q3), sp.tanh(q2 * q3)),
                                      rotation=kronlag.frames.euler_sequence("zyx", (q1, q2, q3))))
    equations = kronlag.derive(system)
    speeds = sp.Matrix(equations.speeds)
    assert_numerically_equal(equations.Cqd, equations.C * speeds, state_symbols(equations))
    kinetic = (speeds.T * equations.M * speeds)[0, 0] / 2
    momentum_rate = time_derivative(equations.M, equations.coordinates, equations.speeds) * speeds
    lagrange = momentum_rate - sp.Matrix([kinetic.diff(q) for q in equations.coordinates])
    assert_numerically_equal(equations.Cqd, lagrange, state_symbols(equations))
