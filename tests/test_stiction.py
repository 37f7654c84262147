"""Exact stiction (issue 18.2, 18.4): ``Friction(law="exact")`` against closed forms, through the Python
API and model files, on the default method with friction (compiled CVODE) and the Python backend."""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import (
    PIN_FRICTION_PENDULUM_VALUES,
    pin_friction_pendulum,
    pin_friction_pendulum_file,
)

import kronlag
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.simulation.trajectory import StictionEvent

G = 9.81
ALPHA = 0.5  # tan(alpha) = 0.546
MASS = 2.0


def _backends() -> list[str]:
    from kronlag.numeric import codegen

    return ["python", "c"] if codegen.c_compiler() else ["python"]


def _incline_system(static: float, kinetic: float):
    m, g = sp.symbols("m g")
    system = mechanism([free_body("block", mass=m, inertia=m / 6)], parameters=[m, g], gravity=(0, -g))
    system.add_joint("prismatic", "ground", "block", axis=(np.cos(ALPHA), -np.sin(ALPHA)), name="guide",
                     friction=kronlag.Friction(kinetic=kinetic, static=static, law="exact"))
    return system


INCLINE_FILE = """
name = "incline"
coordinates = ["x", "y", "th"]
gravity = [0, "-g"]

[parameters]
m = {value = 2.0, unit = "kg"}
g = {value = 9.81, unit = "m/s^2"}
alpha = {value = 0.5, unit = "rad"}
mu_s = STATIC
mu_k = KINETIC
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
friction = {law = "exact", static = "mu_s", kinetic = "mu_k"}
"""


def _incline(static: float, kinetic: float, source: str, tmp_path=None):
    """The block on the incline (axis down the slope), from the API with the backend ``source`` or from a
    model file (``source == "file"``)."""
    if source == "file":
        path = tmp_path / "incline.toml"
        path.write_text(INCLINE_FILE.replace("STATIC", repr(static)).replace("KINETIC", repr(kinetic)))
        model_file = kronlag.load_model(path)
        return kronlag.derive(model_file.system).numeric(model_file.numeric_values())
    return kronlag.derive(_incline_system(static, kinetic)).numeric({"m": MASS, "g": G}, backend=source)


SOURCES = [*_backends(), "file"]
DOWN = np.array([np.cos(ALPHA), -np.sin(ALPHA)])


def _run(model, v0: float, t_end: float):
    trajectory = kronlag.simulate(model, (0, t_end), np.zeros(3), [*(v0 * DOWN), 0.0], rtol=1e-11, atol=1e-12)
    assert trajectory.success, trajectory.message
    return trajectory, trajectory.q[:, :2] @ DOWN


def _stiction_events(trajectory) -> list[StictionEvent]:
    return [event for event in trajectory.events if isinstance(event, StictionEvent)]


@pytest.mark.parametrize("source", SOURCES)
def test_block_below_the_friction_angle_sticks_exactly(source, tmp_path):
    """tan(alpha) <= mu_s from rest: held from t0 (event 'stick'), position constant, friction force
    m g sin(alpha) (the holding row's multiplier) and normal load m g cos(alpha)."""
    model = _incline(0.6, 0.4, source, tmp_path)
    trajectory, distance = _run(model, 0.0, 2.0)
    events = _stiction_events(trajectory)
    assert [(event.kind, event.t) for event in events] == [("stick", 0.0)]
    np.testing.assert_allclose(distance, 0.0, atol=1e-12)
    np.testing.assert_allclose(trajectory.q[:, 2], 0.0, atol=1e-12)
    columns = trajectory.columns()
    np.testing.assert_allclose(columns["guide.friction"], MASS * G * np.sin(ALPHA), rtol=1e-12)
    np.testing.assert_allclose(columns["guide.normal_load"], MASS * G * np.cos(ALPHA), rtol=1e-12)
    np.testing.assert_allclose(trajectory.friction_work, 0.0, atol=1e-12)


