"""A controller and limits in one run (issue 18, items 1 and 3 together): a continuous state feedback
pushing a cart into its end stop (impacts, then a persistent contact whose force is the controller's
force at rest), a sampled PID torque driving a pendulum into a stop (against an independent
integration of its hand-derived equation with the same sampled PID and Newton's restitution law; the
samples at k period across the impact; the API, a model file and the command line), a sample exactly
at an impact, and the energy balance (the controller's work and the impacts' dissipation)."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import sympy as sp
from helpers import rod_on_a_stop_file
from scipy.integrate import solve_ivp

import kronlag
from kronlag.app.cli import main
from kronlag.app.workflows import initial_state, numeric_model, simulate_model
from kronlag.model.modelfile import loads_model
from kronlag.simulation.trajectory import LimitEvent

LIMIT_METHODS = ("switching", "compiled", "ali3p", "baumgarte", "projection")
G = 9.81


def _events(trajectory, kind: str) -> list[LimitEvent]:
    return [event for event in trajectory.events if isinstance(event, LimitEvent) and event.kind == kind]


# -- a cart on a track with end stops, pushed into the upper one ----------------------------------

MASS, RESTITUTION, KP, X_REF = 2.0, 0.5, 8.0, 1.2


@functools.cache
def cart() -> kronlag.NumericModel:
    """A cart x on a track 0 <= x <= 1 (restitution e) driven by the force u."""
    x = sp.Symbol("x")
    M, u, e = sp.symbols("M u e")
    system = kronlag.System([x], parameters=[M, u, e], name="cart on a track")
    system.add_body(kronlag.PointMass("cart", mass=M, position=[x, 0]))
    system.add_generalized_force([u])
    system.add_limit(x, lower=0, upper=1, restitution=e, name="track")
    return kronlag.derive(system).numeric({"M": MASS, "u": 0.0, "e": RESTITUTION})


def spring_feedback(t, q, qd):
    """``u = -kp (x - x_ref)`` with ``x_ref`` beyond the stop: it presses the cart against it at rest."""
    return {"u": -KP * (q[0] - X_REF)}


def _first_impact() -> tuple[float, float]:
    """The closed form from x0 = 0.5 at rest: x = x_ref - (x_ref - 0.5) cos(w t), w^2 = kp / M, up to x = 1."""
    w, amplitude = math.sqrt(KP / MASS), X_REF - 0.5
    t = math.acos((X_REF - 1.0) / amplitude) / w
    return t, amplitude * w * math.sin(w * t)


@pytest.mark.parametrize("method", LIMIT_METHODS)
def test_state_feedback_pushes_a_cart_into_its_stop_then_holds_it_there(method):
    trajectory = kronlag.simulate(cart(), (0, 6), [0.5], [0.0], method=method, controller=spring_feedback)
    assert trajectory.success, trajectory.message
    impacts = _events(trajectory, "impact")
    t_hit, speed = _first_impact()
    rtol = 1e-6 if method == "ali3p" else 1e-8
    assert impacts[0].t == pytest.approx(t_hit, rel=rtol)
    assert impacts[0].speed_before == pytest.approx(-speed, rel=rtol)  # the gap 1 - x closes at xd
    assert impacts[0].speed_after == pytest.approx(RESTITUTION * speed, rel=rtol)
    (contact,) = _events(trajectory, "contact")
    assert contact.side == "track upper" and contact.t > impacts[-1].t - 1e-12
    # at rest on the stop: the contact force is the controller's force there, kp (x_ref - 1)
    rest = trajectory.t > contact.t + 0.1
    np.testing.assert_allclose(trajectory.q[rest, 0], 1.0, atol=1e-9)
    np.testing.assert_allclose(trajectory.limit_forces[rest, 1], KP * (X_REF - 1.0), rtol=1e-9)
    np.testing.assert_allclose(trajectory.inputs["u"][rest], KP * (X_REF - 1.0), rtol=1e-9)
    # the inputs recorded over every segment (the contact variant's included), one row per output
    assert trajectory.inputs["u"].shape == trajectory.t.shape
    np.testing.assert_allclose(trajectory.inputs["u"], -KP * (trajectory.q[:, 0] - X_REF), rtol=1e-12, atol=1e-12)


def test_energy_balance_is_the_controllers_work_less_the_impacts_dissipation():
    """A constant push u (a controller of t only): the controller's work is u (x - x0) exactly, each impact
    dissipates M (v-^2 - v+^2) / 2 with v+ = -e v-, so E(t) - E(0) - W(t) is minus the dissipation."""
    push = 1.5
    trajectory = kronlag.simulate(cart(), (0, 6), [0.2], [0.0], controller=lambda t, q, qd: {"u": push})
    assert trajectory.success, trajectory.message
    impacts = _events(trajectory, "impact")
    assert len(impacts) > 3 and len(_events(trajectory, "contact")) == 1
    dissipated = sum(MASS / 2 * (event.speed_before**2 - event.speed_after**2) for event in impacts)
    # independent: the speeds at impact follow from the constant acceleration (x from 0.2 to 1)
    speed = math.sqrt(2 * push / MASS * 0.8)
    assert -impacts[0].speed_before == pytest.approx(speed, rel=1e-9)
    assert dissipated == pytest.approx(MASS / 2 * speed**2, rel=1e-6)  # all of it, once at rest
    np.testing.assert_allclose(trajectory.nonconservative_work, push * (trajectory.q[:, 0] - 0.2), atol=1e-9)
    assert trajectory.energy_balance[-1] == pytest.approx(-dissipated, rel=1e-8)
    assert trajectory.limit_forces[-1, 1] == pytest.approx(push, rel=1e-9)


@pytest.mark.parametrize("method", LIMIT_METHODS)
def test_a_sample_exactly_at_an_impact_sees_the_state_before_it(method):
    """The cart coasts at 1 m/s from x = 0 and hits the stop x = 1 at t = 1, the 8th sample instant: the
    sample there sees it arriving (the state before the impact), so the sampled controller (its state:
    the number of samples) brakes with u = -2 from the next sample on, held."""
    samples = []

    def brake(t, q, qd, count):
        samples.append((t, q[0], qd[0]))
        return {"u": 0.0 if qd[0] > 0 else -2.0}, count + 1

    controller = kronlag.Sampled(brake, period=0.125, state=0)
    trajectory = kronlag.simulate(cart(), (0, 1.5), [0.0], [1.0], method=method, controller=controller)
    assert trajectory.success, trajectory.message
    (impact,) = _events(trajectory, "impact")
    assert impact.t == pytest.approx(1.0, abs=1e-9)
    times = [t for t, _, _ in samples]
    assert times == [k * 0.125 for k in range(12)]  # exactly k period, none twice, none lost
    assert controller.final_state == 12
    at_impact, after_impact = samples[8], samples[9]
    assert at_impact[1] == pytest.approx(1.0, abs=1e-9) and at_impact[2] == pytest.approx(1.0, rel=1e-9)
    assert after_impact[2] == pytest.approx(-RESTITUTION, rel=1e-9)  # the held input carried over the impact
    # after the impact: x = 1 - e (t - 1) at u = 0 until 1.125, then u = -2 on M = 2 held
    tau = trajectory.t - 1.0
    coasting, braking = (tau > 0) & (tau <= 0.125), tau > 0.125
    expected = 1.0 - RESTITUTION * tau - 0.5 * np.maximum(tau - 0.125, 0.0) ** 2
    np.testing.assert_allclose(trajectory.q[tau > 0, 0], expected[tau > 0], atol=1e-8)
    np.testing.assert_allclose(trajectory.inputs["u"][braking], -2.0)
    np.testing.assert_allclose(trajectory.inputs["u"][(tau < 0) | coasting & (tau < 0.125)], 0.0)


@pytest.mark.parametrize("method", LIMIT_METHODS)
@pytest.mark.parametrize("sampled", [False, True])
def test_an_exception_of_the_controller_after_an_impact_propagates_with_the_run_so_far(method, sampled):
    class Stop(Exception):
        pass

    def failing(t, q, qd):
        if t > 1.5:
            raise Stop("from the controller")
        return spring_feedback(t, q, qd)

    controller = kronlag.Sampled(failing, period=0.01) if sampled else failing
    with pytest.raises(Stop) as raised:
        kronlag.simulate(cart(), (0, 6), [0.5], [0.0], method=method, controller=controller)
    trajectory = raised.value.trajectory
    assert trajectory.result is kronlag.Result.RAISED and 1.0 < trajectory.t[-1] <= 1.51
    assert len(_events(trajectory, "impact")) == 1 and trajectory.inputs["u"].shape == trajectory.t.shape


# -- a pendulum driven by a sampled PID torque into a stop ----------------------------------------

PENDULUM_FILE = rod_on_a_stop_file(name="pid_pendulum_on_a_stop", parameters='tau = {value = 0, unit = "N*m"}',
                                   tables="""
