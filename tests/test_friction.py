"""Joint friction from the reactions (issue 18.2): kronlag.Friction on revolute and prismatic joints,
checked against closed forms through the Python API and model files."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from helpers import (
    PIN_FRICTION_PENDULUM_VALUES,
    pin_friction_pendulum,
    pin_friction_pendulum_file,
)

import kronlag
from kronlag.app.workflows import initial_state, numeric_model
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.numeric.friction import friction_columns
from kronlag.numeric.reactions import joint_reaction

G = 9.81
EXAMPLE = "examples/slider_crank_friction.toml"
FOUR_BAR = "examples/four_bar_friction.toml"


def _backends() -> list[str]:
    from kronlag.numeric import codegen

    return ["python", "c"] if codegen.c_compiler() else ["python"]


# -- a block on an inclined prismatic joint --------------------------------------------------------

def _incline(alpha: float, mu: float, v_eps: float):
    m, g = sp.symbols("m g")
    system = mechanism([free_body("block", mass=m, inertia=m / 6)], parameters=[m, g], gravity=(0, -g))
    system.add_joint("prismatic", "ground", "block", axis=(np.cos(alpha), -np.sin(alpha)), name="guide",
                     friction=kronlag.Friction(kinetic=mu, smoothing_velocity=v_eps))
    return system


INCLINE_FILE = """
name = "incline"
coordinates = ["x", "y", "th"]
gravity = [0, "-g"]

[parameters]
m = {value = 2.0, unit = "kg"}
g = {value = 9.81, unit = "m/s^2"}
alpha = {value = 0.5, unit = "rad"}
mu_k = 0.2
I = {value = 0.333, unit = "kg*m^2"}

[[bodies]]
name = "block"
type = "planar"
mass = "m"
inertia = "I"
position = ["x", "y"]
angle = "th"

