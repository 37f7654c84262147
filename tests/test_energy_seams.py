"""The energy balance at the seams of friction, contacts and stiction (issue 18): the work ``W`` uses the
friction that acted, with the contacts and the sticking joints held as in the integration.

A bar swinging on a pin with friction at the centre of a cart whose rail lets it move along x: when the
cart is held, by a stop it is pushed against (e = 0, a persistent contact) or by its rail's exact
stiction, the bar is a pendulum on a fixed pivot, and its pin's load (hence its friction) is that of a
fixed pivot, not that of a free cart.  The references integrate the hand-derived fixed-pivot pendulum
with pin friction (scipy, tight tolerances), independently of kronlag's equations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import MASS_ON_A_LINE, PIN_FRICTION_PENDULUM_VALUES, pin_friction_pendulum
from scipy.integrate import solve_ivp

import kronlag
from kronlag.app.workflows import simulate_model, summarize
from kronlag.core.errors import KronlagWarning
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.model.modelfile import loads_model
from kronlag.simulation.trajectory import LimitEvent, StictionEvent

CART, BAR, LENGTH, G, MU, RADIUS = 10.0, 2.0, 0.9, 9.81, 0.3, 0.02
PUSH = 200.0  # N on the cart, towards its stop: more than the bar's swing can pull it back
T_END = 0.5  # before the bar's first turning point (its pin's rate keeps its sign)
TIGHT = {"rtol": 1e-11, "atol": 1e-12}


def _cart_and_bar(*, stop: bool, rail: kronlag.Friction | None = None) -> kronlag.NumericModel:
    """The cart (x along the rail) and the bar (angle th from the x axis, pinned at its end to the cart's
    centre with exact pin friction); with ``stop``: the push on the cart and the stop x <= 0 (e = 0)."""
    M, m, L, g, F = sp.symbols("M m L g F")
    system = mechanism([free_body("cart", mass=M, inertia=M / 10), free_body("bar", mass=m, inertia=m * L ** 2 / 12)],
                       parameters=[M, m, L, g, F], gravity=(0, -g), name="cart and bar")
    system.add_joint("prismatic", "ground", "cart", axis=(1, 0), name="rail", friction=rail)
    system.add_joint("revolute", "cart", "bar", at_b=(-L / 2, 0), name="pin",
                     friction=kronlag.Friction(kinetic=MU, radius=RADIUS, law="exact"))
    if stop:
        system.add_force(system.body("cart").position, (F, 0), name="push")
        system.add_limit(system.coordinates[0], upper=0, restitution=0, name="stop")
    return kronlag.derive(system).numeric({"M": CART, "m": BAR, "L": LENGTH, "g": G, "F": PUSH if stop else 0.0})


def _start(th0: float) -> tuple[np.ndarray, np.ndarray]:
    """At rest, the cart at 0, the bar at ``th0`` (coordinates x, y, angle of the cart, then of the bar)."""
    return np.array([0.0, 0.0, 0.0, LENGTH / 2 * np.cos(th0), LENGTH / 2 * np.sin(th0), th0]), np.zeros(6)


def _fixed_pivot(th0: float, t_end: float) -> tuple[float, float, float]:
    """``(th, w, W_f)`` at ``t_end`` of the bar on a fixed pivot from rest at ``th0``:
    ``I_O a = -m g l cos th - r mu N sign(w)``, ``N = |m a_G + m g y|``, ``a_G = l (a t - w^2 n)``
    (``l = L/2``, ``n = (cos th, sin th)``, ``t = (-sin th, cos th)``), ``W_f = -integral r mu N |w| dt``."""
    half, inertia = LENGTH / 2, BAR * LENGTH ** 2 / 3

    def rates(_, state):
        th, w, _work = state
        normal, tangent = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
        direction = np.sign(w) if w != 0 else -np.sign(np.cos(th))  # from rest it swings the way gravity turns it
        a = -BAR * G * half * np.cos(th) / inertia
        for _ in range(60):  # the load depends on a, a weakly (r mu << l): a fixed point
            load = np.linalg.norm(BAR * half * (a * tangent - w ** 2 * normal) + BAR * G * np.array([0.0, 1.0]))
            a = (-BAR * G * half * np.cos(th) - RADIUS * MU * load * direction) / inertia
        return [w, a, -RADIUS * MU * load * abs(w)]

    solution = solve_ivp(rates, (0, t_end), [th0, 0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-13)
    assert solution.success and np.all(solution.y[1, 1:] < 0), "the reference must swing one way"
    return tuple(solution.y[:, -1])


def _events(trajectory, kind) -> list:
    return [event for event in trajectory.events if getattr(event, "kind", "") == kind]


def _check_fixed_pivot_swing(trajectory) -> None:
    th, w, friction_work = _fixed_pivot(0.0, T_END)
    assert trajectory.t[-1] == T_END
    assert trajectory.q[-1, 5] == pytest.approx(th, abs=1e-8)
    assert trajectory.qd[-1, 5] == pytest.approx(w, abs=1e-8)
    np.testing.assert_allclose(trajectory.q[:, 0], 0.0, atol=1e-9)  # the cart held
    # the friction that acted is the fixed pivot's (the old W: the free cart's, 0.35 J off on the stop)
    assert trajectory.friction_work[-1] == pytest.approx(friction_work, abs=1e-8)
    lost = trajectory.total_energy[0] - trajectory.total_energy
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)
    assert np.max(np.abs(trajectory.energy_balance)) <= 1e-8


def test_a_cart_held_on_its_stop_loads_the_pin_as_a_fixed_pivot():
    """The cart starts on its stop, pushed against it: held as a contact (a constraint row) throughout."""
    model = _cart_and_bar(stop=True)
    trajectory = kronlag.simulate(model, (0, T_END), *_start(0.0), **TIGHT)
    assert trajectory.success, trajectory.message
    (contact,) = [event for event in trajectory.events if isinstance(event, LimitEvent)]
    assert contact.kind == "contact" and contact.t == 0.0
    assert not _events(trajectory, "release")
    _check_fixed_pivot_swing(trajectory)


def test_a_cart_stuck_on_its_rail_loads_the_pin_as_a_fixed_pivot():
    """The cart starts at rest on a rail with exact stiction (mu_s N well above what the bar pulls): it
    sticks (held by its "stick rail" row) while the bar's pin slides."""
    model = _cart_and_bar(stop=False, rail=kronlag.Friction(kinetic=0.5, static=0.6, stribeck_velocity=0.01,
                                                             law="exact"))
    trajectory = kronlag.simulate(model, (0, T_END), *_start(0.0), **TIGHT)
    assert trajectory.success, trajectory.message
    stiction = [event for event in trajectory.events if isinstance(event, StictionEvent)]
    assert [(event.joint, event.kind) for event in stiction] == [("rail", "stick"), ("pin", "slip")]
    held = trajectory.friction_held[:, 0]
    assert np.all(np.isfinite(held)) and np.max(np.abs(held)) > 5.0  # held throughout, and loaded
    assert np.all(np.isnan(trajectory.friction_held[:, 1]))  # the pin slides throughout
    # its friction column is r mu N against its rate at every output, the first (rate still 0) included
    columns = trajectory.columns()
    np.testing.assert_allclose(columns["pin.friction"], -RADIUS * MU * columns["pin.normal_load"], rtol=1e-12)
    np.testing.assert_allclose(columns["rail.friction"], held, rtol=1e-12)
    _check_fixed_pivot_swing(trajectory)


