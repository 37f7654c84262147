"""Reports that tell the truth (issue 17, deliverable 7): neutral modes print as 0 with shapes by
coordinate name; multipliers and reactions by constraint and joint name with their units; the
reactions of an equilibrium and of an inverse-dynamics run as :class:`Reaction` objects; a model
file's drives not applied silently; ``check`` assembles the initial state; ``--version``, the
methods in ``--help`` and plain-text help; ``Piecewise``, ``Min``, ``Max`` and ``Heaviside`` in
forces on both backends."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import re
import warnings

import matplotlib
import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag.app.analysis_commands import modes_report
from kronlag.app.cli import build_parser, main
from kronlag.app.commands import method_help
from kronlag.app.workflows import inverse_dynamics_along, parse_drive
from kronlag.model.builtin import example_path, load_example, resolve_model
from kronlag.model.modelfile import load_model, loads_model
from kronlag.numeric import codegen
from kronlag.numeric.reactions import Reaction, multiplier_units
from kronlag.numeric.tolerances import ZERO_EIGENVALUE_RTOL
from kronlag.simulation import METHODS
from kronlag.views.plotting import plot_trajectory

from helpers import backend_params

matplotlib.use("Agg")

#: A pendulum (arm, 2 kg) pinned at the origin carrying a free wheel (2 kg) on a pin at its tip:
#: hanging, the shoulder carries 4 kg and the hub 2 kg, and the wheel's spin is a neutral mode.
ARM_AND_WHEEL = """
name = "arm_and_wheel"
coordinates = ["x1", "y1", "th1", "x2", "y2", "th2"]
gravity = [0, "-g"]

[parameters]
m = {value = 2.0, unit = "kg"}
l = {value = 0.5, unit = "m"}
g = {value = 9.81, unit = "m/s^2"}
I = {value = "m*l**2/12", unit = "kg*m^2"}

[[bodies]]
name = "arm"
type = "planar"
mass = "m"
inertia = "I"
position = ["x1", "y1"]
angle = "th1"

[[bodies]]
name = "wheel"
type = "planar"
mass = "m"
inertia = "I"
position = ["x2", "y2"]
angle = "th2"

[[joints]]
name = "shoulder"
type = "revolute"
body_a = "ground"
body_b = "arm"
at_a = [0, 0]
at_b = ["-l/2", 0]

[[joints]]
name = "hub"
type = "revolute"
body_a = "arm"
body_b = "wheel"
at_a = ["l/2", 0]
at_b = [0, 0]