[[joints]]
name = "guide"
type = "prismatic"
body_a = "ground"
body_b = "block"
axis = ["cos(alpha)", "-sin(alpha)"]
friction = {kinetic = "mu_k", smoothing_velocity = 1e-6}
"""


def _incline_from_file(tmp_path, text: str = INCLINE_FILE):
    path = tmp_path / "incline.toml"
    path.write_text(text)
    model_file = kronlag.load_model(path)
    return kronlag.derive(model_file.system).numeric(model_file.numeric_values())


def _slide(model, alpha: float, v0: float, t_end: float):
    """The motion from the origin with speed ``v0`` down the slope; returns (trajectory, distance)."""
    direction = np.array([np.cos(alpha), -np.sin(alpha)])
    trajectory = kronlag.simulate(model, (0, t_end), np.zeros(3), [*(v0 * direction), 0.0], rtol=1e-11, atol=1e-12,
                                  t_eval=np.linspace(0, t_end, 6))
    return trajectory, trajectory.q[:, :2] @ direction


@pytest.mark.parametrize("backend", _backends())
def test_sliding_block_accelerates_by_the_closed_form(backend):
    """Sliding down (v >> v_eps): a = g (sin alpha - mu_k cos alpha); the normal load read from the
    reaction is m g cos alpha."""
    alpha, mu = 0.5, 0.2
    model = kronlag.derive(_incline(alpha, mu, 1e-6)).numeric({"m": 2.0, "g": G}, backend=backend)
    acceleration = G * (np.sin(alpha) - mu * np.cos(alpha))
    trajectory, distance = _slide(model, alpha, 1.0, 0.5)
    assert trajectory.success
    np.testing.assert_allclose(distance, trajectory.t + acceleration * trajectory.t ** 2 / 2, rtol=1e-9, atol=1e-12)
    columns = friction_columns(model, trajectory.t, trajectory.q, trajectory.qd, trajectory.lam)
    np.testing.assert_allclose(columns["guide.normal_load"], 2.0 * G * np.cos(alpha), rtol=1e-10)
    np.testing.assert_allclose(columns["guide.friction"], mu * 2.0 * G * np.cos(alpha), rtol=1e-10)
    reaction = joint_reaction(model, "guide", trajectory.t, trajectory.q, trajectory.lam)
    np.testing.assert_allclose(np.linalg.norm(reaction.force, axis=1), 2.0 * G * np.cos(alpha), rtol=1e-10)


def test_sliding_block_from_a_model_file(tmp_path):
    model = _incline_from_file(tmp_path)
    acceleration = G * (np.sin(0.5) - 0.2 * np.cos(0.5))
    trajectory, distance = _slide(model, 0.5, 1.0, 0.5)
    np.testing.assert_allclose(distance, trajectory.t + acceleration * trajectory.t ** 2 / 2, rtol=1e-9, atol=1e-12)


def test_block_below_the_friction_angle_creeps_at_the_smooth_laws_speed():
    """tan alpha < mu_k: the smooth law holds the block where mu_k tanh(v / v_eps) = tan alpha, i.e. at the
    creep speed v* = v_eps artanh(tan alpha / mu_k) (the smooth law's stand-in for sticking)."""
    alpha, mu, v_eps = 0.1, 0.3, 1e-4
    model = kronlag.derive(_incline(alpha, mu, v_eps)).numeric({"m": 2.0, "g": G})
    trajectory, _ = _slide(model, alpha, 0.01, 0.2)
    speed = trajectory.qd[-1, :2] @ np.array([np.cos(alpha), -np.sin(alpha)])
    assert speed == pytest.approx(v_eps * np.arctanh(np.tan(alpha) / mu), rel=1e-6)


# -- a pendulum with pin friction ------------------------------------------------------------------

PENDULUM_FILE = pin_friction_pendulum_file('{kinetic = "mu", radius = "r", smoothing_velocity = 1e-3}')


def _pendulum(tmp_path, *, from_file: bool):
    if from_file:
        path = tmp_path / "pendulum.toml"
        path.write_text(PENDULUM_FILE)
        model_file = kronlag.load_model(path)
        return kronlag.derive(model_file.system).numeric(model_file.numeric_values())
    system = pin_friction_pendulum(smoothing_velocity=1e-3)
    return kronlag.derive(system).numeric(PIN_FRICTION_PENDULUM_VALUES)


def _swing(model, angle: float, t_end: float, samples: int, rate: float = 0.0):
    """From ``angle`` off the downward vertical at ``rate``."""
    angle = angle - np.pi / 2
    coordinate = "th" if "th" in model.coordinate_names else "theta_bar"
    q, qd = model.assemble([0, 0, angle], fixed={coordinate: angle}, qd_fixed={coordinate: rate})
    return kronlag.simulate(model, (0, t_end), q, qd, rtol=1e-11, atol=1e-12, t_eval=np.linspace(0, t_end, samples))


@pytest.mark.parametrize("from_file", [False, True])
def test_pendulum_energy_lost_equals_the_friction_work(tmp_path, from_file):
    """Started at the bottom (a start at rest is a turning point on a sample, where the rule's central
    difference of the power, which has a kink at v = 0, is wrong)."""
    trajectory = _swing(_pendulum(tmp_path, from_file=from_file), 0.0, 1.6, 16001, rate=2.0)
    assert trajectory.success
    lost = trajectory.total_energy[0] - trajectory.total_energy
    assert lost[-1] > 0.04  # a real loss, not a rounding one
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)
    assert np.max(np.abs(trajectory.energy_balance)) <= 1e-8


@pytest.mark.parametrize("from_file", [False, True])
def test_pendulum_amplitude_decays_as_the_coulomb_damped_pendulum(tmp_path, from_file):
    """Coulomb-damped pendulum at small amplitude: I_O th'' = -m g l_c th - tau_f sign(th'), l_c = L/2,
    with the friction torque tau_f = mu r N and N = |F| = m g (1 + O(th^2)) (the reaction balances
    gravity; the centripetal and tangential accelerations change it at second order).  On each half
    swing the motion is harmonic about the shifted centre -/+ tau_f / (m g l_c), so each half swing
    takes 2 tau_f / (m g l_c) off the amplitude and a full swing (between two maxima):

        A_{k+1} = A_k - 4 tau_f / (m g l_c) = A_k - 4 mu r / l_c   (= 0.008889 rad here)

    Checked to 1 % (the neglected terms are of relative size A^2 ~ 1e-2 and v_eps / (w A) ~ 3e-3)."""
    model = _pendulum(tmp_path, from_file=from_file)
    trajectory = _swing(model, 0.08, 6.5, 13001)
    angle = trajectory.q[:, 2] + np.pi / 2
    inner = np.flatnonzero((angle[1:-1] > angle[:-2]) & (angle[1:-1] >= angle[2:])) + 1
    left, centre, right = angle[inner - 1], angle[inner], angle[inner + 1]
    maxima = centre + (right - left) ** 2 / (8 * (2 * centre - left - right))  # parabola through three samples
    maxima = np.concatenate([[0.08], maxima])
    assert len(maxima) >= 4
    np.testing.assert_allclose(-np.diff(maxima), 4 * 0.1 * 0.01 / 0.45, rtol=1e-2)


