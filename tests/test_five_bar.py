"""The five-bar parallel robot (kronlag.models.five_bar) against a hand derivation of its
kinematics: the closed-form position of the end effector (intersection of two circles), its
Jacobian from the loop-closure equations, the static motor torques by virtual work
(tau = dV/dtheta - J^T F) and the mass matrix reduced to the base angles."""

import numpy as np
import pytest

import kronlag
from kronlag.model.builtin import load_example

VALUES = load_example("five_bar", apply_drives=False).numeric_values()
D, L1, L2, M1, M2, I1, I2, G = (VALUES[name] for name in ("d", "l1", "l2", "m1", "m2", "I1", "I2", "g"))
#: Base angles (theta1, theta2) in the working mode of the shipped file: elbows out, end effector above.
POSES = [(2 * np.pi / 3, np.pi / 3), (2.3, 1.3), (1.8, 0.4), (2.9, 1.2)]
ACTUATED = ("theta1", "theta2")


def elbows(theta):
    """A_i = base_i + l1 (cos theta_i, sin theta_i), shape (2, 2)."""
    bases = np.array([[-D / 2, 0.0], [D / 2, 0.0]])
    return bases + L1 * np.column_stack([np.cos(theta), np.sin(theta)])


def end_effector(theta):
    """P: the intersection of the circles of radius l2 about the elbows, left of A1 -> A2."""
    a1, a2 = elbows(theta)
    chord = a2 - a1
    half = np.linalg.norm(chord) / 2
    normal = np.array([-chord[1], chord[0]]) / np.linalg.norm(chord)
    return (a1 + a2) / 2 + np.sqrt(L2 ** 2 - half ** 2) * normal


def jacobian(theta):
    """dP/dtheta from |P - A_i|^2 = l2^2: (P - A_i) . (dP - dA_i) = 0, dA_i = l1 (-sin, cos) dtheta_i."""
    p, arms = end_effector(theta), elbows(theta)
    rows = p - arms                                    # u_i = P - A_i
    crank = L1 * np.column_stack([-np.sin(theta), np.cos(theta)])
    return np.linalg.solve(rows, np.diag(np.einsum("ij,ij->i", rows, crank)))


def reduced_mass_matrix(theta):
    """sum m J_c^T J_c + I J_w^T J_w over the four links, with hand-derived velocity Jacobians (2 x 2)."""
    p, arms, jp = end_effector(theta), elbows(theta), jacobian(theta)
    crank = L1 * np.column_stack([-np.sin(theta), np.cos(theta)])
    mass = np.zeros((2, 2))
    for i in range(2):
        unit = np.eye(2)[i]
        centre = np.outer(crank[i] / 2, unit)          # proximal centre: l1/2 along the link
        mass += M1 * centre.T @ centre + I1 * np.outer(unit, unit)
        elbow = np.outer(crank[i], unit)               # dA_i/dtheta
        direction = (p - arms[i]) / L2
        turn = np.array([-direction[1], direction[0]]) @ (jp - elbow) / L2   # d(phi_i)/dtheta
        distal_centre = (elbow + jp) / 2
        mass += M2 * distal_centre.T @ distal_centre + I2 * np.outer(turn, turn)
    return mass


def potential_energy(theta):
    """g (m1 (y_c1 + y_c2) + m2 (y of the distal centres)) from the closed-form positions."""
    arms, p = elbows(theta), end_effector(theta)
    return G * (M1 * np.sum(arms[:, 1]) / 2 + M2 * np.sum(arms[:, 1] + p[1]) / 2)


def assembled(model, theta):
    """Coordinates at the base angles theta, from the hand-derived pose as the guess."""
    p, arms = end_effector(theta), elbows(theta)
    angles = np.arctan2(p[1] - arms[:, 1], p[0] - arms[:, 0])
    centres = (arms + p) / 2
    guess = [*theta, *centres[0], angles[0], *centres[1], angles[1]]
    q, _ = model.assemble(guess, fixed=dict(zip(ACTUATED, theta)))
    return q


def velocity_transformation(model, q):
    """R (m, 2): qd = R thetad on the constraint manifold, from Phi_q R = 0 with R[:2] = I."""
    phi_q = model.Phi_q(q)
    dependent = -np.linalg.solve(phi_q[:, 2:], phi_q[:, :2])
    return np.vstack([np.eye(2), dependent])


