"""Joint reactions (kronlag.reactions) against Newton's and Euler's laws for every body of a
mechanism, and against the closed form of a compound pendulum."""

import numpy as np
import pytest
import sympy as sp
from helpers import FOUR_BAR_VALUES, QUICK_RETURN_VALUES, four_bar_by_joints, quick_return_by_joints
from helpers import numeric_by_joints as numeric

import kronlag
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.numeric.reactions import joint_reaction
from kronlag.symbolic.calculus import time_derivative


def reactions_at(model, q, lam):
    """Every joint's (A, B, point, force, torque) at one state, world components."""
    result = []
    for joint in model.equations.system.joints:
        reaction = joint_reaction(model, joint.name, [0.0], q[None], lam[None])
        result.append((joint.body_a, joint.body_b, reaction.point[0], reaction.force[0], reaction.torque[0]))
    return result


def cross2(r, f):
    return r[0] * f[1] - r[1] * f[0]


@pytest.mark.parametrize("builder, values, guess", [
    (four_bar_by_joints, FOUR_BAR_VALUES, {"theta_crank": 1.0, "theta_coupler": 0.5, "theta_follower": 1.5}),
    (quick_return_by_joints, QUICK_RETURN_VALUES, {"theta_crank": 0.3, "theta_rocker": 1.4, "theta_link": 0.1}),
])
def test_newton_and_euler_hold_for_every_body_of_a_planar_mechanism(builder, values, guess):
    """m a_c = m g + sum of reactions; I theta_dd = torques about the centre of mass (+ the drive on the crank)."""
    model = numeric(builder, "four_bar" if builder is four_bar_by_joints else "quick_return")
    names = model.coordinate_names
    start = np.zeros(model.m)
    for name, value in guess.items():
        start[names.index(name)] = value
    q, qd = model.assemble(start, fixed={"theta_crank": guess["theta_crank"]}, qd_fixed={"theta_crank": 4.0})
    solution = model.forward_dynamics(q, qd)
    reactions = reactions_at(model, q, solution.lam)
    gravity = np.array([0.0, -values["g"]])
    for body in model.equations.system.bodies:
        mass = values[str(body.mass)]
        centre = np.array([q[names.index(f"{axis}_{body.name}")] for axis in "xy"])
        acceleration = np.array([solution.qdd[names.index(f"{axis}_{body.name}")] for axis in "xy"])
        force, moment = mass * gravity, values["tau"] if body.name == "crank" else 0.0
        for body_a, body_b, point, f, torque in reactions:
            sign = 1 if body_b == body.name else -1 if body_a == body.name else 0
            force = force + sign * f
            moment += sign * (torque[0] + cross2(point - centre, f))
        assert np.allclose(mass * acceleration, force, atol=1e-9 * np.max(np.abs(force)) + 1e-12)
        if isinstance(body, kronlag.PlanarBody):
            angular = solution.qdd[names.index(f"theta_{body.name}")]
            assert np.isclose(values[str(body.inertia)] * angular, moment, atol=1e-9 * mass * 10)


def test_compound_pendulum_pivot_reaction_closed_form():
    """Uniform bar of length L pivoted at one end, at angle phi from the downward vertical with rate w:
    the pivot pushes the bar with m (g cos phi + w^2 L/2) towards the pivot and m g sin phi / 4 along
    the direction of increasing phi; no couple."""
    m, L, g = sp.symbols("m L g")
    system = mechanism([free_body("bar", mass=m, inertia=m * L ** 2 / 12)], parameters=[m, L, g], gravity=(0, -g))
    system.add_joint("revolute", "ground", "bar", at_b=(-L / 2, 0), name="pivot")
    model = kronlag.derive(system).numeric({"m": 2.0, "L": 0.9, "g": 9.81}, backend="python")
    for phi, rate in [(0.4, 1.5), (-1.2, 0.3), (2.5, -2.0)]:
        theta = phi - np.pi / 2  # the bar's angle from the x-axis
        q, qd = model.assemble([0, 0, theta], fixed={"theta_bar": theta}, qd_fixed={"theta_bar": rate})
        lam = model.forward_dynamics(q, qd).lam
        reaction = joint_reaction(model, "pivot", [0.0], q[None], lam[None])
        outward = np.array([np.sin(phi), -np.cos(phi)])  # from the pivot to the centre of mass
        along = np.array([np.cos(phi), np.sin(phi)])
        force = reaction.force[0]
        assert np.isclose(-force @ outward, 2.0 * (9.81 * np.cos(phi) + rate ** 2 * 0.45), rtol=1e-10)
        assert np.isclose(force @ along, 2.0 * 9.81 * np.sin(phi) / 4, rtol=1e-10, atol=1e-12)
        assert reaction.torque[0, 0] == pytest.approx(0.0, abs=1e-12)
        assert np.allclose(reaction.point[0], [0, 0], atol=1e-12)