# -- a slider-crank with friction in all joints ----------------------------------------------------

def test_slider_crank_with_friction_in_every_joint_closes_its_energy_balance():
    model_file = kronlag.load_model(EXAMPLE, apply_drives=False)
    assert [joint.friction is not None for joint in model_file.system.joints] == [True] * 4
    model = numeric_model(model_file)
    q0, qd0 = initial_state(model_file, model)
    trajectory = kronlag.simulate(model, (0, 1.0), q0, qd0, rtol=1e-10, atol=1e-12, t_eval=np.linspace(0, 1, 10001))
    assert trajectory.success
    work = trajectory.friction_work
    assert work[-1] < -0.1 and np.all(np.diff(work) <= 1e-12)  # friction only takes energy
    assert np.max(np.abs(trajectory.energy_balance)) <= 1e-6 * abs(work[-1])


def test_the_command_line_simulates_a_model_file_with_friction(capsys, tmp_path):
    from kronlag.app.cli import main

    code = main(["simulate", EXAMPLE, "--t-end", "0.2", "--output", str(tmp_path / "run.csv")])
    out = capsys.readouterr().out
    assert code == 0 and "status: ok" in out
    assert (tmp_path / "run.csv").stat().st_size > 0


# -- both backends, model files and errors -----------------------------------------------------------

def test_friction_forward_dynamics_agrees_between_backends_and_with_newton():
    """Pendulum at a moving state, with Stribeck, viscous and preload terms: I_O th'' = -m g l_c sin(phi) - f,
    f = r mu(v) (|F| + F0) + c v from the module's law, the same on both backends."""
    m, L, g = sp.symbols("m L g")
    results = []
    for backend in _backends():
        system = mechanism([free_body("bar", mass=m, inertia=m * L ** 2 / 12)], parameters=[m, L, g], gravity=(0, -g))
        system.add_joint("revolute", "ground", "bar", at_b=(-L / 2, 0), name="pivot",
                         friction=kronlag.Friction(kinetic=0.3, static=0.5, stribeck_velocity=0.5, radius=0.02,
                                                   viscous=0.01, preload=3.0))
        model = kronlag.derive(system).numeric({"m": 2.0, "L": 0.9, "g": G}, backend=backend)
        phi = 0.4
        q, qd = model.assemble([0, 0, phi - np.pi / 2], fixed={"theta_bar": phi - np.pi / 2},
                               qd_fixed={"theta_bar": 1.5})
        solution = model.forward_dynamics(q, qd)
        columns = friction_columns(model, 0.0, q, qd, solution.lam)
        force = np.linalg.norm(joint_reaction(model, "pivot", [0.0], q[None], solution.lam[None]).force[0])
        assert columns["pivot.normal_load"][0] == pytest.approx(force + 3.0, rel=1e-12)
        mu = 0.3 + 0.2 * np.exp(-(1.5 / 0.5) ** 2)
        assert columns["pivot.friction"][0] == pytest.approx(0.02 * mu * np.tanh(1.5e3) * (force + 3.0) + 0.015,
                                                             rel=1e-12)
        inertia = 2.0 * 0.81 / 3
        assert solution.qdd[2] * inertia == pytest.approx(-2.0 * G * 0.45 * np.sin(phi) - columns["pivot.friction"][0],
                                                          rel=1e-12)
        results.append(solution.qdd)
    np.testing.assert_allclose(results[0], results[-1], rtol=1e-12)


def test_friction_is_written_to_model_files_and_read_back(tmp_path):
    from kronlag.model.modelfile.writer import to_toml

    text = to_toml(kronlag.load_model(EXAMPLE, apply_drives=False))
    (tmp_path / "again.toml").write_text(text)
    joints = kronlag.load_model(tmp_path / "again.toml", apply_drives=False).system.joints
    assert str(joints[0].friction.kinetic) == "mu_pin" and str(joints[0].friction.radius) == "r_pin"
    assert str(joints[3].friction.kinetic) == "mu_guide" and joints[3].friction.radius is None


