"""Controllers in the loop (issue 18, item 1): ``simulate(controller=...)`` with a Python callable called
at every evaluation and with :class:`kronlag.Sampled` (zero-order hold, restarts at the samples), the
model file's ``[controller]`` table, ``kronlag.linearize(...).to_control()`` with ``control.lqr``, and
the cart-pole closed loop validated against a hand-derived linear model."""

from __future__ import annotations

import functools
import math
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import sympy as sp
from helpers import CART_POLE_VALUES, MASS_ON_A_LINE, cart_pole_by_joints

import kronlag
from kronlag.app.cli import main
from kronlag.app.workflows import initial_state, numeric_model, simulate_model
from kronlag.model.modelfile import loads_model
from kronlag.simulation.controllers import file_controller
from kronlag.simulation.solvers import METHODS
from kronlag.simulation.trajectory import Result

CART_POLE_FILE = Path(__file__).parents[1] / "examples" / "cart_pole.toml"
COMPILED = ("compiled", "ali3p", "switching")
PYTHON = ("baumgarte", "projection", "ggl")
UPRIGHT = math.pi / 2


@functools.cache
def cart_pole() -> kronlag.NumericModel:
    return kronlag.derive(cart_pole_by_joints()).numeric(CART_POLE_VALUES)


def tilted(model: kronlag.NumericModel, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The cart-pole at rest with the pole ``angle`` from upright, the cart at 0."""
    lc = CART_POLE_VALUES["lc"]
    guess = [0, 0, 0, -lc * math.sin(angle), lc * math.cos(angle), UPRIGHT + angle]
    return model.assemble(guess, fixed={"x_cart": 0.0, "theta_pole": UPRIGHT + angle})


def feedback(gains: np.ndarray):
    """``u = -K [x, theta - pi/2, xd, thetad]`` on the cart-pole."""

    def controller(t, q, qd):
        return {"u": -float(gains @ [q[0], q[5] - UPRIGHT, qd[0], qd[5]])}

    return controller


GAINS = np.array([-3.0, 40.0, -4.0, 7.5])


# -- the callable: checks, every method, exceptions ---------------------------------------------------


def test_an_unknown_key_is_refused_naming_it_and_the_parameters():
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    with pytest.raises(kronlag.InputError, match=r"returned 'force', which is not a parameter .*M, m, lc, I, Ic, g, u"):
        kronlag.simulate(model, (0, 1), q0, qd0, controller=lambda t, q, qd: {"force": 1.0})


def test_a_parameter_of_the_mass_matrix_cannot_be_an_input():
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    with pytest.raises(kronlag.InputError, match="sets 'M', which enters M or the constraints"):
        kronlag.simulate(model, (0, 1), q0, qd0, controller=lambda t, q, qd: {"M": 2.0})


@pytest.mark.parametrize("method", ["compiled", "projection"])
def test_a_value_that_is_not_finite_is_refused_with_t_and_q(method):
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)

    def controller(t, q, qd):
        return {"u": math.nan if t > 0.2 else 0.0}

    with pytest.raises(kronlag.InputError, match=r"returned u = nan at t = 0\.2\d*, q = \[") as raised:
        kronlag.simulate(model, (0, 1), q0, qd0, method=method, controller=controller)
    assert raised.value.trajectory.result is Result.RAISED
    assert 0.15 < raised.value.trajectory.t[-1] <= 0.2 + 1e-9


def test_the_keys_must_stay_the_same():
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    with pytest.raises(kronlag.InputError, match=r"returned the keys \['g', 'u'\] .* but \['u'\] before"):
        kronlag.simulate(model, (0, 1), q0, qd0, method="compiled",
                         controller=lambda t, q, qd: {"u": 0.0} if t < 0.1 else {"u": 0.0, "g": 9.81})


@pytest.mark.parametrize("method", list(METHODS))
def test_every_method_calls_the_controller_at_every_evaluation_and_agrees_with_the_symbolic_law(method):
    """The Python controller against the same law compiled into the equations (a force on the cart)."""
    model = cart_pole()
    system = cart_pole_by_joints()
    x, theta = (sp.Symbol(name) for name in ("x_cart", "theta_pole"))
    law = -(GAINS @ [x, theta - sp.pi / 2, kronlag.speed_symbol(x), kronlag.speed_symbol(theta)])
    system.add_force(system.body("cart").position, (law, 0), name="feedback")
    symbolic = kronlag.derive(system).numeric(CART_POLE_VALUES)
    q0, qd0 = tilted(model, 0.1)
    times = np.linspace(0, 2, 41)
    calls = []
    controller = feedback(GAINS)

    def counted(t, q, qd):
        calls.append(t)
        return controller(t, q, qd)

    run = kronlag.simulate(model, (0, 2), q0, qd0, method=method, t_eval=times, controller=counted)
    reference = kronlag.simulate(symbolic, (0, 2), q0, qd0, method=method, t_eval=times)
    assert run.success and len(calls) >= run.nfev
    assert np.max(np.abs(run.q - reference.q)) < 1e-9
    # ALI3-P: its Newton matrix lacks du/dq, dU/dqd of a Python controller; the same solution to its tolerance
    assert np.max(np.abs(run.qdd - reference.qdd)) < 1e-7 * np.max(np.abs(reference.qdd))
    expected = [controller(t, q, qd)["u"] for t, q, qd in zip(run.t, run.q, run.qd)]
    np.testing.assert_allclose(run.inputs["u"], expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("method", list(METHODS))
def test_an_exception_in_the_controller_keeps_the_partial_trajectory(method):
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    controller = feedback(GAINS)

    def failing(t, q, qd):
        if t > 0.5:
            raise RuntimeError("sensor lost")
        return controller(t, q, qd)

    with pytest.raises(RuntimeError, match="sensor lost") as raised:
        kronlag.simulate(model, (0, 2), q0, qd0, method=method, controller=failing)
    partial = raised.value.trajectory
    assert partial.result is Result.RAISED and "sensor lost" in partial.message
    assert 0.3 < partial.t[-1] <= 0.5 + 1e-9
    assert len(partial.inputs["u"]) == len(partial.t)


# -- Sampled -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", list(METHODS))
def test_sampled_holds_the_inputs_between_samples_taken_exactly_at_k_periods(method):
    model = cart_pole()
    q0, qd0 = tilted(model, 0.05)
    period, samples, given = 0.05, [], []
    controller = feedback(GAINS)

    def digital(t, q, qd, count):
        samples.append(t)
        given.append(controller(t, q, qd)["u"])
        return {"u": given[-1]}, count + 1

    sampled = kronlag.Sampled(digital, period=period, state=0)
    times = np.linspace(0, 1, 201)  # 10 outputs per period, about one at every sample
    run = kronlag.simulate(model, (0, 1), q0, qd0, method=method, t_eval=times, controller=sampled)
    assert run.success
    np.testing.assert_array_equal(samples, [k * period for k in range(20)])  # none at the end, t = 1
    assert sampled.final_state == 20
    for k in range(20):  # u is what the controller gave at t_k, on [t_k, t_k+1) (compared as the drivers do)
        interval = (times >= k * period) & (times < (k + 1) * period)
        assert np.all(run.inputs["u"][interval] == given[k])
    # the state it was given is the trajectory's there (the sample instants between outputs: interpolated)
    assert np.allclose(given, np.interp(samples, run.t, [controller(*row)["u"] for row in zip(run.t, run.q, run.qd)]),
                       rtol=0, atol=5e-3)


def test_sampled_runs_of_the_compiled_and_python_methods_agree():
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    times = np.linspace(0, 2, 81)
    runs = {method: kronlag.simulate(model, (0, 2), q0, qd0, method=method, t_eval=times, rtol=1e-10, atol=1e-12,
                                     controller=kronlag.Sampled(feedback(GAINS), period=0.01))
            for method in ("compiled", "dop853", "ali3p", "projection", "baumgarte")}
    for method, run in runs.items():
        assert np.max(np.abs(run.q - runs["projection"].q)) < 1e-7, method
        assert np.max(np.abs(run.inputs["u"] - runs["projection"].inputs["u"])) < 1e-5, method


def test_sampled_picks_a_one_step_method_by_default():
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    run = kronlag.simulate(model, (0, 0.1), q0, qd0, controller=kronlag.Sampled(feedback(GAINS), period=0.01))
    assert run.method == "ali3p"


def test_sampled_checks_its_arguments():
    with pytest.raises(kronlag.InputError, match="period must be a positive number"):
        kronlag.Sampled(lambda t, q, qd: {}, period=0)
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    with pytest.raises(kronlag.InputError, match=r"must return \(inputs, new_state\)"):
        kronlag.simulate(model, (0, 0.1), q0, qd0, controller=kronlag.Sampled(lambda t, q, qd, s: {"u": 0.0},
                                                                                period=0.01, state=0))


# -- a PID of a model file: the discrete closed loop of a mass on a line, exactly ---------------------


@pytest.mark.parametrize("method", ["ali3p", "compiled", "projection"])
def test_a_pid_carries_its_integral_from_sample_to_sample(method):
    """Under a zero-order hold a force on a mass is exactly integrable: x_k+1 = x_k + T v_k + T^2 u_k / 2m,
    v_k+1 = v_k + T u_k / m; with e_k = 0.5 - x_k, I_k = I_k-1 + T e_k, u_k = kp e_k + ki I_k - kd v_k."""
    file = loads_model(MASS_ON_A_LINE)
    T, m, kp, ki, kd = 0.02, 2.0, 8.0, 4.0, 3.0
    x, v, integral, expected, forces = 0.0, 0.0, 0.0, [], []
    for _ in range(101):
        expected.append(x)
        error = 0.5 - x
        integral += T * error
        u = kp * error + ki * integral - kd * v
        forces.append(u)
        x, v = x + T * v + T * T * u / (2 * m), v + T * u / m
    model = numeric_model(file)
    controller = file_controller(file.controller, model)
    run = kronlag.simulate(model, (0, 2), [0.0], [0.0], method=method, t_eval=np.arange(101) * T, controller=controller)
    np.testing.assert_allclose(run.q[:, 0], expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.inputs["u"][:-1], forces[:-1], rtol=1e-9, atol=1e-9)
    assert controller.final_state == pytest.approx(sum(T * (0.5 - xk) for xk in expected[:-1]), abs=1e-9)


@pytest.mark.parametrize(("old", "new", "message"), [
    ('input = "u"', 'input = "v"', "controller.input: 'v' is not a parameter of the model (parameters: m, u)"),
    ('coordinate = "x"', 'coordinate = "y"', "controller.coordinate: unknown coordinate 'y'"),
    ('kp = {value = 8, unit = "N/m"}', 'kp = {value = 8, unit = "N/s"}',
     "is used as a quantity of dimension mass*length^2/time^3 in controller.kp.unit"),
    ("period = 0.02", "period = -1", "controller.period: expected a positive number"),
    ('type = "pid"', 'type = "lqr"', "controller.type: expected 'state_feedback' or 'pid', got 'lqr'"),
    ("setpoint = 0.5", 'setpoint = "m"', "controller.setpoint: "),
], ids=["input", "coordinate", "unit", "period", "type", "setpoint"])
def test_a_bad_controller_table_is_located(old, new, message):
    with pytest.raises(kronlag.ModelError, match=f"^<string>: .*{re.escape(message)}"):
        loads_model(MASS_ON_A_LINE.replace(old, new))


# -- the cart-pole closed loop: linearization, LQR, nonlinear simulation, model file --------------------


def hand_derived_cart_pole() -> tuple[np.ndarray, np.ndarray]:
    """``A``, ``B`` of the cart-pole upright, state ``[x, phi, xd, phid]`` (``phi`` from upright, positive
    counterclockwise): with T = 1/2 (M + m) xd^2 - m lc cos(phi) xd phid + 1/2 (I + m lc^2) phid^2 and
    V = m g lc cos(phi), linearized: (M + m) xdd - m lc phidd = u, -m lc xdd + (I + m lc^2) phidd = m g lc phi."""
    M, m, lc, I, g = (CART_POLE_VALUES[name] for name in ("M", "m", "lc", "I", "g"))
    det = (M + m) * (I + m * lc ** 2) - (m * lc) ** 2
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2, 1] = m * lc * m * g * lc / det
    A[3, 1] = (M + m) * m * g * lc / det
    B = np.array([[0.0], [0.0], [(I + m * lc ** 2) / det], [m * lc / det]])
    return A, B


def lqr_gain() -> tuple[np.ndarray, np.ndarray, np.ndarray, kronlag.LinearModel]:
    control = pytest.importorskip("control")
    model = cart_pole()
    q_up, _ = tilted(model, 0.0)
    linear = kronlag.linearize(model, q_up, independent=["x_cart", "theta_pole"], inputs=["u"])
    Q, R = np.diag([10.0, 100.0, 1.0, 1.0]), np.eye(1)
    K, _, _ = control.lqr(linear.to_control(), Q, R)
    return np.asarray(K), Q, R, linear


def test_the_linearization_and_the_lqr_gain_match_the_hand_derived_cart_pole():
    K, Q, R, linear = lqr_gain()
    A, B = hand_derived_cart_pole()
    assert np.max(np.abs(linear.A - A)) <= 1e-9 * np.max(np.abs(A))
    assert np.max(np.abs(linear.B - B)) <= 1e-9 * np.max(np.abs(B))
    P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    expected = np.linalg.solve(R, B.T @ P)
    assert np.max(np.abs(K - expected)) <= 1e-9 * np.max(np.abs(expected))


@pytest.mark.parametrize("method", ["switching", "ali3p", "projection"])
def test_the_closed_loop_stays_with_the_linear_response_at_small_angles(method):
    """The nonlinear closed loop from phi0 against x(t) = expm((A - B K) t) x0: the difference is the
    cubic terms (the cart-pole is symmetric, phi -> -phi), so relative to the amplitude it shrinks like
    phi0^2 (checked at two amplitudes)."""
    K, _, _, _ = lqr_gain()
    A, B = hand_derived_cart_pole()
    model = cart_pole()
    times = np.linspace(0, 4, 81)
    relative = []
    for angle in (0.01, 0.02):
        q0, qd0 = tilted(model, angle)
        run = kronlag.simulate(model, (0, 4), q0, qd0, method=method, t_eval=times, rtol=1e-10, atol=1e-13,
                               controller=feedback(K[0]))
        states = np.column_stack([run.q[:, 0], run.q[:, 5] - UPRIGHT, run.qd[:, 0], run.qd[:, 5]])
        linear = np.array([scipy.linalg.expm((A - B @ K) * t) @ [0, angle, 0, 0] for t in times])
        relative.append(np.max(np.abs(states - linear)) / np.max(np.abs(linear)))
    assert relative[0] < 1e-3  # ~ phi0^2
    assert 3.5 < relative[1] / relative[0] < 4.5  # ~ phi0^2: the cubic terms, not an integration error


def test_the_model_file_controller_gives_the_same_closed_loop():
    K, _, _, _ = lqr_gain()
    gains = ", ".join(repr(float(value)) for value in K[0])
    text = CART_POLE_FILE.read_text()
    start = text.index("gains = [")
    end = text.index("]", start) + 1
    file = loads_model(text[:start] + f"gains = [{gains}]" + text[end:], source="cart_pole.toml")
    times = np.linspace(0, 5, 1001)  # dense enough for the energy balance's quadrature of the power
    from_file = simulate_model(file, t_eval=times)
    model = cart_pole()
    q0, qd0 = initial_state(file, numeric_model(file))
    in_python = kronlag.simulate(model, (0, 5), q0, qd0, t_eval=times, controller=feedback(K[0]))
    assert np.max(np.abs(from_file.q - in_python.q)) < 1e-12
    np.testing.assert_allclose(from_file.inputs["u"], in_python.inputs["u"], rtol=0, atol=1e-10)
    assert abs(from_file.q[-1, 5] - UPRIGHT) < 1e-3  # balanced
    # the controller's work is in W (without it the balance would be off by about W, 5.5e-3 J)
    assert np.max(np.abs(from_file.energy_balance)) < 1e-5


def test_the_shipped_cart_pole_runs_from_the_command_line(tmp_path, capsys):
    output = tmp_path / "cart_pole.csv"
    assert main(["simulate", str(CART_POLE_FILE), "--output", str(output)]) == 0
    assert "status: ok" in capsys.readouterr().out


def test_a_sweep_runs_every_case_under_the_controller():
    model = cart_pole()
    q0, qd0 = tilted(model, 0.1)
    result = kronlag.sweep(model, parameters={"m": [0.1, 0.2, 0.3]}, initial_states=(q0, qd0),
                           fixed=["x_cart", "theta_pole"], t_span=(0, 3), workers=0, progress=False,
                           controller=feedback(GAINS), outcomes={"angle": lambda run: run.q[-1, 5] - UPRIGHT})
    assert list(result.table["status"]) == ["ok"] * 3
    assert np.all(np.abs(result.table["angle"]) < 0.01)  # balanced in every case


def test_a_model_file_with_a_controller_writes_and_reads_back():
    from kronlag.model.modelfile import to_toml

    for file in (kronlag.load_model(CART_POLE_FILE), loads_model(MASS_ON_A_LINE)):
        again = loads_model(to_toml(file))
        assert type(again.controller) is type(file.controller)
        for name in ("input", "states", "reference", "period", "coordinate", "setpoint"):
            assert getattr(again.controller, name, None) == getattr(file.controller, name, None)
        gains = (file.controller.gains if hasattr(file.controller, "gains")
                 else (file.controller.kp, file.controller.ki, file.controller.kd))
        again_gains = (again.controller.gains if hasattr(again.controller, "gains")
                       else (again.controller.kp, again.controller.ki, again.controller.kd))
        assert [gain.value for gain in again_gains] == [gain.value for gain in gains]
        assert [gain.dimension for gain in again_gains] == [gain.dimension for gain in gains]


def test_the_command_line_sweep_runs_the_file_controller(tmp_path, capsys):
    """The grid's cases balance the pole (final angle near upright): the file's [controller] is in the loop."""
    output = tmp_path / "cases.csv"
    assert main(["sweep", str(CART_POLE_FILE), "--grid", "m=0.1,0.3", "--t-end", "4", "--points", "11",
                 "--workers", "0", "--output", str(output)]) == 0
    import pandas

    table = pandas.read_csv(output)
    assert list(table["status"]) == ["ok", "ok"]
    assert np.all(np.abs(table["theta_pole_final"] - UPRIGHT) < 0.01)
