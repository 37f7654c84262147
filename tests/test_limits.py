"""Limits, stops and impacts (issue 18.3): the API and model-file forms, event location, Newton's
restitution law with the constraints kept, persistent contacts and their release, against closed
forms (bouncing ball, pendulum striking a stop, a lifted ball, a four-bar crank on a stop)."""

from __future__ import annotations

import functools
import re

import numpy as np
import pytest
import sympy as sp
from helpers import rod_on_a_stop_file

import kronlag
from kronlag.simulation.trajectory import LimitEvent

G = 9.81


# -- models ---------------------------------------------------------------------------------------

def _ball_system(slope: float | None = None) -> kronlag.System:
    """A point mass falling on the floor y >= 0: on the vertical coordinate ``y`` alone, or (``slope``
    c) with coordinates (x, y) on the guide x = c y (a constrained case: the impulse must keep it)."""
    m, g, e = sp.symbols("m g e")
    y = sp.Symbol("y")
    if slope is None:
        system = kronlag.System([y], parameters=[m, g, e], gravity=(0, -g), name="ball")
        system.add_body(kronlag.PointMass("ball", mass=m, position=[0, y]))
    else:
        x = sp.Symbol("x")
        system = kronlag.System([x, y], parameters=[m, g, e], gravity=(0, -g), name="guided ball")
        system.add_body(kronlag.PointMass("ball", mass=m, position=[x, y]))
        system.add_constraint(x - slope * y, name="guide")
    system.add_limit(y, lower=0, restitution=e, name="floor")
    return system


@functools.cache
def ball(slope: float | None = None, e: float = 0.5, m: float = 0.5) -> kronlag.NumericModel:
    return kronlag.derive(_ball_system(slope)).numeric({"m": m, "g": G, "e": e})


@functools.cache
def pendulum(e: float = 0.6) -> kronlag.NumericModel:
    """A uniform rod (redundant coordinates x, y, th) pinned at one end, with a stop th >= -pi/2."""
    x, y, th = sp.symbols("x y th")
    m, L, g, e_ = sp.symbols("m L g e")
    system = kronlag.System([x, y, th], parameters=[m, L, g, e_], gravity=(0, -g), name="pendulum")
    system.add_body(kronlag.PlanarBody("rod", mass=m, inertia=m * L**2 / 12, position=[x, y], angle=th))
    system.add_joint("revolute", "ground", "rod", at_b=[-L / 2, 0], name="pivot")
    system.add_limit(th, lower=-sp.pi / 2, restitution=e_, name="stop")
    return kronlag.derive(system).numeric({"m": 2.0, "L": 0.8, "g": G, "e": e})


def _impact_times(h0: float, e: float, g: float, count: int) -> np.ndarray:
    """t_1 = sqrt(2 h0 / g), t_{k+1} = t_k + 2 e^k v_1 / g (v_1 = g t_1)."""
    t1 = np.sqrt(2 * h0 / g)
    return t1 + np.concatenate([[0.0], np.cumsum([2 * e**k * t1 for k in range(1, count)])])


def _impacts(trajectory, side: str = "floor lower") -> list[LimitEvent]:
    return [event for event in trajectory.events if isinstance(event, LimitEvent) and event.side == side
            and event.kind == "impact"]


# -- bouncing ball ----------------------------------------------------------------------------------

@pytest.mark.parametrize("method", ["switching", "projection"])
@pytest.mark.parametrize("slope", [None, 0.75])
def test_bouncing_ball_impact_times_and_apex_heights(method, slope):
    e, h0, count = 0.5, 1.0, 6
    g = G / (1 + slope**2) if slope else G  # along the guide x = c y the height falls with g / (1 + c^2)
    times = _impact_times(h0, e, g, count)
    apexes = times[:-1] + e ** np.arange(1, count) * times[0]
    q0 = [h0] if slope is None else [slope * h0, h0]
    trajectory = kronlag.simulate(ball(slope), (0, times[-1] + 0.01), q0, np.zeros(len(q0)), method=method,
                                  t_eval=apexes)
    assert trajectory.success, trajectory.message
    impacts = _impacts(trajectory)
    found = np.array([event.t for event in impacts[:count]])
    np.testing.assert_allclose(found, times, rtol=1e-8)
    heights = trajectory.q[:, -1]
    np.testing.assert_allclose(heights, h0 * e ** (2 * np.arange(1, count)), rtol=1e-8)
    for event in impacts[:count]:  # Newton's law on the gap speed, the speed before from energy
        assert event.speed_after == pytest.approx(-e * event.speed_before, rel=1e-12)
    assert -impacts[0].speed_before == pytest.approx(np.sqrt(2 * g * h0), rel=1e-8)
    if slope is not None:  # the impulse kept the guide: x' = c y' after every impact
        B = trajectory.model.Phi_q(trajectory.q[-1])
        assert abs(B @ trajectory.qd[-1]) < 1e-9


