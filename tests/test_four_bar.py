"""The examples of Van Khang (2011), Section 4: the four-bar (Eqs. 29-34, with
the misprints corrected as in docs/method.md) and the quick-return mechanism
(Eqs. 36-37)."""

import pytest
import sympy as sp
from helpers import derived, is_zero

cos, sin = sp.cos, sp.sin

q1, q2, q3 = sp.symbols("q1 q2 q3")
q1d, q2d, q3d = sp.symbols("q1d q2d q3d")
q1dd, q2dd, q3dd = sp.symbols("q1dd q2dd q3dd")
l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau = sp.symbols("l1 l2 l3 l4 m1 m2 m3 I1 I2 I3 g tau")
lambda1, lambda2 = sp.symbols("lambda1 lambda2")

a = m2 * l1 * l2
c, s = cos(q1 - q2), sin(q1 - q2)
QD = sp.Matrix([q1d, q2d, q3d])

# Corrected results of Section 4.1 (docs/method.md).
M_CORRECT = sp.Matrix([[I1 + m1 * l1**2 / 4 + m2 * l1**2, a * c / 2, 0],
                       [a * c / 2, I2 + m2 * l2**2 / 4, 0],
                       [0, 0, I3 + m3 * l3**2 / 4]])
C_CORRECT = a * s / 4 * sp.Matrix([[q2d, 2 * q2d - q1d, 0], [q2d - 2 * q1d, -q1d, 0], [0, 0, 0]])
G_CORRECT = sp.Matrix([(m1 / 2 + m2) * g * l1 * cos(q1), m2 * g * l2 * cos(q2) / 2, m3 * g * l3 * cos(q3) / 2])
PHI_Q_CORRECT = sp.Matrix([[-l1 * sin(q1), -l2 * sin(q2), l3 * sin(q3)],
                           [l1 * cos(q1), l2 * cos(q2), -l3 * cos(q3)]])
# Eq. 34 as printed (each row moved to the form "left side - right side"), then Eq. 24.
EQ_34 = sp.Matrix([
    (m1 / 4 * l1**2 + m2 * l1**2 + I1) * q1dd + m2 / 2 * l1 * l2 * c * q2dd + m2 / 2 * l1 * l2 * s * q2d**2
    + (m1 / 2 + m2) * g * l1 * cos(q1) - lambda1 * l1 * sin(q1) + lambda2 * l1 * cos(q1) - tau,
    m2 / 2 * l1 * l2 * c * q1dd + (m2 / 4 * l2**2 + I2) * q2dd - m2 / 2 * l1 * l2 * s * q1d**2
    + m2 / 2 * g * l2 * cos(q2) - lambda1 * l2 * sin(q2) + lambda2 * l2 * cos(q2),
    (m3 / 4 * l3**2 + I3) * q3dd + m3 / 2 * g * l3 * cos(q3) + lambda1 * l3 * sin(q3) - lambda2 * l3 * cos(q3),
    l1 * cos(q1) + l2 * cos(q2) - l3 * cos(q3) - l4,
    l1 * sin(q1) + l2 * sin(q2) - l3 * sin(q3),
])

# Entries of Eqs. 29 and 30 as printed in the paper.
M11_PRINTED = I1 + m1 * l1**2 / 4 + m2 * l2**2
M12_PRINTED = a * c / 2
M21_PRINTED = m2 * l1 * c / 2
C12_PRINTED = C21_PRINTED = -a * s * (q1d - q2d) / 2
C11_PRINTED = a * s * q2d / 4
C22_PRINTED = -a * s * q1d / 4


@pytest.fixture(scope="module")
def four_bar():
    return derived("four_bar")


def lagrange_velocity_terms(mass_matrix: sp.Matrix, q: list, qd: sp.Matrix) -> sp.Matrix:
    """``d/dt(dT/dqd) - dT/dq`` without the ``M qdd`` part, from ``T = 1/2 qd^T M qd``."""
    kinetic = (qd.T * mass_matrix * qd)[0, 0] / 2
    mass_rate = sum((mass_matrix.diff(qk) * qdk for qk, qdk in zip(q, qd)), sp.zeros(*mass_matrix.shape))
    return mass_rate * qd - sp.Matrix([kinetic]).jacobian(q).T


def test_symbols(four_bar):
    assert four_bar.coordinates == (q1, q2, q3)
    assert four_bar.speeds == (q1d, q2d, q3d)
    assert four_bar.accelerations == (q1dd, q2dd, q3dd)
    assert four_bar.lambdas == (lambda1, lambda2)


@pytest.mark.parametrize(("name", "expected"), [("M", M_CORRECT), ("C", C_CORRECT), ("g", G_CORRECT),
                                                ("Phi_q", PHI_Q_CORRECT)],
                         ids=["Eq29_M", "Eq30_C", "Eq32_g", "Eq33_Phi_q"])
def test_four_bar_matrices(four_bar, name, expected):
    actual = getattr(four_bar, name)
    assert actual.shape == expected.shape
    assert is_zero(actual - expected)


def test_four_bar_generalized_force(four_bar):
    assert four_bar.f_Q == sp.Matrix([tau, 0, 0])


def test_four_bar_full_equations_eq34(four_bar):
    assert is_zero(four_bar.residual - EQ_34)