@pytest.mark.parametrize("source", SOURCES)
def test_block_above_the_friction_angle_slips_and_slides_by_the_closed_form(source, tmp_path):
    """tan(alpha) > mu_s from rest: slips at t0 (event 'slip' down the slope) and slides with
    a = g (sin(alpha) - mu_k cos(alpha)); the energy lost is the friction work."""
    model = _incline(0.5, 0.4, source, tmp_path)
    trajectory, distance = _run(model, 0.0, 1.5)
    events = _stiction_events(trajectory)
    assert [(event.kind, event.t) for event in events] == [("slip", 0.0)] and events[0].force > 0
    acceleration = G * (np.sin(ALPHA) - 0.4 * np.cos(ALPHA))
    np.testing.assert_allclose(distance, acceleration * trajectory.t ** 2 / 2, rtol=1e-9, atol=1e-12)
    columns = trajectory.columns()
    np.testing.assert_allclose(columns["guide.friction"][1:], 0.4 * MASS * G * np.cos(ALPHA), rtol=1e-10)
    lost = trajectory.total_energy[0] - trajectory.total_energy
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)


@pytest.mark.parametrize("source", SOURCES)
@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_pushed_block_stops_at_the_closed_form_time_and_distance_and_stays(source, direction, tmp_path):
    """Pushed at v0 down (mu_k cos(alpha) > sin(alpha)) or up the slope: decelerates at
    g (mu_k cos(alpha) -+ sin(alpha)), stops at t = v0 / d, s = v0^2 / (2 d) (event 'stick' there, located
    by root finding), then stays (friction m g sin(alpha) <= mu_s m g cos(alpha)); energy lost = friction work."""
    model = _incline(0.7, 0.6, source, tmp_path)
    v0 = 1.0 * direction
    trajectory, distance = _run(model, v0, 4.0)
    deceleration = G * (0.6 * np.cos(ALPHA) - direction * np.sin(ALPHA))
    stop_time, stop_distance = abs(v0) / deceleration, direction * v0 ** 2 / (2 * deceleration)
    events = _stiction_events(trajectory)
    assert [event.kind for event in events] == ["stick"]
    assert abs(events[0].t - stop_time) <= 1e-9 * stop_time
    np.testing.assert_allclose(distance[trajectory.t >= events[0].t], stop_distance, rtol=1e-9)
    # the stop is a sample twice: the sliding segment's end, then the held one's start
    sliding = np.arange(len(trajectory.t)) <= np.argmax(trajectory.t >= events[0].t)
    np.testing.assert_allclose(distance[sliding], v0 * trajectory.t[sliding]
                               - direction * deceleration * trajectory.t[sliding] ** 2 / 2, rtol=1e-9, atol=1e-12)
    columns = trajectory.columns()
    np.testing.assert_allclose(columns["guide.friction"][~sliding], MASS * G * np.sin(ALPHA), rtol=1e-9)
    lost = trajectory.total_energy[0] - trajectory.total_energy
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)


# -- a Coulomb-damped pendulum -----------------------------------------------------------------------

PENDULUM_FILE = pin_friction_pendulum_file('{law = "exact", kinetic = "mu", radius = "r"}')

MU, RADIUS, LENGTH = 0.1, 0.01, 0.9


def _pendulum(source: str, tmp_path):
    if source == "file":
        path = tmp_path / "pendulum.toml"
        path.write_text(PENDULUM_FILE)
        model_file = kronlag.load_model(path)
        return kronlag.derive(model_file.system).numeric(model_file.numeric_values())
    return kronlag.derive(pin_friction_pendulum(law="exact")).numeric(PIN_FRICTION_PENDULUM_VALUES, backend=source)


def _swing(model, angle: float, t_end: float):
    """Released at rest ``angle`` off the downward vertical."""
    q, qd = model.assemble([0, 0, angle - np.pi / 2], fixed={model.coordinate_names[2]: angle - np.pi / 2})
    # steps of at most 0.02 s: the energy balance's quadrature between the outputs (O(h^5)) below 1e-8
    trajectory = kronlag.simulate(model, (0, t_end), q, qd, rtol=1e-11, atol=1e-12, max_step=0.02)
    assert trajectory.success, trajectory.message
    return trajectory