def test_bouncing_ball_ends_resting_after_the_zeno_limit():
    """Impacts accumulate at t_inf = t_1 (1 + 2 e / (1 - e)); the Zeno rule makes the contact
    persistent before it, and the ball then rests with the contact force m g."""
    e, h0, m = 0.5, 1.0, 0.5
    t_inf = np.sqrt(2 * h0 / G) * (1 + 2 * e / (1 - e))
    trajectory = kronlag.simulate(ball(None, e, m), (0, t_inf + 1.0), [h0], [0.0])
    assert trajectory.success, trajectory.message
    contacts = [event for event in trajectory.events if isinstance(event, LimitEvent) and event.kind == "contact"]
    assert len(contacts) == 1 and "rebound" in contacts[0].reason
    # the rule stops at a rebound speed ~ sqrt(2 g 10 atol) = 1.4e-4: within 2 v / (g (1 - e)) of t_inf
    assert abs(contacts[0].t - t_inf) < 2 * 1.5e-4 / (G * (1 - e))
    assert contacts[0].force == pytest.approx(m * G, rel=1e-9)
    after = trajectory.t > contacts[0].t
    np.testing.assert_allclose(trajectory.limit_forces[after, 0], m * G, rtol=1e-9)
    assert np.max(np.abs(trajectory.q[after, 0])) < 1e-12 and np.max(np.abs(trajectory.qd[after, 0])) < 1e-12
    assert len(_impacts(trajectory)) < 40


def test_contact_released_when_its_force_changes_sign():
    """A ball resting on the floor, lifted by the force k t: the contact holds until k t = m g and the
    ball then rises as y = k (t - t_r)^3 / (6 m)."""
    y, m, g, k = sp.Symbol("y"), *sp.symbols("m g k")
    system = kronlag.System([y], parameters=[m, g, k], name="lifted ball")
    system.add_body(kronlag.PointMass("ball", mass=m, position=[0, y]))
    system.add_potential(m * g * y)
    system.add_generalized_force([k * kronlag.t], name="lift")
    system.add_limit(y, lower=0, restitution=0.5, name="floor")
    model = kronlag.derive(system).numeric({"m": 2.0, "g": G, "k": 10.0})
    release = 2.0 * G / 10.0
    for method, rtol in (("switching", 1e-8), ("projection", 1e-8), ("ali3p", 1e-6)):
        trajectory = kronlag.simulate(model, (0, 3), [0.0], [0.0], method=method, t_eval=[1.0, 3.0])
        kinds = [(event.kind, event.side) for event in trajectory.events]
        assert kinds == [("contact", "floor lower"), ("release", "floor lower")], method
        assert trajectory.events[0].reason == "on the stop and pressed against it"
        assert trajectory.events[1].t == pytest.approx(release, rel=1e-8)
        assert trajectory.limit_forces[0, 0] == pytest.approx(2.0 * G - 10.0, rel=1e-9)
        assert trajectory.q[1, 0] == pytest.approx(10.0 * (3.0 - release) ** 3 / 12.0, rel=rtol)
        assert trajectory.limit_forces[1, 0] == 0.0


def test_restitution_is_a_parameter_of_the_built_model():
    """with_parameters changes e without deriving again: the rebound follows."""
    for e in (0.3, 0.9):
        trajectory = kronlag.simulate(ball().with_parameters(e=e), (0, 0.5), [1.0], [0.0])
        (impact,) = _impacts(trajectory)
        assert impact.speed_after == pytest.approx(-e * impact.speed_before, rel=1e-12)


# -- pendulum and four-bar --------------------------------------------------------------------------