@pytest.mark.parametrize("outputs", [None, 101], ids=["every step", "t_eval"])
def test_the_balance_across_an_impact_onto_a_stop_is_the_impacts_loss(outputs):
    """The cart, pushed, runs into its stop (e = 0) and stays: ``E - E0 - W`` is zero before the impact,
    then the kinetic energy the impact took, ``1/2 (qd+^T M qd+ - qd-^T M qd-)`` at the impact's state,
    and stays so while the cart is held; with sparse outputs (``t_eval``: the impact between two of them)
    the work is integrated up to the impact and from it all the same."""
    model = _cart_and_bar(stop=True)
    q0, qd0 = _start(0.0)
    q0[[0, 3]] -= 0.05  # 5 cm from the stop
    t_eval = None if outputs is None else np.linspace(0, T_END, outputs)
    trajectory = kronlag.simulate(model, (0, T_END), q0, qd0, t_eval=t_eval, **TIGHT)
    assert trajectory.success, trajectory.message
    (impact,) = _events(trajectory, "impact")
    assert _events(trajectory, "contact") and not _events(trajectory, "release")
    assert impact.speed_after == pytest.approx(0.0, abs=1e-12)
    # the impact's loss from the state just before it (P = M (1 + e) J qd- along J: e = 0)
    dense = trajectory if outputs is None else kronlag.simulate(model, (0, T_END), q0, qd0, **TIGHT)
    before, after = np.flatnonzero(dense.t == impact.t)
    loss = dense.total_energy[before] - dense.total_energy[after]
    assert loss > 0.1
    if outputs is not None:
        assert impact.t not in trajectory.t
    split = after if outputs is None else np.searchsorted(trajectory.t, impact.t)  # the first output after it
    np.testing.assert_allclose(trajectory.energy_balance[:split], 0.0, atol=1e-8)
    np.testing.assert_allclose(trajectory.energy_balance[split:], -loss, atol=1e-8)
    # the loss is the event's, from its states before and after: the integration's own drift stays zero
    np.testing.assert_allclose(trajectory.event_energy[split:], -loss, atol=1e-9)
    assert np.max(np.abs(trajectory.energy_drift)) <= 1e-8