@pytest.mark.parametrize("source", [pytest.param(source, marks=pytest.mark.slow) if source == "python" else source
                                    for source in SOURCES])
def test_coulomb_damped_pendulum_decays_by_the_closed_form_and_comes_to_rest(source, tmp_path):
    """I_O th'' = -m g l_c sin(th) - tau_f sign(th'), tau_f = mu r N, N = m g (1 + O(th^2)): each half swing
    takes 2 mu r / l_c off the amplitude (turning points: the 'reverse' events, located by root finding);
    the bar sticks at the first turning point where m g l_c |sin(th)| <= mu r N = mu r m g (at rest N = m g
    exactly), and stays there.  Energy lost = friction work to 1e-8."""
    model = _pendulum(source, tmp_path)
    start, half = 0.04, LENGTH / 2
    decrement = 2 * MU * RADIUS / half
    trajectory = _swing(model, start, 10.0)
    events = _stiction_events(trajectory)
    assert events[0].kind == "slip" and events[0].t == 0.0
    turning = [event for event in events[1:] if event.kind == "reverse"]
    amplitudes = np.array([start] + [abs(event.q[2] + np.pi / 2) for event in turning])
    np.testing.assert_allclose(-np.diff(amplitudes), decrement, rtol=5e-3)
    assert events[-1].kind == "stick"
    rest = events[-1].q[2] + np.pi / 2
    assert abs(np.sin(rest)) <= MU * RADIUS / half < abs(np.sin(amplitudes[-1]))
    # closed form (linear): the amplitudes start - k * decrement until the first one <= mu r / l_c
    predicted = start - decrement * np.arange(len(amplitudes) + 1)
    assert len(amplitudes) == np.argmax(predicted <= MU * RADIUS / half)
    np.testing.assert_allclose(abs(rest), predicted[len(amplitudes)], rtol=0, atol=1e-2 * decrement)
    after = trajectory.t >= events[-1].t
    np.testing.assert_allclose(trajectory.q[after, 2] + np.pi / 2, rest, atol=1e-12)
    lost = trajectory.total_energy[0] - trajectory.total_energy
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)


def test_methods_without_exact_stiction_refuse_it():
    model = _incline(0.6, 0.4, "python")
    with pytest.raises(kronlag.InputError, match="does not support exact stiction"):
        kronlag.simulate(model, (0, 1), np.zeros(3), np.zeros(3), method="ggl")


def test_exact_law_is_written_to_model_files_and_read_back(tmp_path):
    from kronlag.model.modelfile.writer import to_toml

    path = tmp_path / "incline.toml"
    path.write_text(INCLINE_FILE.replace("STATIC", "0.6").replace("KINETIC", "0.4"))
    (tmp_path / "again.toml").write_text(to_toml(kronlag.load_model(path)))
    friction = kronlag.load_model(tmp_path / "again.toml").system.joints[0].friction
    assert friction.law == "exact" and str(friction.static) == "mu_s" and str(friction.kinetic) == "mu_k"


def _exact_example(name: str, tmp_path):
    """``examples/<name>.toml`` with the exact law in every joint: ``(model, q0, qd0)``."""
    from kronlag.app.workflows import initial_state, numeric_model

    text = Path(f"examples/{name}.toml").read_text()
    text = "\n".join(line.split(", smoothing_velocity")[0] + ', law = "exact"}' if line.startswith("friction =")
                     else line for line in text.splitlines())
    path = tmp_path / f"{name}_exact.toml"
    path.write_text(text)
    model_file = kronlag.load_model(path, apply_drives=False)
    model = numeric_model(model_file)
    return (model, *initial_state(model_file, model))


