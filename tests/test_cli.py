"""The command line, end to end through ``kronlag.app.cli.main`` (and once as a process):
outputs, files written, and exit codes 0 (ok), 2 (bad input, before any work), 1 (the run did not
complete: a numerical failure or an output that could not be written)."""

from __future__ import annotations

import io
import json
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageSequence

import kronlag
from kronlag.app import commands
from kronlag.app.cli import build_parser, main
from kronlag.app.commands import ProgressBar
from kronlag.app.workflows import model_units
from kronlag.model.builtin import example_names, example_path, resolve_model
from kronlag.simulation.trajectory import Trajectory
from kronlag.views import animation

COMMANDS = ["models", "derive", "export", "check", "simulate", "inverse"]


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(arg) for arg in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def write_model(tmp_path, text: str, name: str = "model.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


POINT_MASS = """
coordinates = ["x", "y"]
[[bodies]]
name = "ball"
type = "point"
mass = 1
position = ["x", "y"]
"""


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_on_every_command(capsys, command):
    code, out, _ = run(capsys, *([command] if command else []), "--help")
    assert code == 0
    assert "usage: kronlag" in out
    if command is None:
        assert all(name in out for name in COMMANDS)


def test_models_lists_every_example(capsys):
    with warnings.catch_warnings():  # listing files is not loading them for a model: no drives warning
        warnings.simplefilter("error", kronlag.DrivesNotAppliedWarning)
        code, out, _ = run(capsys, "models")
    assert code == 0
    for name in example_names():
        assert name in out
    assert "Van Khang" in out and "built-in" in out


def test_derive_json(capsys):
    code, out, err = run(capsys, "derive", "chaplygin_sleigh", "--format", "json")
    assert code == 0, err
    data = json.loads(out)
    assert data["coordinates"] == ["x", "y", "theta"]
    assert set(data["matrices"]) >= {"M", "C", "C_christoffel", "g", "Phi_q", "A", "b", "f_Q"}


@pytest.mark.parametrize("fmt, marker", [("text", "Eq. 23"), ("latex", r"\begin{aligned}"), ("markdown", "## C")])
def test_derive_formats(capsys, fmt, marker):
    code, out, err = run(capsys, "derive", "four_bar", "--format", fmt)
    assert code == 0, err
    assert marker in out and "C_christoffel" in out


def test_derive_file_simplified_to_output(capsys, tmp_path):
    target = tmp_path / "eom.tex"
    code, _, err = run(capsys, "derive", example_path("chaplygin_sleigh"), "--simplify", "--format", "latex",
                       "--output", target)
    assert code == 0, err
    assert r"\dot{\theta}" in target.read_text()


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_export_c_to_file_compiles(capsys, tmp_path):
    target = tmp_path / "four_bar.c"
    code, _, err = run(capsys, "export", "four_bar", "--lang", "c", "--output", target)
    assert code == 0, err
    subprocess.run(["gcc", "-std=c99", "-fsyntax-only", str(target)], check=True)


def test_export_to_stdout(capsys):
    code, out, _ = run(capsys, "export", "slider_crank", "--lang", "julia")
    assert code == 0
    assert "function slider_crank_M(t, q, qd, p)" in out


def test_check_reports_freedom_and_rank(capsys):
    code, out, err = run(capsys, "check", "four_bar")
    assert code == 0, err
    assert "degrees of freedom = 1 (m - rank [Phi_q; A] at the assembled state)" in out
    assert "rank of Phi_q at the initial guess: 2 of 2 (full)" in out


def test_check_reports_dependent_constraints(capsys, tmp_path):
    path = write_model(tmp_path, POINT_MASS + """
[[constraints]]
expression = "x - y"
[[constraints]]
expression = "2*x - 2*y"
""")
    code, out, _ = run(capsys, "check", path)
    assert code == 0
    assert "rank of Phi_q at the initial guess: 1 of 2 (DEFICIENT: 1 dependent rows)" in out
    # the mobility counts the dependent row once: x = y leaves one freedom, not m - r = 0
    assert ("degrees of freedom = 1 (m - rank [Phi_q; A] at the assembled state; m - r - s = 0: dependent "
            "constraints)") in out


@pytest.mark.parametrize("argv, message", [
    (["check", "{bad}"], "bad.toml: bodies[0].position[1]: cannot read 'y + z': unknown symbol 'z'"),
    (["derive", "{missing}"], "missing.toml: cannot read the file"),
    (["simulate", "no_such_model"], "no example model named 'no_such_model'"),
    (["simulate", "four_bar", "--output", "{tmp}/out.xlsx"], "--output"),
    (["simulate", "four_bar", "--method", "magic"], "unknown method 'magic'"),
    (["inverse", "four_bar", "--drive", "q9=t"], "expected COORDINATE=EXPRESSION"),
    (["inverse", "four_bar", "--drive", "q1=os.system('x')"], "calling 'os.system' is not allowed"),
    (["inverse", "four_bar", "--drive", "q1=t", "--drive", "q2=t"], "over-driven: 2 drives"),
])
def test_bad_input_exits_2_with_a_clean_message(capsys, tmp_path, argv, message):
    bad = write_model(tmp_path, POINT_MASS.replace('position = ["x", "y"]', 'position = ["x", "y + z"]'), "bad.toml")
    arguments = [arg.format(bad=bad, missing=tmp_path / "missing.toml", tmp=tmp_path) for arg in argv]
    code, out, err = run(capsys, *arguments)
    assert code == 2
    assert err.startswith("kronlag: error: ") and message in err, err
    assert "Traceback" not in err + out


def test_usage_error_exits_2(capsys):
    code, _, err = run(capsys, "export", "four_bar", "--lang", "cobol")
    assert code == 2 and "invalid choice" in err


def test_simulate_writes_trajectory_and_figure(capsys, tmp_path):
    csv, figure = tmp_path / "traj.csv", tmp_path / "fig.png"
    code, out, err = run(capsys, "simulate", "four_bar", "--t-end", "0.2", "--method", "projection",
                         "--rtol", "1e-6", "--output", csv, "--plot", figure)
    assert code == 0, err
    for text in ("status: ok", "steps", "max constraint drift", "energy drift", "wall time"):
        assert text in out
    header = csv.read_text().splitlines()[0].split(",")
    assert header[:4] == ["t", "q1", "q2", "q3"]
    assert figure.stat().st_size > 0


def test_simulate_reports_saves_and_plots_the_joint_reactions(capsys, tmp_path):
    csv, figure = tmp_path / "engine.csv", tmp_path / "engine.png"
    code, out, err = run(capsys, "simulate", "slider_crank_engine", "--t-end", "0.005", "--points", "11",
                         "--output", csv, "--plot", figure, "--reactions", "main_bearing, cylinder")
    assert code == 0, err
    line = next(line for line in out.splitlines() if line.startswith("max joint force |F|:"))
    assert [entry.split()[0] for entry in line.removeprefix("max joint force |F|:").split(",")] == [
        "main_bearing", "crank_pin", "wrist_pin", "cylinder"]
    table = np.genfromtxt(csv, delimiter=",", names=True)
    largest = np.max(np.hypot(table["main_bearingFx"], table["main_bearingFy"]))
    assert f"main_bearing {largest:.5g}," in line
    assert Image.open(figure).size[1] > 1000  # six rows of panels: the two joints' and the couple's


@pytest.mark.parametrize("options, message", [
    (["--plot", "{tmp}/fig.png", "--reactions", "main,crank_pin"],
     "--reactions: no joint named 'main' in model 'slider_crank_engine' (joints: main_bearing, crank_pin, "),
    (["--reactions", "all"], "--reactions selects what --plot draws: give --plot FILE too"),
])
def test_reaction_selection_is_checked_before_the_run(capsys, tmp_path, options, message):
    code, out, err = run(capsys, "simulate", "slider_crank_engine",
                         *[option.format(tmp=tmp_path) for option in options])
    assert code == 2 and message in err and not out
    assert not (tmp_path / "fig.png").exists()


def test_simulate_npz_from_file_settings(capsys, tmp_path):
    target = tmp_path / "traj.npz"
    code, _, err = run(capsys, "simulate", example_path("chaplygin_sleigh"), "--t-end", "0.5", "--method",
                       "projection", "--output", target)
    assert code == 0, err
    data = np.load(target)
    assert data["t"][-1] == pytest.approx(0.5)
    assert np.max(np.abs(data["velocity_residual1"])) < 1e-8


def test_simulation_failure_exits_1_and_saves_the_partial_trajectory(capsys, tmp_path):
    path = write_model(tmp_path, POINT_MASS + """
[[generalized_forces]]
force = ["1/(1 - t)**3", 0]
[simulation]
t_end = 1.5
method = "projection"
rtol = 1e-4
atol = 1e-6
""", "blowup.toml")
    target = tmp_path / "partial.npz"
    code, out, err = run(capsys, "simulate", path, "--output", target)
    assert code == 1
    assert "simulation failed" in err and str(target) in err
    assert "FAILED" in out
    assert 0.9 < np.load(target)["t"][-1] < 1.0 + 1e-9


def test_assembly_failure_exits_1(capsys, tmp_path):
    path = write_model(tmp_path, POINT_MASS + """
[[constraints]]
expression = "x**2 + 1"
""")
    code, _, err = run(capsys, "simulate", path)
    assert code == 1
    assert err.startswith("kronlag: numerical failure:")


def test_inverse_dynamics_along_the_file_drive(capsys, tmp_path):
    target = tmp_path / "inverse.csv"
    code, out, err = run(capsys, "inverse", "four_bar", "--points", "11", "--output", target)
    assert code == 0, err
    assert "force_q1" in out and "lambda[loop y]" in out and "max |force|: q1" in out
    table = np.genfromtxt(target, delimiter=",", names=True)
    assert len(table) == 11
    np.testing.assert_allclose(table["q1"], 1 + 2 * np.pi * table["t"], rtol=1e-12)
    # Crank turning once per second: the torque is periodic.
    assert table["force_q1"][0] == pytest.approx(table["force_q1"][-1], rel=1e-6)


def test_inverse_dynamics_with_a_command_line_drive(capsys):
    code, out, err = run(capsys, "inverse", "slider_crank", "--drive", "q1=0.5 + 3*t", "--t-end", "0.5",
                         "--points", "5")
    assert code == 0, err
    assert "force_q1" in out


def test_parser_has_a_command_per_task():
    parser = build_parser()
    assert parser.prog == "kronlag"


@pytest.mark.slow
def test_runs_as_a_program(tmp_path):
    good = subprocess.run([sys.executable, "-m", "kronlag", "check", "slider_crank"], capture_output=True,
                          text=True, timeout=1800)
    assert good.returncode == 0, good.stderr
    assert "degrees of freedom = 1 (m - rank [Phi_q; A] at the assembled state)" in good.stdout
    bad = write_model(tmp_path, "coordinates = 'q1'")
    failed = subprocess.run([sys.executable, "-m", "kronlag", "derive", str(bad)], capture_output=True,
                            text=True, timeout=1800)
    assert failed.returncode == 2
    assert failed.stderr == f"kronlag: error: {bad}: coordinates: expected a non-empty list of names, " \
                            "got a string ('q1')\n"


def test_missing_values_are_reported_by_check_and_refused_by_simulate(capsys, tmp_path):
    path = write_model(tmp_path, POINT_MASS.replace('mass = 1', 'mass = "m"') + "[parameters]\nm = {unit = 'kg'}\n")
    code, out, _ = run(capsys, "check", path)
    assert code == 0
    assert "parameters without values: m (numeric checks skipped)" in out
    code, _, err = run(capsys, "simulate", path, "--method", "projection")
    assert code == 2
    assert err.startswith("kronlag: error: ") and "m" in err


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_draws_on_a_terminal_after_its_delay():
    terminal = _Terminal()
    bar = ProgressBar(10.0, terminal, delay=0.0)
    bar(2.5)
    bar.close()
    assert terminal.getvalue() == "\r[#######.......................] t = 2.5 / 10\n"


def test_progress_bar_stays_silent_off_a_terminal():
    log = io.StringIO()
    bar = ProgressBar(10.0, log, delay=0.0)
    bar(5.0)
    bar.close()
    assert log.getvalue() == ""


# -- outputs: checked before the run, all written after it, the result never lost ----------------


@pytest.fixture
def no_simulation(monkeypatch):
    """Fail the test if the CLI starts simulating."""
    def refuse(*args, **kwargs):
        raise AssertionError("simulated although an output option was bad")
    monkeypatch.setattr(commands, "simulate_model", refuse)


def without_module(monkeypatch, missing: str):
    find_spec = commands.importlib.util.find_spec
    monkeypatch.setattr(commands.importlib.util, "find_spec", lambda name: None if name == missing else find_spec(name))


@pytest.mark.parametrize("argv, message, setup", [
    (["--animate", "{tmp}/run.mp4"], "--animate {tmp}/run.mp4: writing .mp4 needs ffmpeg",
     lambda mp: mp.setattr(animation.shutil, "which", lambda name: None)),
    (["--output", "{tmp}/run.parquet"], "--output {tmp}/run.parquet: writing .parquet needs pandas and pyarrow",
     lambda mp: without_module(mp, "pyarrow")),
    (["--plot", "{tmp}/file.txt/fig.png"], "--plot {tmp}/file.txt/fig.png: cannot write there", None),
    (["--output", "{tmp}/run.csv", "--animate", "{tmp}/run.gif", "--fps", "60"], "at most 50 frames per second",
     None),
    (["--output", "{tmp}/run.xlsx"], "the file name must end in .csv, .npz, .parquet", None),
])
def test_outputs_are_checked_before_the_run(capsys, tmp_path, monkeypatch, no_simulation, argv, message, setup):
    (tmp_path / "file.txt").write_text("a file, not a folder")
    if setup:
        setup(monkeypatch)
    code, out, err = run(capsys, "simulate", "four_bar", *(arg.format(tmp=tmp_path) for arg in argv))
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("kronlag: error: ") and message.format(tmp=tmp_path) in err
    assert out == "" and sorted(path.name for path in tmp_path.iterdir()) == ["file.txt"]  # nothing written


def test_animating_a_model_without_drawing_hints_is_refused_first(capsys, tmp_path, no_simulation):
    code, _, err = run(capsys, "simulate", write_model(tmp_path, POINT_MASS), "--animate", tmp_path / "x.gif")
    assert code == 2 and "has no [[drawing]] or [[traces]] to draw" in err


def test_speed_and_duration_exclude_each_other(capsys, no_simulation):
    code, _, err = run(capsys, "simulate", "four_bar", "--speed", "2", "--duration", "1")
    assert code == 2 and "not allowed with" in err


def test_a_failing_output_does_not_stop_the_others(capsys, tmp_path, monkeypatch):
    def full_disk(self, *args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(Trajectory, "animate", full_disk)
    csv, figure, movie = tmp_path / "run.csv", tmp_path / "run.png", tmp_path / "run.gif"
    code, out, err = run(capsys, "simulate", "four_bar", "--t-end", "0.2", "--animate", movie, "--output", csv,
                         "--plot", figure)
    assert code == 1
    assert csv.stat().st_size > 0 and figure.stat().st_size > 0 and f"wrote {csv}" in out
    assert f"could not write --animate {movie}: OSError" in err and "No space left on device" in err
    assert f"the results are saved in {csv}" in err


def test_a_trajectory_no_output_holds_is_saved_in_the_working_folder(capsys, tmp_path, monkeypatch):
    def broken(self, *args, **kwargs):
        raise RuntimeError("the plot broke")
    monkeypatch.setattr(Trajectory, "plot", broken)
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, "simulate", "four_bar", "--t-end", "0.2", "--plot", "run.png")
    assert code == 1 and "the plot broke" in err
    rescued = tmp_path / "four_bar-trajectory.npz"
    assert f"saved in {rescued}" in err
    assert np.load(rescued)["t"][-1] == pytest.approx(0.2)


def test_outputs_go_into_a_new_folder(capsys, tmp_path):
    target = tmp_path / "out" / "deeper" / "run.npz"
    code, _, err = run(capsys, "simulate", "four_bar", "--t-end", "0.1", "--output", target)
    assert code == 0, err
    assert target.exists()


def test_step_limit_is_reported_with_the_option_to_raise_it(capsys, tmp_path):
    target = tmp_path / "run.csv"
    code, out, err = run(capsys, "simulate", "four_bar", "--t-end", "5", "--max-steps", "40", "--output", target)
    assert code == 1
    assert "simulation failed" in err and "--max-steps" in err and str(target) in err
    assert "40 steps" in out
    times = np.genfromtxt(target, delimiter=",", names=True)["t"]
    assert 0 < times[-1] < 5


@pytest.mark.parametrize("options, times", [
    (["--dt", "0.05"], np.arange(5) * 0.05),
    (["--dt", "0.15"], np.array([0.0, 0.15, 0.2])),  # the end is always an output time
    (["--points", "3"], np.array([0.0, 0.1, 0.2])),
    ([], np.linspace(0.0, 0.2, 1001)),  # default: at least 1001 points
])
def test_output_grid(capsys, tmp_path, options, times):
    target = tmp_path / "run.csv"
    code, _, err = run(capsys, "simulate", "four_bar", "--t-end", "0.2", *options, "--output", target)
    assert code == 0, err
    np.testing.assert_allclose(np.genfromtxt(target, delimiter=",", names=True)["t"], times, atol=1e-12)


def test_default_grid_is_bounded_for_long_runs():
    assert commands._default_points(3.0) == 1001
    assert commands._default_points(50.0) == 5001  # a point every 0.01 s
    assert commands._default_points(1e4) == 100_001  # 10^4 s in bounded memory


def test_dt_and_points_exclude_each_other(capsys, no_simulation):
    code, _, err = run(capsys, "simulate", "four_bar", "--dt", "0.1", "--points", "5")
    assert code == 2 and "not allowed with" in err


@pytest.mark.parametrize("options, frames, delay", [
    (["--fps", "10", "--speed", "0.5"], 9, 100),  # 0.4 s shown in 0.8 s: 9 frames, 1/10 s apart
    (["--fps", "25", "--duration", "1.6"], 41, 40),
    ([], 11, 40),  # real time at 25 fps
])
def test_animation_timing_options(capsys, tmp_path, options, frames, delay):
    movie = tmp_path / "run.gif"
    code, _, err = run(capsys, "simulate", "four_bar", "--t-end", "0.4", "--animate", movie, *options)
    assert code == 0, err
    delays = [frame.info["duration"] for frame in ImageSequence.Iterator(Image.open(movie))]
    assert len(delays) == frames and set(delays) == {delay}


def test_inverse_plot_with_units(capsys, tmp_path):
    figure = tmp_path / "torque.png"
    code, _, err = run(capsys, "inverse", "four_bar", "--dt", "0.1", "--plot", figure)
    assert code == 0, err
    assert Image.open(figure).size[0] > 300


@pytest.mark.parametrize("name, units", [
    ("four_bar", {"q1": "rad", "q2": "rad", "q3": "rad", "t": "s", "energy": "J"}),
    ("slider_crank", {"q1": "rad", "q2": "rad", "x": "m", "t": "s", "energy": "J"}),
    ("chaplygin_sleigh", {"x": "m", "y": "m", "theta": "rad"}),  # no unit written with s: time left out
])
def test_units_come_from_the_model_file(name, units):
    assert model_units(resolve_model(name)) == units


def test_no_units_are_guessed(tmp_path):
    assert model_units(resolve_model(str(write_model(tmp_path, POINT_MASS)))) == {}


def test_too_fast_an_animation_gets_a_slower_speed_suggested(capsys, tmp_path):
    movie = tmp_path / "run.gif"
    # The four-bar's crank reaches about 20 rad/s near t = 0.6: 4 x 20 / 25 = 3.2 rad between frames.
    code, _, err = run(capsys, "simulate", "four_bar", "--t-end", "1", "--animate", movie, "--speed", "4")
    assert code == 0 and movie.exists()
    assert "between frames" in err
    suggested = float(re.search(r"--speed (\S+) \(or a higher --fps\)", err)[1])
    assert 0 < suggested < 4
    code, _, err = run(capsys, "simulate", "four_bar", "--t-end", "1", "--animate", movie, "--speed", suggested)
    assert code == 0 and "between frames" not in err


@pytest.mark.slow
def test_singular_configuration_is_explained(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # where the trajectory is rescued
    text = example_path("heavy_top").read_text().replace("theta = 0.5", "theta = 0.0")  # gimbal lock
    code, _, err = run(capsys, "simulate", write_model(tmp_path, text, "top.toml"), "--t-end", "0.1")
    assert code == 1
    assert "singular configuration" in err and f"saved in {tmp_path / 'heavy_top-trajectory.npz'}" in err


def test_inverse_five_bar_reports_the_motor_torques_and_joint_forces(capsys, tmp_path):
    """Held at rest in its symmetric pose, the robot needs mirror-image torques at its two base joints."""
    table = tmp_path / "five_bar.csv"
    code, out, err = run(capsys, "inverse", "five_bar", "--drive", "theta1=2*pi/3", "--drive", "theta2=pi/3",
                         "--points", "2", "--output", table)
    assert code == 0, err
    assert out.split()[:3] == ["t", "force_theta1", "force_theta2"]
    data = np.genfromtxt(table, delimiter=",", names=True)
    assert data["force_theta1"][0] == pytest.approx(-data["force_theta2"][0], rel=1e-9)
    assert abs(data["force_theta1"][0]) > 0.1
    assert np.hypot(data["elbow_1Fx"], data["elbow_1Fy"]) == pytest.approx(np.hypot(data["elbow_2Fx"],
                                                                                     data["elbow_2Fy"]))


def test_simulate_reports_the_method_intervals_of_redundant_constraints(capsys):
    """Bricard's mechanism has a redundant constraint: the summary says which integrator ran and that
    the multipliers are the minimum-norm ones; a plain compiled run prints no interval line."""
    with pytest.warns(kronlag.RedundantConstraintsWarning):
        code, out, _ = run(capsys, "simulate", "bricard", "--t-end", "0.2")
    assert code == 0
    assert re.search(r"^  compiled from t = 0 to 0\.2 \(\d+ steps\): redundant constraints .*minimum-norm", out, re.M)
    code, out, _ = run(capsys, "simulate", "four_bar", "--t-end", "0.2", "--method", "compiled")
    assert code == 0 and " from t = " not in out


def test_simulate_says_when_the_work_is_integrated_over_fewer_outputs_than_steps(capsys):
    """The balance's W is a quadrature over the outputs: with fewer outputs than steps the summary says
    that its error is in the energy drift, and that more points tighten it; a run without work says nothing."""
    friction = Path(__file__).resolve().parents[1] / "examples" / "slider_crank_friction.toml"
    code, out, err = run(capsys, "simulate", friction, "--t-end", "0.5", "--points", "11")
    assert code == 0, err
    assert "W integrated over the 11 output points" in out
    code, out, err = run(capsys, "simulate", "four_bar", "--t-end", "0.2", "--points", "11")
    assert code == 0, err
    assert "W integrated" not in out