@pytest.mark.parametrize(("change", "message"), [
    (('friction = {kinetic = "mu", radius = "r",', 'friction = {kinetic = "mu",'),
     "joints[0]: joint 'pivot': friction in a revolute joint needs radius"),
    (('kinetic = "mu"', 'kinetic = "mu", grip = 1'), "joints[0].friction.grip: unknown field"),
    (('kinetic = "mu"', 'kinetic = "-0.1"'), "joints[0].friction: friction kinetic: must be a real number >= 0"),
    (('kinetic = "mu"', 'kinetic = "mu", law = "coulomb"'), "joints[0].friction: friction: law must be one of"),
    (('r = {value = 0.01, unit = "m"}', 'r = {value = 0.01, unit = "s"}'), "r"),
])
def test_model_file_friction_errors_are_located(tmp_path, change, message):
    path = tmp_path / "pendulum.toml"
    path.write_text(PENDULUM_FILE.replace(*change))
    with pytest.raises(kronlag.ModelError, match=message.replace("[", r"\[").replace("]", r"\]")):
        kronlag.load_model(path)


def test_friction_input_is_checked():
    system = _incline(0.3, 0.2, 1e-3)
    with pytest.raises(kronlag.ModelError, match="static != kinetic needs a stribeck_velocity"):
        kronlag.Friction(kinetic=0.2, static=0.3)
    with pytest.raises(kronlag.ModelError, match=r"static \(0.1\d*\) < kinetic \(0.2\d*\)"):
        kronlag.Friction(kinetic=0.2, static=0.1, stribeck_velocity=1)
    with pytest.raises(kronlag.ModelError, match="a prismatic joint's friction does not use a radius"):
        system.add_joint("prismatic", "ground", "block", axis=(1, 0), name="other",
                         friction=kronlag.Friction(kinetic=0.1, radius=0.1))
    with pytest.raises(kronlag.ModelError, match="friction is available on revolute and prismatic joints"):
        system.add_joint("pin_in_slot", "ground", "block", axis=(1, 0), name="slot",
                         friction=kronlag.Friction(kinetic=0.1))
    with pytest.raises(kronlag.ModelError, match="friction kinetic uses a symbol that is neither"):
        system.add_joint("prismatic", "ground", "block", axis=(1, 0), name="guide 2",
                         friction=kronlag.Friction(kinetic=sp.Symbol("unknown")))


def test_methods_without_friction_refuse_it():
    model = kronlag.derive(_incline(0.3, 0.2, 1e-3)).numeric({"m": 2.0, "g": G}, backend="python")
    with pytest.raises(kronlag.InputError, match="method='ggl' cannot run this model: a model without joint friction"):
        kronlag.simulate(model, (0, 0.1), np.zeros(3), np.zeros(3), method="ggl")