def _one_event_per_joint_and_instant(events: list[StictionEvent]) -> None:
    keys = [(event.t, event.joint) for event in events]
    assert len(keys) == len(set(keys)), keys


def test_four_bar_with_exact_friction_in_every_pin_rubs_against_every_rate(tmp_path):
    """The four-bar of examples/four_bar_friction.toml with the exact law in its four pins: the pins'
    relative rotations reverse while the linkage moves (kinematic dead points: 'reverse' events, not
    stops) and the whole linkage reverses at once (all four pins stop at t = 0.9149: one pin holds the group,
    the others locked to it, no redundant holds; its holding torque far beyond the group's capacity), one
    event per pin and instant; each joint's friction opposes its
    rate at every output (friction power <= 0) and the energy lost is the friction work (to 1e-8 J: the
    power's jumps at the events are integrated from each segment's side)."""
    model, q0, qd0 = _exact_example("four_bar_friction", tmp_path)
    with warnings.catch_warnings():  # the linkage stopping in all its pins: one holds, the others are locked
        warnings.simplefilter("error", kronlag.RedundantConstraintsWarning)
        trajectory = kronlag.simulate(model, (0, 2.0), q0, qd0, rtol=1e-10, atol=1e-12)
    assert trajectory.success, trajectory.message
    kinds = {event.kind for event in _stiction_events(trajectory)}
    assert "reverse" in kinds
    _one_event_per_joint_and_instant(_stiction_events(trajectory))
    columns = trajectory.columns()
    assert np.max(columns["friction_power"]) <= 1e-9
    lost = trajectory.total_energy[0] - trajectory.total_energy
    assert lost[-1] > 2.0  # a real loss (2.74 J)
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)


def test_four_bar_stopping_in_all_pins_is_decided_whatever_the_residual_rates(tmp_path, monkeypatch):
    """At the four-bar's all-pins-stop instant (t = 0.9149) the pins' rates cross zero together (the rates
    are one pin's times rate ratios): which of them the root finder flags and the residual rates, ~1e-12 on
    either side of the at-rest limit (atol), hang on the last bits (the run's step sequence).  The pins stop
    together because the constraints make them (each pin's row is a combination of the loop's and one
    pin's), so the decision -- the whole linkage reverses, every pin at once -- must not change with the pins
    flagged or with those rates scaled by 1/10 or 10 (before: the rocker pin flagged alone left the crank pin
    sliding at 1.2e-12 while the others were decided, and it reversed in a second decision at the same
    instant; with the rates scaled by 1/10, all four were decided together; and the rocker pivot flagged
    alone, near its own dead point, held the group with a poor leverage and the run refused)."""
    import kronlag.simulation.impacts as impacts

    model, q0, qd0 = _exact_example("four_bar_friction", tmp_path)
    calls = []

    def recorded(variant_of, modes, triggered, t, y, names, rest):
        calls.append((variant_of, modes, list(triggered), t, y.copy(), names, rest))
        return impacts_transition(variant_of, modes, triggered, t, y, names, rest)

    impacts_transition = impacts.transition
    monkeypatch.setattr(impacts, "transition", recorded)
    trajectory = kronlag.simulate(model, (0, 0.92), q0, qd0, rtol=1e-10, atol=1e-12)
    assert trajectory.success, trajectory.message
    at_stop = [call for call in calls if abs(call[3] - 0.91494) < 1e-4]
    assert at_stop, [call[1:4] for call in calls]
    variant_of, modes, _, t, y, names, rest = at_stop[0]
    m = len(y) // 2
    rocker_pin = names.index("rocker pin")
    decisions = set()
    for flagged in ([[j] for j in range(len(names))] + [sorted({rocker_pin, names.index("crank pin")})]
                    + [list(range(len(names)))]):
        for scale in (0.1, 1.0, 10.0):
            scaled = np.concatenate([y[:m], scale * y[m:]])
            new, events = impacts_transition(variant_of, modes, flagged, t, scaled, names, rest)
            decisions.add((new, tuple(sorted((event.joint, event.kind) for event in events))))
    assert len(decisions) == 1, decisions
    new, events = decisions.pop()
    assert new == tuple(-mode for mode in modes)  # the linkage reverses: every pin's friction turns
    assert events == tuple(sorted((name, "reverse") for name in names))