[initial]
q = {x1 = 0.01, y1 = -0.25, th1 = -1.5, x2 = 0.01, y2 = -0.5, th2 = 0.3}
"""

G = 9.81


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(arg) for arg in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope="module")
def arm_and_wheel_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("reports") / "arm_and_wheel.toml"
    path.write_text(ARM_AND_WHEEL)
    return path


@pytest.fixture(scope="module")
def arm_and_wheel(arm_and_wheel_file):
    model = load_model(arm_and_wheel_file)
    return kronlag.derive(model.system).numeric(model.numeric_values(), backend="python"), model


# -- modes ------------------------------------------------------------------------------------------


def test_a_neutral_mode_with_rounding_prints_as_zero_with_its_shape_by_coordinate_name(arm_and_wheel):
    numeric, model = arm_and_wheel
    rest = numeric.equilibrium(model.guess_vectors()[0])
    linear = numeric.linearize(rest.q)
    # the spin's eigenvalue as rounding leaves it (-1.3e-15 in the issue): K_r with that on its diagonal
    spin = int(np.argmin(np.abs(np.diag(linear.stiffness))))
    stiffness = linear.stiffness.copy()
    stiffness[spin, spin] = -1.3e-15
    rounded = dataclasses.replace(linear, stiffness=stiffness)
    assert rounded.neutral.tolist() == [True, False]
    assert rounded.natural_frequencies[0] == 0.0
    # the swing: the free wheel acts as a point mass m at l, the arm as a rod of m and l about its end,
    # w^2 = g (m l/2 + m l) / (m l^2/3 + m l^2)
    l = 0.5
    expected = np.sqrt(G * (l / 2 + l) / (l**2 / 3 + l**2))
    assert rounded.natural_frequencies[1] == pytest.approx(expected, rel=1e-9)
    assert rounded.neutral_threshold == pytest.approx(
        ZERO_EIGENVALUE_RTOL * max(rounded.eigenvalue_scale, expected**2), rel=1e-12)
    assert rounded.mode_shape(0) == pytest.approx({"x1": 0, "y1": 0, "th1": 0, "x2": 0, "y2": 0, "th2": 1})
    text = modes_report(rounded)
    assert "nan" not in text.splitlines()[1]
    assert re.search(r"mode 0: 0 rad/s = 0 Hz  \(neutral\)   shape: x1 0, y1 0, th1 0, x2 0, y2 0, th2 1", text)
    assert f"{ZERO_EIGENVALUE_RTOL:g} of the scale" in text.splitlines()[0]


def test_a_true_negative_stiffness_is_still_unstable(arm_and_wheel):
    numeric, model = arm_and_wheel
    rest = numeric.equilibrium(model.guess_vectors()[0])
    linear = numeric.linearize(rest.q)
    flipped = dataclasses.replace(linear, stiffness=-linear.stiffness)
    assert np.isnan(flipped.natural_frequencies).tolist() == [True, False]
    assert "(unstable)" in modes_report(flipped)


# -- reactions by joint name ------------------------------------------------------------------------


def test_equilibrium_prints_multipliers_and_reactions_by_name_with_units(capsys, arm_and_wheel_file):
    code, out, err = run(capsys, "equilibrium", arm_and_wheel_file, "--modes")
    assert code == 0, err
    assert "lambda" not in out
    assert re.search(rf"shoulder\.Fy\s+=\s+{2 * 2 * G:.10g} N\b", out)
    assert re.search(rf"hub\.Fy\s+=\s+{2 * G:.10g} N\b", out)
    assert re.search(r"hub\.Mz\s+=\s+0 N\*m", out)
    assert re.search(r"mode 0: 0 rad/s .*\(neutral\)   shape: .*th2 1\b", out)


def test_equilibrium_names_the_multipliers_of_its_constraints(capsys):
    code, out, err = run(capsys, "equilibrium", "four_bar", "--guess", "q1=-1.5", "--guess", "q2=-0.5",
                         "--guess", "q3=-1.5")
    assert code == 0, err
    assert "lambda[loop x]" in out and "lambda[loop y]" in out and "lambda1" not in out


def test_equilibrium_reaction_is_a_reaction_like_a_trajectorys(arm_and_wheel):
    numeric, model = arm_and_wheel
    rest = numeric.equilibrium(model.guess_vectors()[0])
    hub = rest.reaction("hub")
    assert isinstance(hub, Reaction) and hub.name == "hub"
    np.testing.assert_allclose(hub.force, [[0.0, 2 * G]], atol=1e-9)
    np.testing.assert_allclose(rest.reaction("shoulder").force, [[0.0, 4 * G]], atol=1e-9)
    np.testing.assert_allclose(hub.point, [[0.0, -0.5]], atol=1e-9)
    with pytest.raises(KeyError, match=r"no joint named 'elbow' \(joints: shoulder, hub\)"):
        rest.reaction("elbow")


def test_inverse_dynamics_reaction_is_a_reaction_and_the_report_names_joints(capsys, arm_and_wheel_file):
    model = load_model(arm_and_wheel_file)
    drives = dict(parse_drive(text, model) for text in ("th1=-pi/2", "th2=3*t"))
    run_ = inverse_dynamics_along(model, drives, np.linspace(0.0, 1.0, 5))
    shoulder = run_.reaction("shoulder")
    assert isinstance(shoulder, Reaction)
    np.testing.assert_allclose(shoulder.force, np.tile([0.0, 4 * G], (5, 1)), atol=1e-8)
    np.testing.assert_allclose(shoulder.force[:, 1], run_.reactions["shoulder.Fy"])
    np.testing.assert_allclose(run_.forces, 0.0, atol=1e-8)  # hanging still, spinning evenly: no torque
    with pytest.raises(KeyError, match=r"no joint named 'elbow' \(joints: shoulder, hub\)"):
        run_.reaction("elbow")
    code, out, err = run(capsys, "inverse", arm_and_wheel_file, "--drive", "th1=-pi/2", "--drive", "th2=3*t",
                         "--points", "3")
    assert code == 0, err
    assert re.search(rf"shoulder\.Fy = {4 * G:.5g} N", out) and re.search(rf"hub\.Fy = {2 * G:.5g} N", out)
    assert "lambda" not in out


def test_multiplier_units_follow_the_joint_rows():
    units = multiplier_units(load_example("slider_crank_engine", apply_drives=False).system)
    assert units["main_bearing.x"] == units["cylinder.normal"] == "N"
    assert units["cylinder.angle"] == "N*m"


def test_the_multipliers_panel_labels_each_constraint_with_its_unit(arm_and_wheel):
    numeric, model = arm_and_wheel
    q0, qd0 = numeric.assemble(model.guess_vectors()[0])
    trajectory = kronlag.simulate(numeric, (0.0, 0.05), q0, qd0, t_eval=np.linspace(0, 0.05, 6))
    figure = plot_trajectory(trajectory, units={"t": "s", "energy": "J"})
    panel = next(axes for axes in figure.axes if axes.get_title() == "Lagrange multipliers")
    labels = [text.get_text() for text in panel.get_legend().get_texts()]
    assert labels == ["lambda[shoulder.x] (N)", "lambda[shoulder.y] (N)", "lambda[hub.x] (N)", "lambda[hub.y] (N)"]


# -- drives of a model file -------------------------------------------------------------------------


def test_load_model_says_how_to_apply_a_files_drives():
    with pytest.warns(kronlag.DrivesNotAppliedWarning, match=r"drive q1.*ModelFile\.driven\(\)"):
        model = load_model(example_path("four_bar"))
    assert "drive q1" not in [c.name for c in model.system.constraints]
    driven = model.driven()
    assert [c.name for c in driven.system.constraints] == ["loop x", "loop y", "drive q1"]
    assert driven.system.drives == ["drive q1"] and driven.drives == {}
    assert model.system.drives == []  # the original is left as it was
    applied = load_model(example_path("four_bar"), apply_drives=True)
    assert [c.name for c in applied.system.constraints] == ["loop x", "loop y", "drive q1"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_model(example_path("four_bar"), apply_drives=False)
        resolve_model("four_bar")


# -- check ------------------------------------------------------------------------------------------


def test_check_reports_the_assembly_correction(capsys):
    code, out, err = run(capsys, "check", "four_bar")
    assert code == 0, err
    assert "valid model file" in out
    correction = float(re.search(r"initial state assembled: max \|q0 - guess\| = (\S+),", out).group(1))
    assert 0 < correction < 1e-3


def test_check_refuses_an_initial_state_that_cannot_be_assembled(capsys, tmp_path):
    text = example_path("four_bar").read_text()
    text = re.sub(r"^l4 = .*$", 'l4 = {value = 10.0, unit = "m"}', text, flags=re.MULTILINE)  # ground far too long
    path = tmp_path / "far.toml"
    path.write_text(text)
    code, out, err = run(capsys, "check", path)
    assert code == 2
    assert "valid model file" not in out
    assert len(err.strip().splitlines()) == 1
    assert "cannot be assembled" in err and "'loop x'" in err


# -- help -------------------------------------------------------------------------------------------


def test_version(capsys):
    code, out, _ = run(capsys, "--version")
    assert code == 0
    version, compiler = out.strip().splitlines()
    assert version == f"kronlag {kronlag.__version__}" == f"kronlag {importlib.metadata.version('kronlag')}"
    assert compiler == f"C compiler: {codegen.c_compiler()}"


def _subparsers(parser):
    action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return action.choices


def test_method_help_lists_every_method_and_marks_the_default():
    text = method_help()
    assert all(name in text for name in ("auto", *METHODS))
    assert "auto (the default)" in text and "switching" in text and "ali3p" in text
    commands = _subparsers(build_parser())
    for name in ("simulate", "sweep"):
        flat = " ".join(commands[name].format_help().split())
        assert " ".join(text.split()) in flat


def test_every_help_text_is_plain():
    parser = build_parser()
    texts = [parser.format_help()] + [sub.format_help() for sub in _subparsers(parser).values()]
    for text in texts:
        assert not re.search(r"``|:[a-z]+:`", text), text


# -- piecewise forces ------------------------------------------------------------------------------


x = kronlag.coordinates("x")[0]
k = sp.Symbol("k", positive=True)


def _slider(force) -> kronlag.System:
    system = kronlag.System([x], parameters=[k])
    system.add_body(kronlag.PointMass("block", mass=1, position=(x, 0)))
    system.add_generalized_force([force], name="stop")
    return system


STOPS = {"Piecewise": sp.Piecewise((-k * x, x > 0), (0, True)), "Min": sp.Min(-k * x, 0),
         "Max": -sp.Max(k * x, 0), "Heaviside": -k * x * sp.Heaviside(x)}


@pytest.mark.parametrize("backend", backend_params())
@pytest.mark.parametrize("kind", list(STOPS))
def test_piecewise_forces_derive_and_compile(kind, backend):
    model = kronlag.derive(_slider(STOPS[kind])).numeric({"k": 100.0}, backend=backend)
    assert model.forward_dynamics([0.1], [0.0]).qdd[0] == pytest.approx(-10.0, rel=1e-14)
    assert model.forward_dynamics([-0.1], [0.0]).qdd[0] == 0.0


@pytest.mark.parametrize("backend", backend_params())
def test_heaviside_is_one_half_at_zero(backend):
    model = kronlag.derive(_slider(-k * sp.Heaviside(x))).numeric({"k": 100.0}, backend=backend)
    assert [model.forward_dynamics([value], [0.0]).qdd[0] for value in (-1e-3, 0.0, 1e-3)] == [0.0, -50.0, -100.0]


@pytest.mark.parametrize("backend", backend_params())
def test_a_one_sided_stop_bounces_the_block_back(backend):
    # block at x = -0.5 moving at 1 toward a stop at 0 of stiffness 100 (w = 10): touches it at t = 0.5,
    # leaves it pi/10 later at speed -1, and is back at x = -(1 - 0.5 - pi/10) at t = 1
    model = kronlag.derive(_slider(STOPS["Piecewise"])).numeric({"k": 100.0}, backend=backend)
    run = kronlag.simulate(model, (0.0, 1.0), [-0.5], [1.0], rtol=1e-10, atol=1e-12, t_eval=[0.0, 0.6, 1.0])
    assert run.success, run.message
    assert run.q[-1, 0] == pytest.approx(-(0.5 - np.pi / 10), abs=1e-6)
    assert run.qd[-1, 0] == pytest.approx(-1.0, abs=1e-6)
    assert run.q[1, 0] == pytest.approx(0.1 * np.sin(10 * 0.1), abs=1e-6)


def test_model_file_forces_may_use_min_max_and_heaviside():
    text = """