@pytest.mark.parametrize(("method", "rtol"), [("switching", 1e-8), ("projection", 1e-8), ("ali3p", 1e-6)])
def test_pendulum_striking_a_stop_rebounds_with_e_times_its_speed(method, rtol):
    """Released horizontal, the rod reaches the stop (hanging) with w = sqrt(3 g / L) (energy) and
    leaves it with e w; the pin's constraints hold after the impulse."""
    e, L = 0.6, 0.8
    model = pendulum(e)
    trajectory = kronlag.simulate(model, (0, 0.6), [L / 2, 0.0, 0.0], [0.0, 0.0, 0.0], method=method)
    assert trajectory.success, trajectory.message
    (impact,) = _impacts(trajectory, "stop lower")
    speed = np.sqrt(3 * G / L)
    assert -impact.speed_before == pytest.approx(speed, rel=rtol)
    assert impact.speed_after == pytest.approx(e * speed, rel=rtol)
    row = np.flatnonzero(trajectory.t == impact.t)[-1]  # the state after the impact
    assert np.max(np.abs(model.Phi_q(trajectory.q[row]) @ trajectory.qd[row])) < 1e-9
    assert trajectory.qd[row, 2] == pytest.approx(e * speed, rel=rtol)


def test_four_bar_crank_hitting_a_stop_keeps_the_loop_closed():
    """After each impact Phi_q qd+ = 0 (the loop's velocity constraints) and J qd+ = -e J qd-."""
    system = kronlag.models.four_bar()
    e = 0.7
    system.add_limit(sp.Symbol("q1"), upper=2.0, restitution=e, name="crank stop")
    values = {"l1": 0.2, "l2": 0.6, "l3": 0.5, "l4": 0.5, "m1": 1.0, "m2": 2.0, "m3": 3.0, "I1": 1 / 300,
              "I2": 0.06, "I3": 0.0625, "g": G, "tau": 3.0}
    model = kronlag.derive(system).numeric(values)
    q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0})
    trajectory = kronlag.simulate(model, (0, 1.0), q0, qd0)
    assert trajectory.success, trajectory.message
    impacts = _impacts(trajectory, "crank stop upper")
    assert len(impacts) >= 3
    for impact in impacts:
        before, after = np.flatnonzero(trajectory.t == impact.t)[[0, -1]]
        q, qd_minus, qd_plus = trajectory.q[after], trajectory.qd[before], trajectory.qd[after]
        assert np.max(np.abs(model.Phi_q(q) @ qd_plus)) < 1e-9
        assert -qd_plus[0] == pytest.approx(-e * -qd_minus[0], rel=1e-9)  # J = [0, 0, 0] - [1, 0, 0] on q1
        assert trajectory.q[after, 0] == pytest.approx(2.0, abs=1e-10)


@functools.cache
def four_bar_with_stop() -> kronlag.NumericModel:
    system = kronlag.models.four_bar()
    system.add_limit(sp.Symbol("q1"), upper=2.0, restitution=0.7, name="crank stop")
    values = {"l1": 0.2, "l2": 0.6, "l3": 0.5, "l4": 0.5, "m1": 1.0, "m2": 2.0, "m3": 3.0, "I1": 1 / 300,
              "I2": 0.06, "I3": 0.0625, "g": G, "tau": 3.0}
    return kronlag.derive(system).numeric(values)


@pytest.mark.parametrize("method", ["switching", "projection", "baumgarte", "ali3p"])
def test_four_bar_crank_comes_to_rest_on_its_stop(method):
    """Driven against the stop by its torque, the crank's impacts accumulate, the Zeno rule holds it
    there, and its contact force is the static one: h(q) = Phi_q^T lam + J^T lam_c at qd = 0,
    F = -lam_c (from the model's own terms, independently of the contact model)."""
    model = four_bar_with_stop()
    q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0})
    trajectory = kronlag.simulate(model, (0, 2.0), q0, qd0, method=method)
    assert trajectory.success, trajectory.message
    contacts = [event for event in trajectory.events if event.kind == "contact"]
    assert len(contacts) == 1 and contacts[0].t < 1.4
    q = trajectory.q[-1]
    assert q[0] == pytest.approx(2.0, abs=1e-9) and np.max(np.abs(trajectory.qd[-1])) < 1e-8
    terms = model.dynamics_terms(q, np.zeros(3))
    rows = np.vstack([terms["Phi_q"], [[-1.0, 0.0, 0.0]]])  # the gap 2 - q1
    multipliers = np.linalg.lstsq(rows.T, terms["h"], rcond=None)[0]
    assert trajectory.limit_forces[-1, 0] == pytest.approx(-multipliers[-1], rel=1e-8)