def test_four_bar_dead_point_reversals_turn_inside_the_compiled_run(tmp_path, monkeypatch):
    """The four-bar's single-pin reversals are kinematic dead points (the pin's rate zero for every motion
    the loop allows, so it passes through zero): the compiled driver turns those directions itself (kl_turn
    in c/cvode.c) and returns to Python only at the three instants where the whole linkage stops -- 4 driver
    runs instead of one per event instant (18) -- with the same events (joints, kinds, times to 1e-9), the
    same pieces of the trajectory (one model each) and an energy balance that closes as when every event
    goes back to Python (turning disabled: _MAX_TURNS = 0)."""
    import kronlag.simulation.impacts as impacts
    import kronlag.simulation.solvers.compiled as compiled

    model, q0, qd0 = _exact_example("four_bar_friction", tmp_path)
    starts = []
    segment = impacts._LimitRun._segment

    def counted(self, solver, problem):
        starts.append(problem.t0)
        return segment(self, solver, problem)

    monkeypatch.setattr(impacts._LimitRun, "_segment", counted)
    runs = {}
    for turns in (1000, 0):
        monkeypatch.setattr(compiled, "_MAX_TURNS", turns)
        starts.clear()
        trajectory = kronlag.simulate(model, (0, 2.0), q0, qd0, method="compiled", rtol=1e-10, atol=1e-12)
        assert trajectory.success, trajectory.message
        runs[turns] = (trajectory, len(starts))
    (inside, inside_runs), (outside, outside_runs) = runs[1000], runs[0]
    assert (inside_runs, outside_runs) == (4, 18)
    events = [_stiction_events(trajectory) for trajectory in (inside, outside)]
    assert [(event.joint, event.kind) for event in events[0]] == [(event.joint, event.kind) for event in events[1]]
    np.testing.assert_allclose([event.t for event in events[0]], [event.t for event in events[1]], rtol=0, atol=1e-9)
    assert len(inside.segments) == len(outside.segments) == 18
    assert np.max(inside.columns()["friction_power"]) <= 1e-9
    lost = inside.total_energy[0] - inside.total_energy
    np.testing.assert_allclose(lost, -inside.friction_work, rtol=0, atol=1e-8)
    np.testing.assert_allclose(inside.q[-1], outside.q[-1], rtol=0, atol=1e-6)
    np.testing.assert_allclose(inside.qd[-1], outside.qd[-1], rtol=0, atol=1e-6)


def test_a_stop_on_a_joint_with_exact_friction_is_refused_where_the_load_division_is_indeterminate():
    """The block slides down the incline (tan alpha > mu_s) onto a stop across its guide (e = 0): resting on
    the stop, its guide's friction and the stop's contact force share one motion and any division of the
    load between them is as good as another.  The run stops there with the joint, the limit, t and q named
    (before, it went on with a minimum-norm division whose friction was 70 times r mu_s N, no slip)."""
    system = _incline_system(static=0.3, kinetic=0.2)
    x, y = system.coordinates[:2]
    system.add_limit(x * np.cos(ALPHA) - y * np.sin(ALPHA), upper=0.05, restitution=0, name="stop")
    model = kronlag.derive(system).numeric({"m": MASS, "g": G})
    with pytest.raises(kronlag.NumericalError, match=r"exact stiction at t = .*q = .*the motion of joint 'guide' "
                                                      r"is stopped by the contact of 'stop upper'.*law='smooth'"):
        kronlag.simulate(model, (0, 1.0), np.zeros(3), np.zeros(3))


