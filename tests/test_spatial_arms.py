"""Spatial serial arms with the default settings: the UR5 and Panda built-in models, and the
angular-velocity Jacobian of a RotationSequence.

References: Pinocchio's CRBA / RNEA on the same DH and inertial data (an independent
implementation, skipped where ``pin`` is not installed); identities that hold for any
mechanical system (M symmetric positive definite, g = dV/dq, C qd = dM/dt qd - dT/dq); and
``vee(R^T dR/dq)`` of the composed matrix."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag import RigidBody, RotationSequence, System, models

ARMS = ("ur5", "panda")


@functools.cache
def arm(name: str) -> kronlag.NumericModel:
    """The arm derived with the defaults, numeric with g = 9.81 and no joint torques."""
    system = models.BUILTIN_MODELS[name]()
    values = {p.name: 0.0 for p in system.parameters} | {"g": 9.81}
    return kronlag.derive(system).numeric(values, backend="python")


def random_states(m: int, count: int = 4, seed: int = 3):
    rng = np.random.default_rng(seed)
    return [rng.uniform(-np.pi, np.pi, (2, m)) for _ in range(count)]


@pytest.mark.parametrize("name", ARMS)
def test_mass_matrix_is_symmetric_positive_definite(name):
    model = arm(name)
    for q, _ in random_states(model.m):
        M = model.M(q)
        np.testing.assert_allclose(M, M.T, rtol=0, atol=1e-14)
        assert np.linalg.eigvalsh(M).min() > 0


@pytest.mark.parametrize("name", ARMS)
def test_gravity_is_the_gradient_of_the_potential(name):
    model, step = arm(name), 1e-6
    for q, _ in random_states(model.m):
        gradient = [(model.potential_energy(q + step * e) - model.potential_energy(q - step * e)) / (2 * step)
                    for e in np.eye(model.m)]
        np.testing.assert_allclose(model.g(q), gradient, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("name", ARMS)
def test_velocity_terms_are_the_lagrangian_ones(name):
    """C qd = (dM/dt) qd - dT/dq, both by central differences of M."""
    model, step = arm(name), 1e-6
    for q, qd in random_states(model.m):
        dM = [(model.M(q + step * e) - model.M(q - step * e)) / (2 * step) for e in np.eye(model.m)]
        M_dot = sum(derivative * rate for derivative, rate in zip(dM, qd))
        dT_dq = np.array([qd @ derivative @ qd / 2 for derivative in dM])
        np.testing.assert_allclose(model.Cqd(q, qd), M_dot @ qd - dT_dq, rtol=1e-6, atol=1e-6)


def _pinocchio_arm(name: str):
    """The arm rebuilt in Pinocchio from the DH table and the inertial data of kronlag.models."""
    pin = pytest.importorskip("pinocchio")
    system = models.BUILTIN_MODELS[name]()
    convention = {"ur5": "standard", "panda": "modified"}[name]
    table = {"ur5": [(0, 0.089159, np.pi / 2), (-0.425, 0, 0), (-0.39225, 0, 0), (0, 0.10915, np.pi / 2),
                     (0, 0.09465, -np.pi / 2), (0, 0.0823, 0)],
             "panda": [(0, 0.333, 0), (0, 0, -np.pi / 2), (0, 0.316, np.pi / 2), (0.0825, 0, np.pi / 2),
                       (-0.0825, 0.384, -np.pi / 2), (0, 0, np.pi / 2), (0.088, 0, np.pi / 2)]}[name]

    def rx(angle):
        c, s = np.cos(angle), np.sin(angle)
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    def se3(rotation, translation):
        return pin.SE3(np.asarray(rotation, float), np.asarray(translation, float))

    model = pin.Model()
    parent, after_joint = 0, pin.SE3.Identity()
    for i, (a, d, alpha) in enumerate(table):
        if convention == "standard":  # T_i = T_{i-1} Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)
            joint_placement, link = after_joint, se3(rx(alpha), [a, 0, d])
        else:  # T_i = T_{i-1} Rx(alpha_i) Tx(a_i) Rz(q_i) Tz(d_i)
            joint_placement, link = after_joint * se3(rx(alpha), [a, 0, 0]), se3(np.eye(3), [0, 0, d])
        parent = model.addJoint(parent, pin.JointModelRZ(), joint_placement, f"joint{i + 1}")
        body = system.body(f"link{i + 1}")  # mass and central inertia: the published data
        inertia = pin.Inertia(float(body.mass), np.array(_CENTRES[name][i], float),
                              np.array(body.inertia.evalf(), float))
        model.appendBodyToJoint(parent, inertia, link)
        after_joint = link
    model.gravity.linear = np.array([0, 0, -9.81])
    return pin, model


_CENTRES = {
    "ur5": [(0, -0.02561, 0.00193), (0.2125, 0, 0.11336), (0.15, 0, 0.0265), (0, -0.0018, 0.01634),
            (0, 0.0018, 0.01634), (0, 0, -0.001159)],
    "panda": [(0.003875, 0.002081, -0.04762), (-0.003141, -0.02872, 0.003495), (0.027518, 0.039252, -0.066502),
              (-0.05317, 0.104419, 0.027454), (-0.011953, 0.041065, -0.038437), (0.060149, -0.014117, -0.010517),
              (0.010517, -0.004252, 0.061597)],
}


@pytest.mark.parametrize("name", ARMS)
def test_dynamics_match_pinocchio(name):
    pin, reference = _pinocchio_arm(name)
    data = reference.createData()
    model = arm(name)
    for q, qd in random_states(model.m):
        M = pin.crba(reference, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        np.testing.assert_allclose(model.M(q), M, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(model.g(q), pin.computeGeneralizedGravity(reference, data, q),
                                   rtol=1e-9, atol=1e-10)
        bias = pin.rnea(reference, data, q, qd, np.zeros(model.m))  # C qd + g
        np.testing.assert_allclose(model.Cqd(q, qd) + model.g(q), bias, rtol=1e-9, atol=1e-10)


def _vee_jacobian_numeric(rotation: sp.Matrix, q: list, point: dict) -> np.ndarray:
    """Column k = vee(R^T dR/dq_k), evaluated at ``point`` without any simplification."""
    columns = []
    R = np.array(rotation.subs(point).evalf(), float)
    for qk in q:
        dR = np.array(rotation.diff(qk).subs(point).evalf(), float)
        skew = R.T @ dR
        columns.append([skew[2, 1], skew[0, 2], skew[1, 0]])
    return np.array(columns).T


@pytest.mark.parametrize("factors", [
    [("z", "a"), ("y", "b"), ("x", "c")],
    [("z", "a"), ("x", "b"), ("z", "c")],
    [("x", "a + b"), ("z", "pi/3"), ("y", "2*c"), ((sp.Rational(3, 5), 0, sp.Rational(4, 5)), "a*c")],
])
def test_sequence_jacobian_equals_vee_of_rotation_derivative(factors):
    a, b, c = q = list(sp.symbols("a b c"))
    symbols = {"a": a, "b": b, "c": c, "pi": sp.pi}
    sequence = RotationSequence([(axis, sp.sympify(angle, locals=symbols)) for axis, angle in factors])
    system = System(q)
    system.add_body(RigidBody("body", mass=1, inertia=sp.diag(1, 2, 3), position=(a, b, c), rotation=sequence))
    from_axes = kronlag.symbolic.derivation._rotation_jacobian(system.bodies[0], [kronlag.symbolic.derivation.se.Symbol(s.name)
                                                                         for s in q])
    rng = np.random.default_rng(11)
    for _ in range(3):
        point = dict(zip(q, rng.uniform(-2, 2, 3)))
        numeric = np.array(sp.Matrix(3, 3, [sp.sympify(e) for e in from_axes]).subs(point).evalf(), float)
        np.testing.assert_allclose(numeric, _vee_jacobian_numeric(sequence.matrix, q, point), atol=1e-12)


def test_sequence_body_derives_like_the_trigsimped_matrix():
    """The heavy top written as a RotationSequence gives the same M and C as the matrix form
    whose J_R is trigsimp'd."""
    psi, theta, phi = q = kronlag.coordinates("psi theta phi")
    m, l, g = sp.symbols("m l g")

    def top(rotation):
        system = System(q, parameters=[m, l, g], gravity=(0, 0, -g))
        matrix = rotation.matrix if isinstance(rotation, RotationSequence) else rotation
        system.add_body(RigidBody("top", mass=m, inertia=sp.diag(1, 1, 2), position=matrix * sp.Matrix([0, 0, l]),
                                  rotation=rotation))
        return kronlag.derive(system)

    sequence = RotationSequence([("z", psi), ("x", theta), ("z", phi)])
    from_axes, from_matrix = top(sequence), top(sp.Matrix(sequence.matrix))
    for name in ("M", "C", "g"):
        difference = (getattr(from_axes, name) - getattr(from_matrix, name)).applyfunc(sp.trigsimp)
        assert difference == sp.zeros(*difference.shape), name