def test_sleigh_hitting_a_wall_keeps_its_blade_constraint():
    """A nonholonomic case: the Chaplygin sleigh runs into the wall x <= 1; the impulse keeps the blade's
    A qd + b = 0 and reverses the wall-normal speed by e."""
    system = kronlag.models.chaplygin_sleigh()
    system.add_limit(sp.Symbol("x"), upper=1.0, restitution=0.5, name="wall")
    model = kronlag.derive(system).numeric({"m": 1.0, "I": 0.1, "a": 0.2})
    for method in ("auto", "projection"):
        trajectory = kronlag.simulate(model, (0, 2), [0.0, 0.0, 0.3], [np.cos(0.3), np.sin(0.3), 0.0], method=method)
        (impact,) = _impacts(trajectory, "wall upper")
        before, after = np.flatnonzero(trajectory.t == impact.t)[[0, -1]]
        q, qd = trajectory.q[after], trajectory.qd[after]
        assert abs(model.A(q) @ qd + model.b(q).ravel()) < 1e-12
        assert qd[0] == pytest.approx(-0.5 * trajectory.qd[before, 0], rel=1e-12)
        assert np.max(trajectory.q[:, 0]) <= 1.0 + 1e-12


# -- model files ------------------------------------------------------------------------------------

BALL_FILE = """
name = "bouncing_ball"
coordinates = ["y"]
gravity = [0, "-g"]

[parameters]
m = {value = 500, unit = "g"}
g = {value = 9.81, unit = "m/s^2"}
e = {value = 0.5}
floor = {value = 0, unit = "mm"}

[[bodies]]
name = "ball"
type = "point"
mass = "m"
position = [0, "y"]

[[limits]]
name = "floor"
expression = "y"
lower = "floor"
restitution = "e"
"""

PENDULUM_FILE = rod_on_a_stop_file()


def _from_file(tmp_path, text: str) -> kronlag.NumericModel:
    path = tmp_path / "model.toml"
    path.write_text(text)
    model_file = kronlag.load_model(path)
    return kronlag.derive(model_file.system).numeric(model_file.numeric_values())


def test_bouncing_ball_from_a_model_file(tmp_path):
    model = _from_file(tmp_path, BALL_FILE)
    times = _impact_times(1.0, 0.5, G, 4)
    trajectory = kronlag.simulate(model, (0, times[-1] + 0.01), [1.0], [0.0], t_eval=times[:-1] + 0.5**np.arange(1, 4)
                                  * times[0])
    np.testing.assert_allclose([event.t for event in _impacts(trajectory)][:4], times, rtol=1e-8)
    np.testing.assert_allclose(trajectory.q[:, 0], 0.5 ** (2 * np.arange(1, 4)), rtol=1e-8)


def test_pendulum_from_a_model_file(tmp_path):
    model = _from_file(tmp_path, PENDULUM_FILE)
    trajectory = kronlag.simulate(model, (0, 0.6), [0.4, 0.0, 0.0], [0.0, 0.0, 0.0])
    (impact,) = _impacts(trajectory, "stop lower")
    assert impact.speed_after == pytest.approx(0.6 * np.sqrt(3 * G / 0.8), rel=1e-8)


def test_four_bar_with_a_stop_from_a_model_file(tmp_path):
    from kronlag.app.workflows import initial_state, numeric_model
    from kronlag.model.builtin import example_path

    path = tmp_path / "four_bar_stop.toml"
    text = example_path("four_bar").read_text().replace('tau = {value = 0.0', 'tau = {value = 3.0')
    path.write_text(text + '\n[[limits]]\nname = "crank stop"\nexpression = "q1"\nupper = 2.0\nrestitution = 0.7\n')
    model_file = kronlag.load_model(path, apply_drives=False)
    model = numeric_model(model_file)
    q0, qd0 = initial_state(model_file, model)
    trajectory = kronlag.simulate(model, (0, 1.0), q0, qd0)
    impacts = _impacts(trajectory, "crank stop upper")
    assert impacts and trajectory.success
    for impact in impacts:
        assert impact.speed_after == pytest.approx(-0.7 * impact.speed_before, rel=1e-12)
        after = np.flatnonzero(trajectory.t == impact.t)[-1]
        assert np.max(np.abs(model.Phi_q(trajectory.q[after]) @ trajectory.qd[after])) < 1e-9