def test_the_energy_drift_of_a_bouncing_ball_leaves_out_what_its_impacts_took():
    """A ball dropped from h0 = 1 m (e = 0.5) bounces until the Zeno rule rests it on the floor: its impacts
    took m g h0 (no other force does work), so ``E - E0 - W`` ends at -m g h0 and the drift that
    ``kronlag simulate`` and the sweeps report (``energy_drift``, before: the balance itself, 4.9 J) is the
    integration's error alone."""
    y, m, g = sp.symbols("y m g")
    system = kronlag.System([y], parameters=[m, g], gravity=(0, -g), name="ball")
    system.add_body(kronlag.PointMass("ball", mass=m, position=[0, y]))
    system.add_limit(y, lower=0, restitution=0.5, name="floor")
    model = kronlag.derive(system).numeric({"m": 0.5, "g": G})
    trajectory = kronlag.simulate(model, (0, 2), [1.0], [0.0], **TIGHT)
    assert _events(trajectory, "contact") and trajectory.q[-1, 0] == pytest.approx(0.0, abs=1e-12)
    impacts = _events(trajectory, "impact")
    taken = sum(0.5 * 0.5 * (event.speed_before ** 2 - event.speed_after ** 2) for event in impacts)
    assert taken == pytest.approx(0.5 * G * 1.0, rel=1e-9)
    assert trajectory.energy_balance[-1] == pytest.approx(-taken, rel=1e-9)
    assert trajectory.event_energy[-1] == pytest.approx(-taken, rel=1e-9)
    assert np.max(np.abs(trajectory.energy_drift)) <= 1e-9
    summary = summarize(trajectory)
    assert summary.energy_drift <= 1e-9 and summary.event_energy == pytest.approx(-taken, rel=1e-9)
    assert f"changed the energy by {-taken:.6g}, apart from the drift" in summary.report()


# -- controllers: the work of inputs held between samples, and of inputs that vary along the motion ------