def test_spatial_revolute_reaction_satisfies_newton_and_euler():
    """A body hinged to the ground about a tilted axis: m a_c = m g + F and
    dH_c/dt = R (I w_b' + w_b x I w_b) = T + (P - r_c) x F, world components."""
    m, g = sp.symbols("m g")
    inertia = sp.Matrix([[0.05, 0.01, 0], [0.01, 0.07, 0.002], [0, 0.002, 0.03]])
    body = free_body("b", mass=m, inertia=inertia, dimension=3, rotation="xyz", simplify=False)
    system = mechanism([body], parameters=[m, g], gravity=(0, 0, -g))
    axis = (1 / 3, 2 / 3, 2 / 3)
    system.add_joint("revolute", "ground", "b", at_a=(0.1, 0, 0.2), at_b=(0.2, -0.1, 0.3), axis=axis,
                     name="hinge")
    model = kronlag.derive(system).numeric({"m": 1.5, "g": 9.81}, backend="python")
    q, qd = model.assemble(np.zeros(6), qd_guess=[0, 0, 0, 1.0, 2.0, 2.0])
    q, qd = model.assemble(q + [0, 0, 0, 0.2, 0.4, 0.4], qd_guess=qd)  # a turned, moving state
    solution = model.forward_dynamics(q, qd)
    reaction = joint_reaction(model, "hinge", [0.0], q[None], solution.lam[None])
    F, T, P = reaction.force[0], reaction.torque[0], reaction.point[0]
    assert np.allclose(1.5 * solution.qdd[:3], 1.5 * np.array([0, 0, -9.81]) + F, atol=1e-9)

    coordinates = list(system.coordinates)
    speeds = [kronlag.speed_symbol(x) for x in coordinates]
    R = sp.Matrix(body.body.rotation)
    spin = R.T * time_derivative(R, coordinates, speeds)
    omega = sp.Matrix([spin[2, 1], spin[0, 2], spin[1, 0]])
    omega_dot = time_derivative(omega, coordinates + speeds,
                                speeds + [kronlag.acceleration_symbol(x) for x in coordinates])
    state = dict(zip(coordinates, q)) | dict(zip(speeds, qd)) | {
        kronlag.acceleration_symbol(x): v for x, v in zip(coordinates, solution.qdd)}
    Rn = np.array(R.subs(state), dtype=float)
    w, w_dot = np.array(omega.subs(state), dtype=float).ravel(), np.array(omega_dot.subs(state), dtype=float).ravel()
    J = np.array(inertia, dtype=float)
    torque_rate = Rn @ (J @ w_dot + np.cross(w, J @ w))
    assert np.allclose(torque_rate, T + np.cross(P - q[:3], F), atol=1e-9)
    body_frame = joint_reaction(model, "hinge", [0.0], q[None], solution.lam[None], frame="body")
    assert np.allclose(body_frame.force[0], Rn.T @ F) and np.allclose(body_frame.torque[0], Rn.T @ T)
    # a hinge transmits no couple about its axis
    assert T @ (np.array(axis) / np.linalg.norm(axis)) == pytest.approx(0.0, abs=1e-10)


def test_trajectory_reactions_by_name_and_as_columns(tmp_path):
    model = numeric(four_bar_by_joints, "four_bar")
    start = np.zeros(model.m)
    start[[2, 5, 8]] = [1.0, 0.5, 1.5]
    q, qd = model.assemble(start, fixed={"theta_crank": 1.0}, qd_fixed={"theta_crank": 6.0})
    trajectory = kronlag.simulate(model, (0, 0.2), q, qd, method="projection", t_eval=np.linspace(0, 0.2, 5))
    reaction = trajectory.reaction("crank_coupler_revolute")
    assert reaction.force.shape == (5, 2) and reaction.torque.shape == (5, 1)
    columns = trajectory.columns()
    assert np.array_equal(columns["crank_coupler_revolute.Fy"], reaction.force[:, 1])
    assert "ground_follower_revolute.Mz" in columns
    trajectory.to_csv(tmp_path / "run.csv")
    header = (tmp_path / "run.csv").read_text().splitlines()[0].split(",")
    assert "ground_crank_revolute.Fx" in header
    body = trajectory.reaction("crank_coupler_revolute", frame="body")
    theta = trajectory.q[:, model.coordinate_names.index("theta_coupler")]
    # body components: the world force turned back by the coupler's angle
    assert np.allclose(body.force[:, 0], np.cos(theta) * reaction.force[:, 0] + np.sin(theta) * reaction.force[:, 1])
    with pytest.raises(KeyError, match="no joint named 'crank_rod'"):
        trajectory.reaction("crank_rod")
    with pytest.raises(ValueError, match="frame must be"):
        trajectory.reaction("crank_coupler_revolute", frame="crank")


def test_reaction_plot_has_a_row_per_joint(tmp_path):
    model = numeric(four_bar_by_joints, "four_bar")
    start = np.zeros(model.m)
    start[[2, 5, 8]] = [1.0, 0.5, 1.5]
    q, qd = model.assemble(start, fixed={"theta_crank": 1.0}, qd_fixed={"theta_crank": 6.0})
    trajectory = kronlag.simulate(model, (0, 0.2), q, qd, method="projection", t_eval=np.linspace(0, 0.2, 5))
    figure = trajectory.plot_reactions(path=tmp_path / "reactions.png")
    assert len(figure.axes) == 2 * len(model.equations.system.joints)
    assert (tmp_path / "reactions.png").stat().st_size > 10_000
    assert len(trajectory.plot_reactions(["crank_coupler_revolute"], frame="body").axes) == 2
    with pytest.raises(ValueError, match="no joint named 'crank'"):
        trajectory.plot_reactions(["crank"])