def test_limits_are_written_to_model_files_and_read_back(tmp_path):
    from kronlag.model.modelfile.writer import to_toml

    path = tmp_path / "model.toml"
    path.write_text(BALL_FILE)
    text = to_toml(kronlag.load_model(path))
    assert "[[limits]]" in text
    (tmp_path / "again.toml").write_text(text)
    (limit,) = kronlag.load_model(tmp_path / "again.toml").system.limits
    assert (limit.name, str(limit.value), str(limit.lower), limit.upper, str(limit.restitution)) == (
        "floor", "y", "floor", None, "e")


@pytest.mark.parametrize(("change", "message"), [
    (('lower = "floor"', 'lower = "g"'), "limits[0].lower"),
    (('restitution = "e"', 'restitution = "m"'), "limits[0].restitution"),
    (('expression = "y"', 'expression = "m"'), "limits[0]: limit 'floor' does not depend on any coordinate"),
    (('lower = "floor"\n', ''), "limits[0]: give lower, upper or both"),
    (('restitution = "e"', 'restitution = "e"\nbounce = 1'), "limits[0].bounce: unknown field"),
])
def test_model_file_limit_errors_are_located(tmp_path, change, message):
    path = tmp_path / "model.toml"
    path.write_text(BALL_FILE.replace(*change))
    with pytest.raises(kronlag.ModelError, match=message.replace("[", r"\[").replace("]", r"\]")):
        kronlag.load_model(path)


# -- errors -----------------------------------------------------------------------------------------

def test_add_limit_refuses_bad_input():
    system = _ball_system()
    m = sp.Symbol("m")
    with pytest.raises(kronlag.ModelError, match="does not depend on any coordinate"):
        system.add_limit(m, lower=0)
    with pytest.raises(kronlag.ModelError, match="give lower=, upper= or both"):
        system.add_limit(sp.Symbol("y"))
    with pytest.raises(kronlag.ModelError, match="restitution must lie in"):
        system.add_limit(sp.Symbol("y"), upper=2, restitution=1.5)
    with pytest.raises(kronlag.ModelError, match="duplicate limit name 'floor'"):
        system.add_limit(sp.Symbol("y"), upper=2, name="floor")
    with pytest.raises(kronlag.ModelError, match="neither a coordinate nor a declared parameter"):
        system.add_limit(sp.Symbol("y"), upper=sp.Symbol("h"))


def test_a_limit_violated_at_the_start_is_refused():
    with pytest.raises(kronlag.InputError, match=r"limit 'floor': its value -0.1 is below the lower bound 0 "
                                                 "at the initial state"):
        kronlag.simulate(ball(), (0, 1), [-0.1], [0.0])
    with pytest.raises(kronlag.InputError, match="method='ggl' does not watch limits"):
        kronlag.simulate(ball(), (0, 1), [1.0], [0.0], method="ggl")


def test_plot_marks_the_impacts():
    trajectory = kronlag.simulate(ball(), (0, 1.0), [1.0], [0.0])
    figure = trajectory.plot()
    labels = [text.get_text() for text in figure.axes[0].texts]
    assert labels == ["impact: floor lower"] * len(_impacts(trajectory))
    assert figure.axes[-1].get_title() == "limit contact forces" or any(
        axes.get_title() == "limit contact forces" for axes in figure.axes)


def test_cli_simulates_a_model_file_with_limits(tmp_path, capsys):
    from kronlag.app.cli import main

    path = tmp_path / "ball.toml"
    path.write_text(BALL_FILE + '\n[initial]\nq = {y = 1}\n\n[simulation]\nt_end = 1.5\n')
    code = main(["simulate", str(path), "--plot", str(tmp_path / "ball.png")])
    out = capsys.readouterr().out
    assert code == 0 and "status: ok" in out
    assert re.search(r"limit events: \d+ impact, 1 contact, 0 release", out)
    assert (tmp_path / "ball.png").stat().st_size > 10_000
    code = main(["simulate", str(path), "--output", str(tmp_path / "ball.csv")])
    header = (tmp_path / "ball.csv").read_text().splitlines()[0].split(",")
    assert code == 0 and header[-1] == "floor lower.force"