def test_a_sampled_controllers_work_is_that_of_its_held_inputs():
    """Under the PID of a model file (zero-order hold, a sample every 0.02 s) the work on the mass is exactly
    ``sum_k u_k (x_(k+1) - x_k)`` over the outputs (u_k held from output k), and ``E - E0 - W`` closes to
    rounding (before: 0.036 J of 0.57 J, the jump of u at each sample smeared over the outputs' rule)."""
    trajectory = simulate_model(loads_model(MASS_ON_A_LINE), method="ali3p")
    assert trajectory.success, trajectory.message
    assert len(trajectory.sample_times) == 100 and trajectory.sample_times[1] == pytest.approx(0.02)
    u, x = trajectory.inputs["u"], trajectory.q[:, 0]
    held = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(x))])
    np.testing.assert_allclose(trajectory.nonconservative_work, held, rtol=0, atol=1e-10)
    assert np.max(np.abs(trajectory.energy_balance)) <= 1e-10
    # outputs between the sample instants cannot resolve the jumps: said, not silent
    sparse = simulate_model(loads_model(MASS_ON_A_LINE), method="ali3p", t_eval=np.linspace(0.005, 1.995, 50))
    with pytest.warns(KronlagWarning, match="99 of the controller's sample instants fall between outputs"):
        _ = sparse.energy_balance


def test_a_continuous_controllers_work_follows_its_inputs_along_the_motion():
    """The cart-pole under its file's LQR state feedback (u a function of the state): ``E - E0 - W`` closes to
    1e-6 of the controller's work (1e-7 seen; before: 2.5e-4 of it, the inputs held over the rule's
    derivative, their rate along the motion left out)."""
    trajectory = simulate_model(kronlag.load_model(Path(__file__).parents[1] / "examples" / "cart_pole.toml"))
    assert trajectory.success, trajectory.message
    work = np.max(np.abs(trajectory.nonconservative_work))
    assert work > 0.05
    assert np.max(np.abs(trajectory.energy_balance)) <= 1e-6 * work


def test_the_balance_between_two_events_closes_when_no_output_is_at_either():
    """A pendulum with exact pin friction swings through several turning points ('reverse' events); outputs
    every 7 ms fall on none of them, so each swing's piece has its start and its end added to the outputs
    for the quadrature of W, in time order: the balance closes as with outputs at every step."""
    model = kronlag.derive(pin_friction_pendulum(law="exact")).numeric(PIN_FRICTION_PENDULUM_VALUES)
    angle = 0.6
    q, qd = model.assemble([0, 0, angle - np.pi / 2], fixed={model.coordinate_names[2]: angle - np.pi / 2})
    trajectory = kronlag.simulate(model, (0, 3.0), q, qd, rtol=1e-11, atol=1e-12, t_eval=np.arange(0, 3.0, 0.007))
    assert trajectory.success, trajectory.message
    turns = [event.t for event in trajectory.events if isinstance(event, StictionEvent) and event.kind == "reverse"]
    assert len(turns) >= 3 and not np.isin(turns, trajectory.t).any()
    assert -trajectory.friction_work[-1] > 1e-2  # the friction's work is what the balance must follow
    np.testing.assert_allclose(trajectory.energy_balance, 0.0, atol=1e-8)


def test_the_works_multipliers_at_a_singular_state_raise_as_forward_dynamics_does():
    """The power of the constraint forces and friction is evaluated for all samples in one batch; a state
    the batch cannot solve (rank -1, NaN) must raise the error naming it, never pass NaN into W."""
    from helpers import derived, parameter_values

    from kronlag.simulation.energy import _multipliers

    values = {**parameter_values("double_pendulum"), "m2": 0.0, "I2": 0.0}
    model = derived("double_pendulum").numeric(values)
    with pytest.raises(kronlag.SingularConfigurationError, match=r"q = \[0.1, 0.2\]"):
        _multipliers(model, np.array([0.0, 0.5]), np.array([[0.1, 0.2], [0.3, 0.4]]), np.zeros((2, 2)))