def test_an_impact_that_turns_a_sliding_joint_reverses_its_friction():
    """The pendulum with exact pin friction swings onto a stop at its own angle (e = 0.6): the impulse turns
    the pin's rate, and its friction must turn with it (the watched d v starts below zero, so no root
    would ever say so: the friction would push the bar along, feeding energy in).  The energy lost is the
    friction work plus what the impacts take, 1/2 I_O (v-^2 - v+^2) with the gap speeds of the events."""
    model = _pendulum("c" if "c" in _backends() else "python", None)
    system = model.equations.system
    limited = copy.copy(system)
    limited.limits = list(system.limits)
    limited.add_limit(system.coordinates[2] + np.pi / 2, upper=0.03, restitution=0.6, name="stop")
    model = kronlag.derive(limited).numeric({"m": MASS, "L": LENGTH, "g": G, "mu": MU, "r": RADIUS})
    trajectory = _swing(model, -0.04, 1.5)
    impacts = [event for event in trajectory.events if getattr(event, "kind", "") == "impact"]
    assert impacts, "the bar must reach the stop"
    turned = [event for event in _stiction_events(trajectory) if event.kind == "reverse"
              and any(event.t == impact.t for impact in impacts)]
    assert turned, "the impact must reverse the pin's friction"
    inertia = MASS * LENGTH ** 2 / 3
    taken = sum(0.5 * inertia * (event.speed_before ** 2 - event.speed_after ** 2) for event in impacts)
    lost = trajectory.total_energy[0] - trajectory.total_energy[-1]
    np.testing.assert_allclose(lost, -trajectory.friction_work[-1] + taken, rtol=0, atol=1e-7)


# -- a locked pair: two pins geared together -----------------------------------------------------------

BAR_MASS, BAR_LENGTH, WHEEL_MASS, WHEEL_DISTANCE = 1.0, 1.0, 10.0, 2.0
BAR_PIN, WHEEL_PIN, MU_S, MU_K = 0.01, 0.05, 0.5, 0.4


def _geared_bar(angle: float):
    """A bar (mass 1, length 1) on a pin at one end at the origin, geared to a balanced wheel (mass 10) on a pin
    at its centre ``(2, 0)`` by ``th_wheel = -th_bar`` (a constraint on the angles: pure torques, no load on
    the pins); both pins with the exact law (mu_s 0.5, mu_k 0.4; radii 0.01 and 0.05).  Held at ``angle``
    above the horizontal and released at rest: ``(model, trajectory or the error)``."""
    m1, m2, L, g = sp.symbols("m1 m2 L g")
    system = mechanism([free_body("bar", mass=m1, inertia=m1 * L ** 2 / 12),
                        free_body("wheel", mass=m2, inertia=m2 / 8)], parameters=[m1, m2, L, g], gravity=(0, -g))
    friction = dict(static=MU_S, kinetic=MU_K, law="exact")
    system.add_joint("revolute", "ground", "bar", at_b=(-L / 2, 0), name="bar pin",
                     friction=kronlag.Friction(radius=BAR_PIN, **friction))
    system.add_joint("revolute", "ground", "wheel", at_a=(WHEEL_DISTANCE, 0), name="wheel pin",
                     friction=kronlag.Friction(radius=WHEEL_PIN, **friction))
    bar_angle, wheel_angle = system.coordinates[2], system.coordinates[5]
    system.add_constraint(wheel_angle + bar_angle, name="gear")
    model = kronlag.derive(system).numeric({"m1": BAR_MASS, "m2": WHEEL_MASS, "L": BAR_LENGTH, "g": G})
    names = model.coordinate_names
    q, qd = model.assemble([BAR_LENGTH / 2 * np.cos(angle), BAR_LENGTH / 2 * np.sin(angle), angle,
                            WHEEL_DISTANCE, 0, -angle], fixed={names[2]: angle})
    return model, q, qd


