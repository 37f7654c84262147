"""Body points and joints in model files: the shipped slider-crank engine file
against the built-in slider-crank, and its reactions over a driven revolution against Newton's law."""

import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag.app.workflows import driven_model, inverse_dynamics_along, parse_drive
from kronlag.core.errors import ModelFileError
from kronlag.model.builtin import example_path
from kronlag.model.modelfile.reader import loads_model
from kronlag.model.modelfile.writer import to_toml
from kronlag.numeric.reactions import joint_reaction

ENGINE = example_path("slider_crank_engine")


@pytest.fixture(scope="module")
def engine():
    model = kronlag.load_model(ENGINE)
    return model, kronlag.derive(model.system).numeric(model.numeric_values(), backend="python")


def test_engine_file_has_named_points_joints_and_constraint_rows(engine):
    model, _ = engine
    system = model.system
    assert [c.name for c in system.constraints] == [
        "main_bearing.x", "main_bearing.y", "crank_pin.x", "crank_pin.y", "wrist_pin.x", "wrist_pin.y",
        "cylinder.normal", "cylinder.angle"]
    assert [joint.name for joint in system.joints] == ["main_bearing", "crank_pin", "wrist_pin", "cylinder"]
    assert system.point("crank_pin").body == "crank"
    assert system.drawing[0].points[1] == system.point("crank_pin").position


def test_engine_has_the_dynamics_of_the_builtin_slider_crank(engine):
    model, numeric = engine
    values = model.numeric_values()
    shared = {name: values[name] for name in ("l1", "l2", "m1", "m2", "m3", "I1", "I2", "g")}
    reference = kronlag.derive(kronlag.models.slider_crank()).numeric({**shared, "tau": 3.0}, backend="python")
    numeric = kronlag.derive(model.system).numeric({**values, "tau": 3.0}, backend="python")
    for crank in (0.4, 2.0, 4.0):
        q, qd = reference.assemble([crank, -0.1, 0.2], fixed={"q1": crank}, qd_fixed={"q1": 20.0})
        guess = np.zeros(numeric.m)
        guess[[2, 5, 6]] = crank, q[1], q[2]
        Q, QD = numeric.assemble(guess, fixed={"theta_crank": crank}, qd_fixed={"theta_crank": 20.0})
        expected = reference.forward_dynamics(q, qd).qdd
        result = numeric.forward_dynamics(Q, QD).qdd
        assert np.allclose(result[[2, 5, 6]], expected, rtol=1e-9)


def test_piston_obeys_newton_over_a_driven_revolution(engine):
    """m3 a_piston = m3 g + (wrist pin force on the piston) + (cylinder force on the piston)."""
    model, numeric = engine
    omega = 157.0
    times = np.linspace(0, 2 * np.pi / omega, 13)
    drives = dict([parse_drive(f"theta_crank = {omega} * t", model)])
    run = inverse_dynamics_along(model, drives, times)
    numeric = driven_model(model, drives)
    assert run.success
    wrist = joint_reaction(numeric, "wrist_pin", run.t, run.q, run.lam).force
    cylinder = joint_reaction(numeric, "cylinder", run.t, run.q, run.lam)
    total = wrist + cylinder.force + 0.5 * np.array([0, -9.81])
    assert np.allclose(0.5 * run.qdd[:, 6:8], total, atol=1e-9 * np.max(np.abs(wrist)))
    assert np.allclose(cylinder.force[:, 0], 0, atol=1e-9)  # a frictionless guide pushes normal to its axis
    assert np.array_equal(run.columns()["wrist_pin.Fy"], wrist[:, 1])


@pytest.mark.parametrize("change, message", [
    (('type = "prismatic"', 'type = "hinge"'), r"joints\[3\]: joint 'cylinder': unknown 2-d joint kind 'hinge'"),
    (('at_a = "small_end"', 'at_a = "wrist"'), r"joints\[2\].*point 'wrist' is on 'piston', not on 'rod'"),
    (('points = {wrist = [0, 0]}', 'points = {main = [0, 0]}'), r"bodies\[2\].points.main: .*used twice"),
    (('points = {wrist = [0, 0]}', 'points = {wrist = [0, 0, 0]}'), r"bodies\[2\].points.wrist: expected 2"),
])
def test_model_file_joint_errors_name_the_entry(change, message):
    text = ENGINE.read_text()
    assert change[0] in text
    with pytest.raises(ModelFileError, match=message):
        loads_model(text.replace(change[0], change[1]), source="engine.toml")


def test_point_coordinates_can_be_used_in_constraints_and_forces():
    """``crank_pin_y`` in a constraint is the world y of the named body point."""
    text = ENGINE.read_text().replace("[parameters]", '[parameters]\nk = {value = 50.0, unit = "N/m"}').replace(
        "[[torques]]", '''[[constraints]]
name = "pin on the axis"
expression = "crank_pin_y"

[[forces]]
name = "push"
point = "wrist"
force = ["-k*wrist_x", 0]

[[torques]]''')
    system = loads_model(text, source="engine.toml").system
    assert system.constraints[-1].expression == system.point("crank_pin").position[1]
    force = next(f for f in system.forces if f.name == "push")
    assert force.value[0] == -sp.Symbol("k") * system.point("wrist").position[0]
    clash = ENGINE.read_text().replace("[parameters]", "[parameters]\nwrist_x = 1.0")
    with pytest.raises(ModelFileError, match=r"bodies\[2\].points.wrist: the coordinate names wrist_x"):
        loads_model(clash, source="engine.toml")


def test_written_engine_reads_back_with_its_points_and_joints():
    written = to_toml(kronlag.models.slider_crank_engine())
    assert "[[joints]]" in written and "crank_pin.x" not in written
    again = loads_model(written, source="written.toml").system
    original = kronlag.models.slider_crank_engine()
    assert [j.name for j in again.joints] == [j.name for j in original.joints]
    assert [c.name for c in again.constraints] == [c.name for c in original.constraints]
    assert [sp.simplify(a.expression - b.expression) for a, b in zip(again.constraints, original.constraints)] \
        == [0] * len(original.constraints)
    assert {name: point.position for name, point in again.points.items()} == \
        {name: point.position for name, point in original.points.items()}
    assert [j.wrench for j in again.joints] == [j.wrench for j in original.joints]
