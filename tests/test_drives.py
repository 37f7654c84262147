"""Drives (rheonomic constraints): kinematic analysis, inverse dynamics and simulation along
prescribed motions, against closed-form kinematics and independently derived reduced Lagrangians."""

import warnings

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

import kronlag
from kronlag import models

SLIDER = dict(l1=0.1, l2=0.35, m1=1.0, m2=2.0, m3=1.5, I1=0.01, I2=0.03, g=9.81, tau=0.0)
PENDULUM = dict(l1=0.5, l2=0.4, m1=1.0, m2=0.8, I1=1.0 * 0.5 ** 2 / 12, I2=0.8 * 0.4 ** 2 / 12, g=9.81)
T = sp.Symbol("t")


def slider_crank_reference(theta):
    """Slider-crank (crank angle ``theta``, an expression of t): closed-form q2, x and the
    reduced Lagrangian ``L(theta, thetad)``, written here from the geometry, not from kronlag."""
    l1, l2, m1, m2, m3, I1, I2, g = (sp.Float(SLIDER[k]) for k in ("l1", "l2", "m1", "m2", "m3", "I1", "I2", "g"))
    rod = sp.asin(-l1 * sp.sin(theta) / l2)
    x = l1 * sp.cos(theta) + l2 * sp.cos(rod)
    crank_centre = sp.Matrix([l1 / 2 * sp.cos(theta), l1 / 2 * sp.sin(theta)])
    rod_centre = sp.Matrix([l1 * sp.cos(theta) + l2 / 2 * sp.cos(rod), l1 * sp.sin(theta) + l2 / 2 * sp.sin(rod)])
    v1, v2 = crank_centre.diff(T), rod_centre.diff(T)
    kinetic = (m1 * v1.dot(v1) + I1 * theta.diff(T) ** 2 + m2 * v2.dot(v2) + I2 * rod.diff(T) ** 2
               + m3 * x.diff(T) ** 2) / 2
    potential = g * (m1 * crank_centre[1] + m2 * rod_centre[1])
    return rod, x, kinetic - potential


def crank_torque(theta):
    """``tau = d/dt dL/dthetad - dL/dtheta`` along ``theta(t)`` (a function of t), as a callable of t."""
    angle = sp.Function("theta")(T)
    _, _, lagrangian = slider_crank_reference(angle)
    rate = angle.diff(T)
    torque = lagrangian.diff(rate).diff(T) - lagrangian.diff(angle)
    return sp.lambdify(T, torque.subs(angle, theta).doit())


def driven_slider_crank(drive_target, motion):
    system = models.slider_crank()
    system.add_drive(drive_target, motion)
    return kronlag.derive(system).numeric(SLIDER)


@pytest.fixture(scope="module")
def crank_driven():
    motion = 5 * T + sp.sin(2 * T) / 3
    return driven_slider_crank("q1", motion), motion


def test_equations_of_a_drive_have_its_time_derivatives(crank_driven):
    model, _ = crank_driven
    equations = model.equations
    assert equations.rheonomic and equations.constraints_do_work
    assert equations.Phi_t[2] == -(5 + 2 * sp.cos(2 * T) / 3)
    assert equations.gamma[2] == -4 * sp.sin(2 * T) / 3  # -Phi_tt for q1 - theta(t)
    q = np.array([0.3, -0.08, 0.44])
    np.testing.assert_allclose(model.Phi_t(q, 0.2), [0, 0, -(5 + 2 * np.cos(0.4) / 3)], rtol=1e-14)