def _geared_thresholds() -> tuple[float, float]:
    """At rest the pins carry the weights (N = m g each: the gear's multiplier is a pair of torques) and the
    bar needs the holding torque tau = m1 g L/2 cos(angle) about its pin; the wheel pin's rate is minus the
    bar pin's, so its friction counts one for one.  The group holds iff tau <= r1 mu_s m1 g + r2 mu_s m2 g;
    the wheel pin alone holds it iff tau <= r2 mu_s m2 g.  Returned: the two torques."""
    alone = WHEEL_PIN * MU_S * WHEEL_MASS * G
    return alone, alone + BAR_PIN * MU_S * BAR_MASS * G


def _torque(angle: float) -> float:
    return BAR_MASS * G * BAR_LENGTH / 2 * np.cos(angle)


def test_a_locked_pair_held_by_one_pin_sticks_with_that_pin_holding_it():
    """tau just below the wheel pin's own capacity (the bar pin's own is 20 times too small): the geared pair
    sticks at the start and stays; the wheel pin holds tau (its friction column), the bar pin, locked to it,
    carries nothing, and no event is spurious (one 'stick' per pin at t0)."""
    alone, _ = _geared_thresholds()
    angle = np.arccos(0.98 * alone / (BAR_MASS * G * BAR_LENGTH / 2))
    model, q, qd = _geared_bar(angle)
    trajectory = kronlag.simulate(model, (0, 1.0), q, qd, rtol=1e-10, atol=1e-12)
    assert trajectory.success, trajectory.message
    events = _stiction_events(trajectory)
    assert sorted((event.joint, event.kind, event.t) for event in events) == [
        ("bar pin", "stick", 0.0), ("wheel pin", "stick", 0.0)]
    np.testing.assert_allclose(trajectory.q - q, 0.0, atol=1e-12)
    columns = trajectory.columns()
    np.testing.assert_allclose(np.abs(columns["wheel pin.friction"]), _torque(angle), rtol=1e-9)
    np.testing.assert_allclose(columns["wheel pin.normal_load"], WHEEL_MASS * G, rtol=1e-9)
    np.testing.assert_allclose(columns["bar pin.friction"], 0.0, atol=1e-12)


def test_a_locked_pair_beyond_the_combined_capacity_slips_as_a_whole():
    """tau 2 % above the combined capacity: both pins slip at t0 together (directions from the motion: the
    bar falls, th_bar decreasing, the wheel turning the other way) and the energy lost is the friction work."""
    _, combined = _geared_thresholds()
    angle = np.arccos(1.02 * combined / (BAR_MASS * G * BAR_LENGTH / 2))
    model, q, qd = _geared_bar(angle)
    trajectory = kronlag.simulate(model, (0, 0.3), q, qd, rtol=1e-10, atol=1e-12)
    assert trajectory.success, trajectory.message
    events = _stiction_events(trajectory)
    assert sorted((event.joint, event.kind, event.t) for event in events) == [
        ("bar pin", "slip", 0.0), ("wheel pin", "slip", 0.0)]
    assert trajectory.q[-1, 2] < angle - 1e-3 and trajectory.q[-1, 5] > -angle + 1e-3
    columns = trajectory.columns()
    assert np.all(columns["bar pin.rate"][1:] < 0) and np.all(columns["wheel pin.rate"][1:] > 0)
    lost = trajectory.total_energy[0] - trajectory.total_energy
    assert lost[-1] > 1e-3
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)


def test_a_locked_pair_between_one_pins_capacity_and_the_groups_is_refused():
    """tau between the wheel pin's own capacity and the combined one: it sticks only if the holding torque is
    divided between the pins, which the segments cannot watch: the run stops naming the pins, t, q and the
    smooth law (before, it held both pins redundantly with a minimum-norm division)."""
    alone, combined = _geared_thresholds()
    angle = np.arccos((alone + combined) / 2 / (BAR_MASS * G * BAR_LENGTH / 2))
    model, q, qd = _geared_bar(angle)
    with pytest.raises(kronlag.NumericalError, match=r"exact stiction at t = 0, q = .*'bar pin', 'wheel pin' "
                                                      r"are locked together.*law='smooth'"):
        kronlag.simulate(model, (0, 0.3), q, qd, rtol=1e-10, atol=1e-12)