def test_large_matrix_rotation_derives_without_unbounded_simplification():
    """A rotation given as a plain matrix product of 6 joint rotations (simplify=True by
    default): entries too large for trigsimp are kept, and J_R is still vee(R^T dR/dq)."""
    q = kronlag.coordinates("q1 q2 q3 q4 q5 q6")
    rotation = RotationSequence([(axis, angle) for axis, angle in zip("zyyxzx", q)]).matrix
    system = System(q)
    system.add_body(RigidBody("tip", mass=1, inertia=sp.eye(3), position=(0, 0, 0), rotation=sp.Matrix(rotation)))
    jacobian = kronlag.symbolic.derivation._rotation_jacobian(system.bodies[0],
                                                     [kronlag.symbolic.derivation.se.Symbol(s.name) for s in q])
    point = dict(zip(q, np.random.default_rng(2).uniform(-2, 2, 6)))
    numeric = np.array(sp.Matrix(3, 6, [sp.sympify(e) for e in jacobian]).subs(point).evalf(), float)
    np.testing.assert_allclose(numeric, _vee_jacobian_numeric(sp.Matrix(rotation), list(q), point), atol=1e-12)


def test_unactuated_ur5_conserves_energy():
    """The UR5 falling from its example pose with no joint torques: E = T + V is constant."""
    from kronlag.app.workflows import simulate_model
    from kronlag.model.builtin import load_example

    trajectory = simulate_model(load_example("ur5"))
    assert trajectory.success
    energy = trajectory.kinetic_energy + trajectory.potential_energy
    assert trajectory.kinetic_energy.max() > 10.0  # it does fall
    assert np.abs(energy - energy[0]).max() < 1e-6 * trajectory.kinetic_energy.max()