name = "stop"
coordinates = ["x"]
[parameters]
k = 100
[[bodies]]
name = "block"
type = "point"
mass = 1
position = ["x", 0]
[[generalized_forces]]
name = "stops"
force = ["-k*max(x, 0) - k*min(x + 1, 0) - heaviside(x - 2)"]
"""
    model = loads_model(text)
    numeric = kronlag.derive(model.system).numeric(model.numeric_values(), backend="python")
    accelerations = [numeric.forward_dynamics([value], [0.0]).qdd[0] for value in (0.5, -0.5, -1.5, 3.0)]
    assert accelerations == pytest.approx([-50.0, 0.0, 50.0, -301.0], rel=1e-14)


@pytest.mark.parametrize("kind", list(STOPS))
def test_piecewise_forces_have_exact_stiffness_for_equilibrium_and_modes(kind):
    # pushed with 10 N against the stop of stiffness 100: at rest at x = 0.1, vibrating at 10 rad/s
    model = kronlag.derive(_slider(STOPS[kind] + 10)).numeric({"k": 100.0}, backend="python")
    rest = model.equilibrium([0.05])
    assert rest.q[0] == pytest.approx(0.1, rel=1e-10)
    assert model.linearize(rest.q).natural_frequencies[0] == pytest.approx(10.0, rel=1e-10)