def test_four_bar_velocity_terms_are_lagrange(four_bar):
    """``C qd = a s/2 [qd2², -qd1², 0]``, the velocity terms of Lagrange's equations."""
    expected = a * s / 2 * sp.Matrix([q2d**2, -q1d**2, 0])
    assert is_zero(lagrange_velocity_terms(M_CORRECT, [q1, q2, q3], QD) - expected)
    assert is_zero(four_bar.C * QD - expected)


def test_misprint_eq29_M11(four_bar):
    """Eq. 29 prints ``m2 l2²`` in M11; the derivation gives ``m2 l1²``."""
    assert not is_zero(four_bar.M[0, 0] - M11_PRINTED)
    assert is_zero(four_bar.M[0, 0] - M_CORRECT[0, 0])


def test_misprint_eq29_M21(four_bar):
    """Eq. 29 prints M21 without ``l2``, so the printed M is not even symmetric."""
    assert not is_zero(M12_PRINTED - M21_PRINTED)
    assert not is_zero(four_bar.M[1, 0] - M21_PRINTED)
    assert is_zero(four_bar.M[1, 0] - four_bar.M[0, 1])
    assert is_zero(four_bar.M[0, 1] - M12_PRINTED)


def test_misprint_eq30_C_offdiagonal(four_bar):
    """Eq. 30 prints ``C12 = C21 = -1/2 a s (qd1 - qd2)``: not Eq. 22, and a wrong ``C qd``.

    Its diagonal entries are right.
    """
    printed = sp.Matrix([[C11_PRINTED, C12_PRINTED, 0], [C21_PRINTED, C22_PRINTED, 0], [0, 0, 0]])
    assert not is_zero(four_bar.C[0, 1] - C12_PRINTED)
    assert not is_zero(four_bar.C[1, 0] - C21_PRINTED)
    assert is_zero(four_bar.C[0, 0] - C11_PRINTED)
    assert is_zero(four_bar.C[1, 1] - C22_PRINTED)
    velocity_terms = lagrange_velocity_terms(M_CORRECT, [q1, q2, q3], QD)
    assert not is_zero(printed * QD - velocity_terms)
    assert is_zero(four_bar.C * QD - velocity_terms)


# Quick-return mechanism: centres of mass written out from Eq. 36, constraints Eq. 37.
phi1, phi2, phi3 = sp.symbols("phi1 phi2 phi3")
l_BC, l_AB, l_AE, l_EF, l_AH = sp.symbols("l_BC l_AB l_AE l_EF l_AH")
m4, m5 = sp.symbols("m4 m5")
PHI = [phi1, phi2, phi3]
EQ_36 = [  # (mass, x, y, central inertia, angle) of links BC, AE, EF and sliders D, G
    (m1, l_BC / 2 * cos(phi1), l_BC / 2 * sin(phi1) + l_AB, I1, phi1),
    (m2, l_AE / 2 * cos(phi2), l_AE / 2 * sin(phi2), I2, phi2),
    (m3, l_AE * cos(phi2) + l_EF / 2 * cos(phi3), l_AE * sin(phi2) + l_EF / 2 * sin(phi3), I3, phi3),
    (m4, l_BC * cos(phi1), l_AB + l_BC * sin(phi1), 0, 0),
    (m5, l_AE * cos(phi2) + l_EF * cos(phi3), l_AH, 0, 0),
]
EQ_37 = sp.Matrix([l_AH - l_AE * sin(phi2) - l_EF * sin(phi3), l_AB * cos(phi2) - l_BC * sin(phi2 - phi1)])


def quick_return_reference() -> dict[str, sp.Matrix]:
    """M (Eq. 12), g and Phi_q computed here from Eqs. 36-37."""
    mass_matrix = sp.zeros(3, 3)
    potential = 0
    for mass, x, y, inertia, angle in EQ_36:
        translation = sp.Matrix([x, y]).jacobian(PHI)
        rotation = sp.Matrix([angle]).jacobian(PHI)
        mass_matrix += mass * translation.T * translation + inertia * rotation.T * rotation
        potential += mass * g * y
    return {"M": mass_matrix, "g": sp.Matrix([potential]).jacobian(PHI).T, "Phi_q": EQ_37.jacobian(PHI)}


@pytest.mark.parametrize("name", ["M", "g", "Phi_q"])
def test_quick_return_matrices(name):
    equations = derived("quick_return")
    assert equations.coordinates == tuple(PHI)
    actual, expected = getattr(equations, name), quick_return_reference()[name]
    assert actual.shape == expected.shape
    assert is_zero(actual - expected)


def test_quick_return_mass_matrix_closed_form():
    """The reference M of Eq. 36 written out by hand (guards the reference itself)."""
    expected = sp.Matrix([
        [I1 + m1 * l_BC**2 / 4 + m4 * l_BC**2, 0, 0],
        [0, I2 + (m2 / 4 + m3) * l_AE**2 + m5 * l_AE**2 * sin(phi2)**2,
         m3 * l_AE * l_EF / 2 * cos(phi2 - phi3) + m5 * l_AE * l_EF * sin(phi2) * sin(phi3)],
        [0, m3 * l_AE * l_EF / 2 * cos(phi2 - phi3) + m5 * l_AE * l_EF * sin(phi2) * sin(phi3),
         I3 + m3 * l_EF**2 / 4 + m5 * l_EF**2 * sin(phi3)**2],
    ])
    assert is_zero(quick_return_reference()["M"] - expected)
    assert is_zero(derived("quick_return").M - expected)