def test_slider_crank_stopped_by_its_guide_holds_by_the_guide_alone_without_spurious_events(tmp_path):
    """examples/slider_crank_friction.toml with the exact law everywhere: the spinning crank is brought to
    rest and the guide sticks (t = 0.2815); the three pins are then locked to it (their rates zero for every
    motion the held guide allows): no friction of their own, one 'stick' each, and no event after.  The
    guide's holding force is the closed form of virtual work on the stopped linkage (pivot at the origin,
    guide on y = 0): f = g (m1 + m2) l1/2 cos(th) / |dx3/dth|, dx3/dth = -l1 sin(th) (1 + l1 cos(th) /
    sqrt(l2^2 - l1^2 sin^2(th))).  (Before, the pins 'slid' with r mu_k N in fixed directions while at rest,
    flipping with 6 'reverse' events at one instant, and the guide held 0.0125 N instead of 4.34 N.)"""
    model, q0, qd0 = _exact_example("slider_crank_friction", tmp_path)
    trajectory = kronlag.simulate(model, (0, 1.5), q0, qd0, rtol=1e-10, atol=1e-12)
    assert trajectory.success, trajectory.message
    events = _stiction_events(trajectory)
    _one_event_per_joint_and_instant(events)
    stop = events[-1].t
    assert 0.28 < stop < 0.29
    assert sorted((event.joint, event.kind) for event in events if event.t == stop) == [
        ("crank pin", "stick"), ("guide", "stick"), ("main bearing", "stick"), ("wrist pin", "stick")]
    l1, l2, m1, m2 = 0.1, 0.3, 1.0, 2.0
    angle = events[-1].q[2]
    slope = l1 * np.sin(angle) * (1 + l1 * np.cos(angle) / np.sqrt(l2 ** 2 - (l1 * np.sin(angle)) ** 2))
    holding = G * (m1 + m2) * l1 / 2 * np.cos(angle) / slope
    columns = trajectory.columns()
    after = trajectory.t > stop
    np.testing.assert_allclose(np.abs(columns["guide.friction"][after]), holding, rtol=1e-8)
    assert np.all(np.abs(columns["guide.friction"][after]) <= 0.15 * columns["guide.normal_load"][after])
    for pin in ("main bearing", "crank pin", "wrist pin"):
        np.testing.assert_allclose(columns[f"{pin}.friction"][after], 0.0, atol=1e-12)
    np.testing.assert_allclose(trajectory.q[after] - events[-1].q, 0.0, atol=1e-10)
    assert np.max(columns["friction_power"]) <= 1e-9
    lost = trajectory.total_energy[0] - trajectory.total_energy
    np.testing.assert_allclose(lost, -trajectory.friction_work, rtol=0, atol=1e-8)


def test_a_joint_that_would_hold_a_locked_partner_still_taken_as_sliding_refuses():
    """The direction check of the joints at rest (``_consistent``) holds a joint that decelerates whichever way
    it slides; in the geared pair at rest both pins taken as sliding (kinetic friction in fixed directions)
    decelerate either way below their combined kinetic capacity, and holding one locks the other, whose
    friction was then not a sliding one: that judgement is unsure, so it refuses instead of keeping the
    partner sliding at rest."""
    from kronlag.core.errors import NumericalError
    from kronlag.simulation.stiction import _consistent, stiction_model

    _, combined = _geared_thresholds()
    angle = np.arccos(0.5 * MU_K / MU_S * combined / (BAR_MASS * G * BAR_LENGTH / 2))
    model, q, qd = _geared_bar(angle)
    with pytest.raises(NumericalError, match="'bar pin', 'wheel pin'|'wheel pin', 'bar pin'"):
        _consistent(lambda modes: stiction_model(model, modes), [1, 1], 0.0, np.concatenate([q, qd]), 1e-12,
                    ["bar pin", "wheel pin"])