[[torques]]
body = "rod"
torque = "tau"

[controller]
type = "pid"
input = "tau"
coordinate = "th"
setpoint = -2.0
kp = {value = 6, unit = "N*m"}
ki = 3.0
kd = {value = 0.4, unit = "N*m*s"}
period = 0.01

[initial]
q = {x = 0.4, y = 0, th = 0}

[simulation]
t_end = 1.0
""")

PID = {"kp": 6.0, "ki": 3.0, "kd": 0.4, "setpoint": -2.0, "period": 0.01}


def pid_pendulum_reference(t_end: float, m: float = 2.0, L: float = 0.8, e: float = 0.6):
    """The rod pinned at its end, ``m L^2 / 3 th'' = -m g L / 2 cos th + tau``, from th = 0 at rest, the
    torque of the file's PID held over each sample, Newton's law ``th'+ = -e th'-`` at th = -pi/2:
    integrated independently (DOP853, tolerance 1e-12, events by scipy).  The impacts ``(t, th'-)``
    and the state at ``t_end``."""
    inertia, period = m * L**2 / 3, PID["period"]
    state, integral, impacts = np.array([0.0, 0.0]), 0.0, []
    steps = round(t_end / period)
    for k in range(steps):
        error = PID["setpoint"] - state[0]
        integral += period * error
        torque = PID["kp"] * error + PID["ki"] * integral - PID["kd"] * state[1]

        def rhs(t, y, torque=torque):
            return [y[1], (-m * G * L / 2 * math.cos(y[0]) + torque) / inertia]

        def stop(t, y):
            return y[0] + math.pi / 2

        stop.terminal, stop.direction = True, -1
        t = k * period
        while True:
            solution = solve_ivp(rhs, (t, (k + 1) * period), state, method="DOP853", rtol=1e-12, atol=1e-12,
                                 events=stop)
            state = solution.y[:, -1].copy()
            if solution.status != 1:
                break
            t = solution.t[-1]
            impacts.append((t, state[1]))
            state = np.array([-math.pi / 2, -e * state[1]])
    return impacts, state


@functools.cache
def pid_pendulum_api() -> kronlag.NumericModel:
    x, y, th = sp.symbols("x y th")
    m, L, g, e, tau = sp.symbols("m L g e tau")
    system = kronlag.System([x, y, th], parameters=[m, L, g, e, tau], gravity=(0, -g), name="pid pendulum")
    system.add_body(kronlag.PlanarBody("rod", mass=m, inertia=m * L**2 / 12, position=[x, y], angle=th))
    system.add_joint("revolute", "ground", "rod", at_b=[-L / 2, 0], name="pivot")
    system.add_torque("rod", tau)
    system.add_limit(th, lower=-sp.pi / 2, restitution=e, name="stop")
    return kronlag.derive(system).numeric({"m": 2.0, "L": 0.8, "g": G, "e": 0.6, "tau": 0.0})


def pid(t, q, qd, integral):
    """The file's PID on th (docs/control.md): e_k, I_k = I_(k-1) + T e_k, u = kp e + ki I - kd thd."""
    error = PID["setpoint"] - q[2]
    integral += PID["period"] * error
    return {"tau": PID["kp"] * error + PID["ki"] * integral - PID["kd"] * qd[2]}, integral


def _check_against_reference(trajectory, t_end: float, rtol: float) -> None:
    assert trajectory.success, trajectory.message
    impacts, final = pid_pendulum_reference(t_end)
    found = _events(trajectory, "impact")
    assert len(found) == len(impacts) >= 2
    for event, (t, speed) in zip(found, impacts):
        assert event.t == pytest.approx(t, rel=rtol)
        assert event.speed_before == pytest.approx(speed, rel=rtol)
        assert event.speed_after == pytest.approx(-0.6 * speed, rel=rtol)  # the rebound: e v
        row = np.flatnonzero(trajectory.t == event.t)[-1]  # after the impulse: the pin still holds
        assert trajectory.qd[row, 2] == pytest.approx(-0.6 * speed, rel=rtol)
        assert abs(trajectory.qd[row, 0] + 0.4 * trajectory.qd[row, 2] * math.sin(trajectory.q[row, 2])) < 1e-9
    np.testing.assert_allclose([trajectory.q[-1, 2], trajectory.qd[-1, 2]], final, rtol=rtol * 10, atol=rtol * 10)


@pytest.mark.parametrize(("method", "rtol"), [("switching", 1e-7), ("compiled", 1e-7), ("ali3p", 1e-5),
                                              ("baumgarte", 1e-7), ("projection", 1e-7)])
def test_sampled_pid_drives_a_pendulum_into_its_stop(method, rtol):
    times = []

    def recorded(t, q, qd, integral):
        times.append(t)
        return pid(t, q, qd, integral)

    controller = kronlag.Sampled(recorded, period=PID["period"], state=0.0)
    trajectory = kronlag.simulate(pid_pendulum_api(), (0, 1.0), [0.4, 0.0, 0.0], [0.0, 0.0, 0.0], method=method,
                                  controller=controller, rtol=1e-10, atol=1e-12)
    _check_against_reference(trajectory, 1.0, rtol)
    assert times == [k * PID["period"] for k in range(100)]  # across the impacts: every sample, once


def test_sampled_pid_from_a_model_file_and_the_command_line(tmp_path):
    model_file = loads_model(PENDULUM_FILE)
    trajectory = simulate_model(model_file, rtol=1e-10, atol=1e-12)
    _check_against_reference(trajectory, 1.0, 1e-7)
    path = tmp_path / "pendulum.toml"
    path.write_text(PENDULUM_FILE)
    output = tmp_path / "pendulum.csv"
    assert main(["simulate", str(path), "--rtol", "1e-10", "--atol", "1e-12", "--output", str(output)]) == 0
    import pandas

    table = pandas.read_csv(output)
    assert table["th"].iloc[-1] == pytest.approx(trajectory.q[-1, 2], rel=1e-9)
    assert "stop lower.force" in table.columns


def test_every_method_agrees_on_a_sampled_pid_with_impacts():
    model_file = loads_model(PENDULUM_FILE)
    model = numeric_model(model_file)
    q0, qd0 = initial_state(model_file, model)
    t_eval = np.linspace(0, 1.0, 41)
    runs = {method: kronlag.simulate(model, (0, 1.0), q0, qd0, method=method, t_eval=t_eval, rtol=1e-10, atol=1e-12,
                                     controller=kronlag.Sampled(pid, period=PID["period"], state=0.0))
            for method in LIMIT_METHODS}
    reference = runs["switching"]
    for method, trajectory in runs.items():
        assert trajectory.success, (method, trajectory.message)
        np.testing.assert_allclose(trajectory.q, reference.q, atol=1e-5, err_msg=method)
        np.testing.assert_allclose(trajectory.inputs["tau"], reference.inputs["tau"], atol=1e-4, err_msg=method)