@pytest.fixture(scope="module")
def model():
    return kronlag.derive(kronlag.models.five_bar()).numeric(VALUES, backend="python")


def test_structure_and_names():
    system = kronlag.models.five_bar()
    assert [q.name for q in system.coordinates][:2] == ["theta1", "theta2"]
    assert system.degrees_of_freedom == 2 and len(system.coordinates) == 8
    assert [joint.name for joint in system.joints] == ["elbow_1", "elbow_2", "tip"]
    assert {"end_effector", "base_1", "base_2", "elbow_1", "elbow_2"} <= set(system.points)


@pytest.mark.parametrize("theta", POSES)
def test_end_effector_is_where_the_circles_meet(model, theta):
    q = assembled(model, np.array(theta))
    np.testing.assert_allclose(model.point_position("end_effector", q), end_effector(np.array(theta)), atol=1e-12)


@pytest.mark.parametrize("theta", POSES)
def test_static_torques_for_a_load_at_the_end_effector_are_minus_J_transpose_F(theta):
    """Virtual work at rest without gravity: tau . dtheta + F . dP = 0 for every admissible motion."""
    theta = np.array(theta)
    load = np.array([3.0, -20.0])                      # N, a mostly vertical load on the end effector
    system = kronlag.models.five_bar()
    system.add_force(system.point("end_effector").position, tuple(load), name="load")
    model = kronlag.derive(system).numeric(VALUES | {"g": 0.0}, backend="python")
    q = assembled(model, theta)
    zero = np.zeros(model.m)
    torques = model.inverse_dynamics(q, zero, zero, actuated=ACTUATED).forces
    np.testing.assert_allclose(torques, -jacobian(theta).T @ load, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("theta", POSES)
def test_static_torques_against_gravity_are_the_gradient_of_the_potential(model, theta):
    theta = np.array(theta)
    q = assembled(model, theta)
    zero = np.zeros(model.m)
    torques = model.inverse_dynamics(q, zero, zero, actuated=ACTUATED).forces
    step = 1e-6
    gradient = [(potential_energy(theta + step * e) - potential_energy(theta - step * e)) / (2 * step)
                for e in np.eye(2)]
    np.testing.assert_allclose(torques, gradient, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("theta", POSES)
def test_mass_matrix_on_the_constraint_manifold_is_the_hand_reduced_one(model, theta):
    theta = np.array(theta)
    q = assembled(model, theta)
    mass = model.M(q)
    np.testing.assert_allclose(mass, mass.T, atol=1e-15)
    transformation = velocity_transformation(model, q)
    reduced = transformation.T @ mass @ transformation
    np.testing.assert_allclose(reduced, reduced_mass_matrix(theta), rtol=1e-10)
    assert np.all(np.linalg.eigvalsh(reduced) > 0)


def test_distal_link_is_in_equilibrium_under_its_joint_forces_and_weight(model):
    """Held at rest: elbow_2 (proximal_2 on distal_2) + tip (distal_1 on distal_2) + weight = 0, and the
    moments about the centre of distal_2 balance (revolute joints transmit no couple)."""
    theta = np.array(POSES[1])
    q = assembled(model, theta)
    zero = np.zeros(model.m)
    lam = model.inverse_dynamics(q, zero, zero, actuated=ACTUATED).lam
    system = model.equations.system
    from kronlag.numeric.reactions import joint_reaction

    elbow, tip = (joint_reaction(model, name, [0.0], q[None], lam[None]) for name in ("elbow_2", "tip"))
    assert [joint.body_b for joint in system.joints if joint.name in ("elbow_2", "tip")] == ["distal_2"] * 2
    np.testing.assert_allclose(elbow.force[0] + tip.force[0] + [0, -M2 * G], 0, atol=1e-12)
    centre = (elbows(theta)[1] + end_effector(theta)) / 2

    def moment(reaction):
        r = reaction.point[0] - centre
        return r[0] * reaction.force[0, 1] - r[1] * reaction.force[0, 0]

    assert abs(moment(elbow) + moment(tip)) < 1e-12
    np.testing.assert_allclose(np.vstack([elbow.torque, tip.torque]), 0, atol=1e-12)