def test_trajectory_columns_and_plot_show_the_friction(tmp_path):
    model = kronlag.derive(_incline(0.5, 0.2, 1e-3)).numeric({"m": 2.0, "g": G})
    trajectory, _ = _slide(model, 0.5, 1.0, 0.2)
    columns = trajectory.columns()
    np.testing.assert_allclose(columns["guide.normal_load"], 2.0 * G * np.cos(0.5), rtol=1e-10)
    np.testing.assert_allclose(columns["guide.friction"], 0.2 * 2.0 * G * np.cos(0.5), rtol=1e-10)
    figure = trajectory.plot(path=tmp_path / "run.png")
    titles = [axes.get_title() for axes in figure.axes]
    assert "joint friction (force or torque)" in titles


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("kind", ["revolute", "prismatic"])
def test_spatial_friction_is_the_force_or_torque_along_the_axis_against_the_rate(kind, backend):
    """A body on a tilted spatial joint at a moving state: the friction's generalized force equals that of
    the torque (revolute) or force (prismatic) -f along the world axis applied to the body at the joint,
    with f = r mu_k N + c v, N = |F_perp| + |T_perp or T| / arm, from the reaction at the solution."""
    m, g = sp.symbols("m g")
    inertia = sp.Matrix([[0.05, 0.01, 0], [0.01, 0.07, 0.002], [0, 0.002, 0.03]])
    axis = np.array([1 / 3, 2 / 3, 2 / 3])
    arm = 0.1
    friction = kronlag.Friction(kinetic=0.3, viscous=0.05, arm=arm, smoothing_velocity=1e-6,
                                **({"radius": 0.02} if kind == "revolute" else {}))

    def build(with_friction: bool):
        body = free_body("b", mass=m, inertia=inertia, dimension=3, rotation="xyz", simplify=False)
        system = mechanism([body], parameters=[m, g], gravity=(0, 0, -g))
        system.add_joint(kind, "ground", "b", at_a=(0.1, 0, 0.2), at_b=(0.2, -0.1, 0.3), axis=tuple(axis),
                         name="joint", friction=friction if with_friction else None)
        return system

    model = kronlag.derive(build(True)).numeric({"m": 1.5, "g": G}, backend=backend)
    guess = [0, 0, 0, 1.0, 2.0, 2.0] if kind == "revolute" else [*(0.7 * axis), 0, 0, 0]
    q, qd = model.assemble(np.zeros(6), qd_guess=guess)
    solution = model.forward_dynamics(q, qd)
    columns = friction_columns(model, 0.0, q, qd, solution.lam)
    f, rate = columns["joint.friction"][0], columns["joint.rate"][0]
    reaction = joint_reaction(model, "joint", [0.0], q[None], solution.lam[None])
    F, T = reaction.force[0], reaction.torque[0]
    u = axis  # the ground's axis: the world axis
    if kind == "revolute":
        load = np.linalg.norm(F - (F @ u) * u) + np.linalg.norm(T - (T @ u) * u) / arm
        assert f == pytest.approx(0.02 * 0.3 * load + 0.05 * rate, rel=1e-10)
    else:
        load = np.linalg.norm(F - (F @ u) * u) + np.linalg.norm(T) / arm
        assert f == pytest.approx(0.3 * load + 0.05 * rate, rel=1e-10)
    assert abs(rate) > 0.5
    plain = build(False)
    if kind == "revolute":
        plain.add_torque("b", list(-f * u), name="friction")
    else:
        plain.add_force(plain.joints[0].point, list(-f * u), name="friction")
    reference = kronlag.derive(plain).numeric({"m": 1.5, "g": G}, backend="python").forward_dynamics(q, qd)
    np.testing.assert_allclose(solution.qdd, reference.qdd, rtol=1e-9, atol=1e-9)


def test_analyses_that_do_not_include_friction_refuse_it():
    """Inverse dynamics and linearization would silently leave the friction out: they refuse."""
    model = kronlag.derive(_incline(0.3, 0.2, 1e-3)).numeric({"m": 2.0, "g": G}, backend="python")
    with pytest.raises(kronlag.InputError, match="inverse dynamics does not include joint friction"):
        model.inverse_dynamics(np.zeros(3), np.zeros(3), np.zeros(3), actuated=["x_block"])
    with pytest.raises(kronlag.InputError, match="linearize: .* has joint friction"):
        kronlag.linearize(model, np.zeros(3))


# -- the solve is a function of the state alone ------------------------------------------------------

def test_friction_solve_does_not_depend_on_the_calls_before_it():
    """The friction forces are solved from the state at every call (Newton from f = 0, no start carried
    over from the call before): two models sharing one compiled library (``with_parameters``: other
    coefficients) evaluated in turn give each the bits it gives alone, and the records read from the
    library's compiled kernel follow each model's own parameters."""
    from kronlag.numeric.friction import friction_records

    model_file = kronlag.load_model(FOUR_BAR, apply_drives=False)
    model = numeric_model(model_file)
    q0, qd0 = initial_state(model_file, model)
    states = kronlag.simulate(model, (0, 0.3), q0, qd0, rtol=1e-8, atol=1e-10, t_eval=np.linspace(0, 0.3, 7))
    other = model.with_parameters(mu_pin=0.4)
    q, qd = states.q[3], states.qd[3]
    alone = [model.forward_dynamics(q, qd, 0.15) for _ in range(2)]
    np.testing.assert_array_equal(alone[0].qdd, alone[1].qdd)
    for i in range(len(states.t)):
        other.forward_dynamics(states.q[i], states.qd[i], states.t[i])
        after = model.forward_dynamics(q, qd, 0.15)
        np.testing.assert_array_equal(after.qdd, alone[0].qdd)
        np.testing.assert_array_equal(after.lam, alone[0].lam)
    kinetic = {record["kinetic"] for record in friction_records(model, 0.15, q, qd)}
    assert kinetic == {0.1} and {record["kinetic"] for record in friction_records(other, 0.15, q, qd)} == {0.4}