def test_kinematic_analysis_matches_the_closed_form_slider_crank(crank_driven):
    model, motion = crank_driven
    times = np.linspace(0, 2, 41)
    result = kronlag.kinematic_analysis(model, times, [0.0, 0.0, 0.45])
    assert result.success, result.message
    rod, x, _ = slider_crank_reference(motion)
    for k, expression in ((1, rod), (2, x)):
        for order, values in enumerate((result.q, result.qd, result.qdd)):
            exact = sp.lambdify(T, expression.diff(T, order))(times)
            np.testing.assert_allclose(values[:, k], exact, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(result.q[:, 0], 5 * times + np.sin(2 * times) / 3, atol=1e-12)


def test_coarse_output_times_are_followed_with_substeps(crank_driven):
    """Crank steps of 2.5 rad between outputs: sub-steps keep the assembly branch (x > 0)."""
    model, motion = crank_driven
    times = np.linspace(0, 2, 5)
    result = kronlag.kinematic_analysis(model, times, [0.0, 0.0, 0.45])
    assert result.success, result.message
    _, x, _ = slider_crank_reference(motion)
    np.testing.assert_allclose(result.q[:, 2], sp.lambdify(T, x)(times), rtol=1e-10)


@pytest.mark.parametrize("method", ["auto", "compiled", "ali3p", "projection", "baumgarte", "ggl"])
def test_simulated_drive_torque_is_the_reduced_lagrangian_torque(crank_driven, method):
    """Forward simulation of the fully driven slider-crank: q1 follows the drive, the drive's
    multiplier is minus the torque of the reduced Lagrangian, and energy balances with its work."""
    model, motion = crank_driven
    q0, qd0 = model.assemble([0.0, 0.0, 0.45], qd_guess=[5.0, 0.0, 0.0])
    times = np.linspace(0, 2, 401)
    trajectory = kronlag.simulate(model, (0, 2), q0, qd0, t_eval=times, method=method, rtol=1e-9, atol=1e-11)
    assert trajectory.success, trajectory.message
    np.testing.assert_allclose(trajectory.q[:, 0], 5 * times + np.sin(2 * times) / 3, atol=1e-9)
    reference = crank_torque(motion)(times)
    np.testing.assert_allclose(-trajectory.lam[:, 2], reference, atol=1e-7 * np.max(np.abs(reference)))
    np.testing.assert_allclose(trajectory.energy_balance, 0, atol=1e-6)
    assert np.max(np.abs(trajectory.nonconservative_work)) > 0.1  # the drive does work


def test_inverse_dynamics_reports_the_drive_torque(crank_driven):
    model, motion = crank_driven
    times = np.linspace(0, 2, 21)
    run = kronlag.inverse_dynamics(model, times, [0.0, 0.0, 0.45])
    assert run.success and run.actuated == ("drive q1",)
    reference = crank_torque(motion)(times)
    np.testing.assert_allclose(run.forces[:, 0], reference, rtol=1e-9, atol=1e-12)
    assert set(run.columns()) >= {"t", "q1", "xdd", "force_drive q1", "lambda[drive q1]"}


def test_a_piston_drive_with_the_crank_actuated():
    """Driven at the piston, actuated at the crank: the crank torque is the reduced Lagrangian's
    along the resulting crank motion; the drive's own force carries the same power."""
    motion = 0.38 + 0.04 * sp.sin(3 * T)
    model = driven_slider_crank("x", motion)
    times = np.linspace(0, 1, 21)
    crank = kronlag.inverse_dynamics(model, times, [0.9, -0.2, 0.38], actuated=["q1"])
    piston = kronlag.inverse_dynamics(model, times, [0.9, -0.2, 0.38])
    assert crank.success and piston.success
    assert np.all(crank.lam[:, 2] == 0)  # the drive is replaced by the actuator
    angle, rate, acceleration = sp.symbols("angle rate acceleration")
    function = sp.Function("theta")(T)
    _, _, lagrangian = slider_crank_reference(function)
    torque = (lagrangian.diff(function.diff(T)).diff(T) - lagrangian.diff(function)).subs(
        {function.diff(T, 2): acceleration}).subs({function.diff(T): rate}).subs({function: angle})
    reference = sp.lambdify((angle, rate, acceleration), torque)(crank.q[:, 0], crank.qd[:, 0], crank.qdd[:, 0])
    np.testing.assert_allclose(crank.forces[:, 0], reference, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(piston.forces[:, 0] * piston.qd[:, 2], crank.forces[:, 0] * crank.qd[:, 0],
                               rtol=1e-9, atol=1e-12)
    with pytest.raises(kronlag.ModelError, match="under-actuated: 0 actuator"):
        kronlag.inverse_dynamics(model, times, [0.9, -0.2, 0.38], actuated=[])
    with pytest.warns(kronlag.ActuationWarning, match="over-actuated"):
        both = kronlag.inverse_dynamics(model, times, [0.9, -0.2, 0.38], actuated=["q1", "x"])
    # the minimum-norm split still produces the motion: both actuators together do the same work
    np.testing.assert_allclose(np.sum(both.forces * both.qd[:, [0, 2]], axis=1), crank.forces[:, 0] * crank.qd[:, 0],
                               rtol=1e-8, atol=1e-10)


def test_kinematic_analysis_stops_before_a_dead_centre():
    """The piston pushed towards l1 + l2: the crank reaches its dead centre at t = 0.5, where the
    assembly branches meet; the analysis stops before it and says where."""
    model = driven_slider_crank("x", 0.4 + 0.1 * T)
    result = kronlag.kinematic_analysis(model, np.linspace(0, 0.6, 61), [0.5, -0.1, 0.4])
    assert not result.success
    assert "nearly singular" in result.message and "t = " in result.message and "q = " in result.message
    assert 0.3 < result.t[-1] < 0.5


def test_kinematic_analysis_refuses_a_mechanism_that_is_not_fully_driven():
    model = kronlag.derive(models.slider_crank()).numeric(SLIDER)
    with pytest.raises(kronlag.ModelError, match="not fully driven.*1 degree"):
        kronlag.kinematic_analysis(model, [0.0, 0.1], [0.0, 0.0, 0.45])
    with pytest.raises(kronlag.ModelError, match="no drives"):
        kronlag.inverse_dynamics(model, [0.0, 0.1], [0.0, 0.0, 0.45], actuated=["q1"])


def test_inverse_dynamics_rejects_a_motion_that_violates_the_constraints(crank_driven):
    model, _ = crank_driven
    free = kronlag.derive(models.slider_crank()).numeric(SLIDER)
    run = kronlag.inverse_dynamics(model, [0.0, 0.1], [0.0, 0.0, 0.45])
    q, qd, qdd = run.q[1], run.qd[1], run.qdd[1]
    free.inverse_dynamics(q, qd, qdd, actuated=["q1"])  # consistent: accepted
    for bad, level in (((q + [0, 0, 1e-3], qd, qdd), "position"), ((q, qd + [0, 0, 0.1], qdd), "velocity"),
                       ((q, qd, qdd + [0, 0, 1.0]), "acceleration")):
        with pytest.raises(ValueError, match=f"violates constraint 'pin x' at {level} level at t = 0"):
            free.inverse_dynamics(*bad, actuated=["q1"])


def test_a_partly_driven_double_pendulum_swings_like_the_reduced_equation():
    """q1 = 0.3 sin(2 t) prescribed, q2 free: the simulation matches the second Lagrange equation
    integrated alone (SymPy + SciPy), and the drive torque matches the first."""
    system = models.double_pendulum()
    system.add_drive("q1", 0.3 * sp.sin(2 * T))
    model = kronlag.derive(system).numeric(PENDULUM)
    q0, qd0 = model.assemble([0.0, 0.2], qd_guess=[0.6, 0.0])
    times = np.linspace(0, 3, 61)
    trajectory = kronlag.simulate(model, (0, 3), q0, qd0, t_eval=times, rtol=1e-10, atol=1e-12)
    assert trajectory.success, trajectory.message

    a, b = sp.Function("a")(T), sp.Function("b")(T)
    l1, l2, m1, m2, I1, I2, g = (PENDULUM[k] for k in ("l1", "l2", "m1", "m2", "I1", "I2", "g"))
    centre1 = sp.Matrix([l1 / 2 * sp.sin(a), -l1 / 2 * sp.cos(a)])
    centre2 = sp.Matrix([l1 * sp.sin(a) + l2 / 2 * sp.sin(b), -l1 * sp.cos(a) - l2 / 2 * sp.cos(b)])
    kinetic = (m1 * centre1.diff(T).dot(centre1.diff(T)) + m2 * centre2.diff(T).dot(centre2.diff(T))
               + I1 * a.diff(T) ** 2 + I2 * b.diff(T) ** 2) / 2
    lagrangian = kinetic - g * (m1 * centre1[1] + m2 * centre2[1])
    equations = [lagrangian.diff(x.diff(T)).diff(T) - lagrangian.diff(x) for x in (a, b)]
    prescribed = 0.3 * sp.sin(2 * T)
    states = sp.symbols("b0 b1 b2")
    second = [e.subs(a, prescribed).doit().subs({b.diff(T, 2): states[2]}).subs({b.diff(T): states[1]})
              .subs({b: states[0]}) for e in equations]
    # the second equation is linear in b'': b'' = -(its value at b'' = 0) / (its coefficient of b'')
    acceleration = sp.lambdify((T, *states[:2]), -second[1].subs(states[2], 0) / second[1].diff(states[2]))
    reference = solve_ivp(lambda time, y: [y[1], acceleration(time, *y)], (0, 3), [q0[1], qd0[1]], t_eval=times,
                          rtol=1e-12, atol=1e-13, method="DOP853")
    np.testing.assert_allclose(trajectory.q[:, 1], reference.y[0], atol=1e-7)
    torque = sp.lambdify((T, *states), second[0])(times, trajectory.q[:, 1], trajectory.qd[:, 1], trajectory.qdd[:, 1])
    np.testing.assert_allclose(-trajectory.lam[:, 0], torque, atol=1e-6 * np.max(np.abs(torque)))


def test_kinematics_of_named_points():
    """The engine's wrist point follows the closed-form piston position x(theta)."""
    engine = kronlag.model.builtin.load_example("slider_crank_engine", apply_drives=False)
    engine.system.add_drive("theta_crank", 20 * T)
    model = kronlag.derive(engine.system).numeric(engine.numeric_values())
    times = np.linspace(0, 0.3, 31)
    result = kronlag.kinematic_analysis(model, times, engine.guess_vectors()[0], points=["wrist"])
    assert result.success, result.message
    values = engine.numeric_values()
    l1, l2 = values["l1"], values["l2"]
    angle = 20 * T
    x = l1 * sp.cos(angle) + sp.sqrt(l2 ** 2 - (l1 * sp.sin(angle)) ** 2)
    for order, quantity in enumerate(("position", "velocity", "acceleration")):
        exact = sp.lambdify(T, x.diff(T, order))(times)
        np.testing.assert_allclose(result.points["wrist"][quantity][:, 0], exact, rtol=1e-9, atol=1e-9)
    assert "wrist.ax" in result.columns()


def test_cli_kinematics_command(tmp_path, capsys):
    from kronlag.app.cli import main

    target = tmp_path / "kinematics.csv"
    assert main(["kinematics", "slider_crank", "--drive", "q1=0.5 + 3*t", "--t-end", "0.5", "--points", "6",
                 "--output", str(target)]) == 0
    table = np.genfromtxt(target, delimiter=",", names=True)
    np.testing.assert_allclose(table["q1"], 0.5 + 3 * table["t"], atol=1e-12)
    assert "q1dd" in table.dtype.names and len(table) == 6


def test_a_time_dependent_constraint_in_a_model_file_drives_simulations(tmp_path):
    text = """
name = "driven pendulum"
parameters = {m = 1.0, l = 0.5, g = 9.81}
coordinates = ["x", "y"]
gravity = [0, "-g"]

[[bodies]]
name = "bob"
type = "point"
mass = "m"
position = ["x", "y"]

[[constraints]]
name = "rod"
expression = "x**2 + y**2 - l**2"

[[constraints]]
name = "drive"
expression = "x - l*sin(t)/2"

[initial]
q = {x = 0.0, y = -0.5}
"""
    path = tmp_path / "driven.toml"
    path.write_text(text)
    from kronlag.app.workflows import simulate_model

    model = kronlag.load_model(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.simulation.InitialStateWarning)
        trajectory = simulate_model(model, t_end=1.0, t_eval=np.linspace(0, 1, 11))
    assert trajectory.success, trajectory.message
    np.testing.assert_allclose(trajectory.q[:, 0], 0.25 * np.sin(trajectory.t), atol=1e-8)
    np.testing.assert_allclose(trajectory.q[:, 1], -np.sqrt(0.25 - trajectory.q[:, 0] ** 2), atol=1e-8)


def test_equilibrium_and_linearization_refuse_moving_drives(crank_driven):
    from kronlag.core.errors import EquilibriumError
    from kronlag.studies.equilibrium import equilibrium
    from kronlag.studies.linearization import linearize

    model, _ = crank_driven
    with pytest.raises(EquilibriumError, match="drives move there"):
        equilibrium(model, [0.0, 0.0, 0.45])
    with pytest.raises(ValueError, match="time-dependent constraints"):
        linearize(model, [0.0, 0.0, 0.45])


FIVE_BAR_CIRCLE = """
[[drives]]
name = "end effector x"
target = "end_effector_x"
motion = "0.05*cos(2*pi*t)"

[[drives]]
name = "end effector y"
target = "end_effector_y"
motion = "0.35 + 0.05*sin(2*pi*t)"
"""


def five_bar_circle_file(tmp_path):
    from kronlag.model.builtin import example_path

    text = example_path("five_bar").read_text()
    text = text[:text.index("[[drives]]")] + FIVE_BAR_CIRCLE
    path = tmp_path / "five_bar_circle.toml"
    path.write_text(text)
    return path


def test_five_bar_driven_at_its_end_effector_reports_the_motor_torques(tmp_path, capsys):
    """The motor power tau1 theta1d + tau2 theta2d equals the rate of the total energy
    (no other force does work), along the circle that the end-effector drives prescribe."""
    from kronlag.app.cli import main
    from kronlag.app.workflows import inverse_dynamics_along

    path = five_bar_circle_file(tmp_path)
    robot = kronlag.load_model(path, apply_drives=False)  # the drives go to inverse_dynamics_along
    times = np.linspace(0, 1, 401)
    run = inverse_dynamics_along(robot, robot.drives, times, actuated=["theta1", "theta2"])
    assert run.success, run.message
    assert run.actuated == ("theta1", "theta2")
    free = kronlag.derive(robot.system).numeric(robot.numeric_values())
    energy = np.array([free.kinetic_energy(q, qd) + free.potential_energy(q) for q, qd in zip(run.q, run.qd)])
    power = np.sum(run.forces * run.qd[:, :2], axis=1)
    rate = np.gradient(energy, times, edge_order=2)
    np.testing.assert_allclose(power[2:-2], rate[2:-2], atol=1e-4 * np.max(np.abs(power)))
    position = run.points["end_effector"]["position"]
    np.testing.assert_allclose(position, np.column_stack([0.05 * np.cos(2 * np.pi * times),
                                                          0.35 + 0.05 * np.sin(2 * np.pi * times)]), atol=1e-12)
    # and from the command line, with the actuators named
    target = tmp_path / "torques.csv"
    assert main(["inverse", str(path), "--t-end", "1", "--points", "11", "--actuated", "theta1,theta2",
                 "--output", str(target)]) == 0
    table = np.genfromtxt(target, delimiter=",", names=True)
    np.testing.assert_allclose(table["force_theta1"], run.forces[::40, 0], rtol=1e-9)


def test_a_time_dependent_velocity_constraint():
    """A point mass on a line whose speed is prescribed, xd = cos t (b = -cos t): x = x0 + sin t,
    and the constraint force is m xdd = -m sin t."""
    x, y = kronlag.coordinates("x y")
    m = sp.Symbol("m")
    system = kronlag.System([x, y], parameters=[m])
    system.add_body(kronlag.PointMass("bob", mass=m, position=(x, y)))
    system.add_nonholonomic_constraint(kronlag.speed_symbol(x) - sp.cos(T), name="conveyor")
    model = kronlag.derive(system).numeric({"m": 2.0})
    times = np.linspace(0, 2, 201)  # the work is integrated between outputs: fine enough for 1e-7
    trajectory = kronlag.simulate(model, (0, 2), [0.5, 0.0], [1.0, 0.3], t_eval=times, method="projection")
    assert trajectory.success, trajectory.message
    np.testing.assert_allclose(trajectory.q[:, 0], 0.5 + np.sin(times), atol=1e-8)
    np.testing.assert_allclose(trajectory.q[:, 1], 0.3 * times, atol=1e-8)
    np.testing.assert_allclose(-trajectory.mu[:, 0], -2.0 * np.sin(times), atol=1e-7)
    np.testing.assert_allclose(trajectory.energy_balance, 0, atol=1e-7)


def test_motions_that_stop_for_an_instant_pass_the_constraint_checks(capsys):
    """The five-bar file's drives swing both arms (speed zero at t = 0.25, 0.75); a state at rest
    computed with rounding is consistent too."""
    from kronlag.app.cli import main

    assert main(["inverse", "five_bar", "--points", "5"]) == 0
    assert "max |force|: theta1" in capsys.readouterr().out
    free = kronlag.derive(models.slider_crank()).numeric(SLIDER)
    q, qd = free.assemble([0.5, -0.1, 0.4])
    result = free.inverse_dynamics(q, qd + 1e-16, np.full(3, 1e-17), actuated=["q1"])
    # at rest the crank torque holds the weights: tau = dV/dtheta of the reduced potential
    angle = sp.Symbol("angle")
    _, _, lagrangian = slider_crank_reference(angle + 0 * T)  # at rest: L = -V(angle)
    np.testing.assert_allclose(result.forces, [float(-lagrangian.diff(angle).subs(angle, q[0]))], rtol=1e-9)