def test_four_bar_friction_solve_agrees_with_the_python_reference():
    """The four-bar's 4 pins read 3 angles: the compiled solve takes the responses to those coordinates'
    unit forces and combines them (3 right-hand sides, not 4); the Python backend, the reference, takes
    one per pin.  Both solve the same (qdd, lambda) at moving states, the smooth law and the exact one
    (each pin sliding)."""
    from kronlag.simulation.stiction import stiction_model

    if len(_backends()) < 2:
        pytest.skip("no C compiler")
    model_file = kronlag.load_model(FOUR_BAR, apply_drives=False)
    equations = kronlag.derive(model_file.system)
    models = {backend: equations.numeric(model_file.values, backend=backend) for backend in _backends()}
    q0, qd0 = initial_state(model_file, models["c"])
    states = kronlag.simulate(models["c"], (0, 0.3), q0, qd0, rtol=1e-8, atol=1e-10, t_eval=np.linspace(0, 0.3, 4))
    for modes in [None, (1, -1, 1, -1)]:
        solved = {}
        for backend, model in models.items():
            model = model if modes is None else stiction_model(model, modes)
            solved[backend] = [model.forward_dynamics(q, qd, t) for t, q, qd in zip(states.t, states.q, states.qd)]
        for c, python in zip(solved["c"], solved["python"]):
            np.testing.assert_allclose(c.qdd, python.qdd, rtol=1e-10, atol=1e-10 * np.max(np.abs(python.qdd)))
            np.testing.assert_allclose(c.lam, python.lam, rtol=1e-10, atol=1e-10 * np.max(np.abs(python.lam)))


# -- the Newton steps of the friction solve ----------------------------------------------------------

def test_friction_newton_steps_stop_when_the_error_bound_is_within_the_tolerance():
    """The friction forces' Newton steps stop once the error they leave is within FRICTION_RTOL of the
    largest force: the last step's change is, or the bound from the contraction theta of the last two steps
    (theta / (1 - theta) times the last change) is, which saves the step that would only confirm it.  A
    first step (no contraction known) or steps that do not contract are not taken as converged by the
    bound."""
    from kronlag.numeric.friction import _converged
    from kronlag.numeric.tolerances import FRICTION_RTOL

    assert _converged(0.0, 0.0, 0.0)  # no force at all
    assert _converged(0.5 * FRICTION_RTOL, 0.0, 1.0)  # the step itself within the tolerance
    assert not _converged(1e-7, 0.0, 1.0)  # a first step
    assert _converged(1e-7, 1.0, 1.0)  # theta 1e-7: about 1e-14 left
    assert not _converged(1e-6, 1.0, 1.0)  # theta 1e-6: about 1e-12 left
    assert not _converged(2 * FRICTION_RTOL, 2 * FRICTION_RTOL, 1.0)  # no contraction


def test_four_bar_friction_solve_stopped_by_the_bound_agrees_with_steps_to_the_tolerance(monkeypatch):
    """The solve stopped by the contraction bound (both backends) gives the (qdd, lambda) of Newton steps
    run until a step itself is below FRICTION_RTOL (the Python reference so), at moving states of the
    four-bar, to far below any integrator tolerance."""
    import kronlag.numeric.friction as friction
    from kronlag.numeric.tolerances import FRICTION_RTOL

    model_file = kronlag.load_model(FOUR_BAR, apply_drives=False)
    equations = kronlag.derive(model_file.system)
    models = {backend: equations.numeric(model_file.values, backend=backend) for backend in _backends()}
    fastest = models[_backends()[-1]]
    q0, qd0 = initial_state(model_file, fastest)
    states = kronlag.simulate(fastest, (0, 0.2), q0, qd0, rtol=1e-8, atol=1e-10,
                              t_eval=np.linspace(0, 0.2, 3))
    bound = {backend: [model.forward_dynamics(q, qd, t) for t, q, qd in zip(states.t, states.q, states.qd)]
             for backend, model in models.items()}
    monkeypatch.setattr(friction, "_converged", lambda change, previous, largest: change <= FRICTION_RTOL * largest)
    strict = [models["python"].forward_dynamics(q, qd, t) for t, q, qd in zip(states.t, states.q, states.qd)]
    for solutions in bound.values():
        for solution, reference in zip(solutions, strict):
            for got, want in ((solution.qdd, reference.qdd), (solution.lam, reference.lam)):
                np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-11 * np.max(np.abs(want)))
