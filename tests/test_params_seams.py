"""Issue 17, derived parameters and sweeps at the seams: definitions computed again wherever values change
(``with_parameters``, ``sweep``, CLI ``--grid``/``--set``), command-line values in the file's units, the
bodies' checks in every variant, and sweeps that check their output first, keep their rows and refuse
options that would never return."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import kronlag
from kronlag.app.cli import EXIT_BAD_INPUT, EXIT_INTERRUPTED, main
from kronlag.app.workflows import simulate_model
from kronlag.core.errors import InputError, ModelError
from kronlag.model.builtin import example_path, load_example
from kronlag.model.modelfile import loads_model
from kronlag.studies.sweeps import SweepInterrupted, _batches, sweep

T_END = 0.5
T_EVAL = np.linspace(0.0, T_END, 11)
FOUR_BAR = example_path("four_bar").read_text(encoding="utf-8")

#: A rod pendulum whose length the file gives in millimetres and whose inertia is defined from it.
ROD_MM = """
name = "rod_mm"
coordinates = ["theta"]
gravity = [0, "-g"]

[parameters]
L = {value = LENGTH, unit = "UNIT"}
m = {value = 1.5, unit = "kg"}
I = {value = INERTIA, unit = "kg*m^2"}
g = {value = 9.81, unit = "m/s^2"}

[[bodies]]
name = "rod"
type = "planar"
mass = "m"
inertia = "I"
position = ["L/2*sin(theta)", "-L/2*cos(theta)"]
angle = "theta"

[initial]
q = {theta = 0.5}

[simulation]
t_end = 0.5
"""


def rod(length, unit: str = "mm", inertia: str = '"m*L**2/12"'):
    return ROD_MM.replace("LENGTH", str(length)).replace("UNIT", unit).replace("INERTIA", inertia)


def explicit_four_bar(l1: float):
    """The four-bar file with ``l1`` changed and ``I1`` written as the number ``m1 l1^2 / 12`` (m1 = 1):
    an independent reference in which no definition is computed."""
    text = FOUR_BAR.replace('l1 = {value = 0.2,', f"l1 = {{value = {l1!r},")
    text = text.replace('I1 = {value = "m1*l1**2/12"', f"I1 = {{value = {l1 ** 2 / 12!r}")
    assert text.count(repr(l1)) >= 1 and "m1*l1**2/12" not in text
    return loads_model(text, source="four_bar_explicit.toml")


def reference_final(model_file) -> np.ndarray:
    return simulate_model(model_file, t_end=T_END, t_eval=T_EVAL).q[-1]


@pytest.fixture(scope="module")
def example():
    return load_example("four_bar", apply_drives=False)


@pytest.fixture(scope="module")
def model(example):
    return kronlag.derive(example.system).numeric(example.values)


def run_sweep(model, example, parameters, **options):
    settings = example.simulation
    options = {"t_eval": T_EVAL, **options}
    return sweep(model, parameters=parameters, initial_states=example.guess_vectors(), fixed=example.fixed,
                 qd_fixed=example.qd_fixed, t_span=(0.0, T_END), method=settings.method,
                 rtol=settings.rtol, atol=settings.atol, workers=0, progress=False, **options)


# -- derived parameters -------------------------------------------------------------------------------


def test_with_parameters_computes_the_defined_inertia_again(model):
    assert str(model.parameter_definitions()["I1"]) == "l1**2*m1/12"
    variant = model.with_parameters(l1=0.3)
    assert variant.parameter_values()["I1"] == pytest.approx(0.3 ** 2 / 12, rel=1e-15)
    assert model.parameter_values()["I1"] == pytest.approx(0.2 ** 2 / 12, rel=1e-15)  # unchanged
    assert variant.with_parameters(m1=2.0).parameter_values()["I1"] == pytest.approx(2 * 0.3 ** 2 / 12, rel=1e-15)
    given = model.with_parameters(l1=0.3, I1=0.5)  # a defined parameter given a value keeps it
    assert given.parameter_values()["I1"] == 0.5 and "I1" not in given.parameter_definitions()
    assert given.with_parameters(l1=0.25).parameter_values()["I1"] == 0.5


def test_a_pickled_model_keeps_its_definitions(model):
    import pickle

    copy = pickle.loads(pickle.dumps(model.with_parameters(l1=0.3)))
    assert copy.with_parameters(l1=0.25).parameter_values()["I1"] == pytest.approx(0.25 ** 2 / 12, rel=1e-15)


def test_definitions_in_a_cycle_or_of_unknown_names_are_refused(example):
    import sympy as sp

    equations = kronlag.derive(example.system)
    l1, l2 = sp.symbols("l1 l2")
    with pytest.raises(InputError, match="cycle: l1, l2"):
        equations.numeric({**example.values, "l1": 2 * l2, "l2": l1 / 2})
    with pytest.raises(InputError, match="I1 = .*not a finite real number"):
        equations.numeric({**example.values, "I1": sp.sqrt(-l1)})


def test_sweep_computes_the_defined_inertia_of_every_case(model, example):
    result = run_sweep(model, example, {"l1": [0.15, 0.3]})
    assert set(result.table["status"]) == {"ok"}
    for row in result.table.itertuples():
        expected = reference_final(explicit_four_bar(row.l1))
        np.testing.assert_allclose([row.q1_final, row.q2_final, row.q3_final], expected, rtol=1e-10, atol=1e-12)


def test_cli_grid_and_set_compute_the_defined_inertia(tmp_path):
    output = tmp_path / "sweep.csv"
    assert main(["sweep", "four_bar", "--grid", "l1=0.15,0.3", "--t-end", str(T_END), "--points", "11",
                 "--workers", "0", "--output", str(output)]) == 0
    table = pd.read_csv(output)
    assert list(table["l1 [m]"]) == [0.15, 0.3]
    for row in table.itertuples():
        expected = reference_final(explicit_four_bar(float(row[2])))
        np.testing.assert_allclose([row.q1_final, row.q2_final, row.q3_final], expected, rtol=1e-10, atol=1e-12)
    assert main(["sweep", "four_bar", "--set", "l1=300mm", "--grid", "tau=0", "--t-end", str(T_END),
                 "--points", "11", "--workers", "0", "--output", str(output)]) == 0
    row = pd.read_csv(output).iloc[0]
    np.testing.assert_allclose(row[["q1_final", "q2_final", "q3_final"]].to_numpy(float),
                               reference_final(explicit_four_bar(0.3)), rtol=1e-10, atol=1e-12)


# -- values in the file's units ------------------------------------------------------------------------


@pytest.mark.parametrize("grid", ["L=300:500:3", "L=0.3m:0.5m:3", "L=30cm,40cm,50cm"])
def test_cli_grid_reads_values_in_the_files_unit_or_their_own(tmp_path, grid):
    model_path = tmp_path / "rod_mm.toml"
    model_path.write_text(rod(500), encoding="utf-8")
    output = tmp_path / "rod.csv"
    assert main(["sweep", str(model_path), "--grid", grid, "--points", "11", "--workers", "0",
                 "--output", str(output)]) == 0
    table = pd.read_csv(output)
    np.testing.assert_allclose(table["L [m]"], [0.3, 0.4, 0.5], rtol=1e-14)
    for length, final in zip((0.3, 0.4, 0.5), table["theta_final"]):  # reference: L in m, I a number
        reference = loads_model(rod(length, "m", repr(1.5 * length ** 2 / 12)), source="rod_m.toml")
        assert final == pytest.approx(reference_final(reference)[0], rel=1e-10, abs=1e-12)


def test_a_unit_of_another_dimension_is_refused_in_one_line(tmp_path, capsys):
    model_path = tmp_path / "rod_mm.toml"
    model_path.write_text(rod(500), encoding="utf-8")
    assert main(["sweep", str(model_path), "--grid", "L=3kg:5kg:3", "--workers", "0"]) == EXIT_BAD_INPUT
    assert main(["sweep", str(model_path), "--grid", "L=300", "--set", "m=2m", "--workers", "0"]) == EXIT_BAD_INPUT
    assert main(["sweep", str(model_path), "--grid", "theta=10deg", "--workers", "0"]) == EXIT_BAD_INPUT
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 3 and "Traceback" not in "".join(lines)
    assert "'kg' is not a unit of L" in lines[0] and "'mm'" in lines[0]
    assert "'m' is not a unit of m" in lines[1]
    assert "theta has no unit" in lines[2]


# -- physical checks -------------------------------------------------------------------------------------


def test_with_parameters_checks_the_bodies_and_a_sweep_reports_a_negative_mass_as_an_error(model, example):
    with pytest.raises(ModelError, match="coupler.*mass = -1"):
        model.with_parameters(m2=-1.0)
    result = run_sweep(model, example, {"m2": [2.0, -1.0]})
    assert list(result.table["status"]) == ["ok", "error"]
    assert "must not be negative" in result.table["message"].iloc[1]


# -- the sweep's default outcome ---------------------------------------------------------------------------


def test_default_energy_outcome_is_the_energy_balance_with_the_work_of_the_torque(model, example):
    result = run_sweep(model, example, {"tau": [2.0]}, keep_trajectories=True, t_eval=np.linspace(0, T_END, 201))
    trajectory = result.trajectories[0]
    energy = trajectory.total_energy
    assert np.max(np.abs(energy - energy[0])) > 0.1  # the torque does work: E alone is not conserved
    assert result.table["energy_drift"].iloc[0] == pytest.approx(np.max(np.abs(trajectory.energy_balance)))
    assert result.table["energy_drift"].iloc[0] < 1e-6


# -- output, interruption, options ----------------------------------------------------------------------------


def test_cli_refuses_an_output_it_cannot_write_before_the_first_case(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    assert main(["sweep", "four_bar", "--grid", "tau=0:1:3", "--workers", "0",
                 "--output", str(blocker / "x.csv")]) == EXIT_BAD_INPUT
    captured = capsys.readouterr()
    assert captured.out == ""  # no case ran
    assert len(captured.err.strip().splitlines()) == 1 and "--output" in captured.err


def test_an_interrupted_sweep_hands_back_the_finished_rows(model, example):
    seen = []

    def stop_at_the_third_case(trajectory):
        if len(seen) == 2:
            raise KeyboardInterrupt
        return 0.0

    with pytest.raises(KeyboardInterrupt) as stop:
        run_sweep(model, example, {"tau": [0.0, 0.5, 1.0, 1.5]}, on_row=seen.append,
                  outcomes={"zero": stop_at_the_third_case})
    assert isinstance(stop.value, SweepInterrupted)
    assert list(stop.value.partial.table["case"]) == [0, 1] and [row["case"] for row in seen] == [0, 1]
    assert list(stop.value.partial.table["tau"]) == [0.0, 0.5]


def test_ctrl_c_keeps_every_finished_row_of_the_cli_sweep(tmp_path):
    output = tmp_path / "sweep.csv"
    command = [sys.executable, "-m", "kronlag", "sweep", "four_bar", "--grid", "tau=0:1:200", "--t-end", "4",
               "--workers", "0", "--output", str(output)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONPATH": str(Path(kronlag.__file__).parents[1])})
    try:
        deadline = time.monotonic() + 600  # a hang guard, not a measurement
        while time.monotonic() < deadline and process.poll() is None:
            if output.exists() and len(output.read_text().splitlines()) >= 3:  # header and two rows
                break
            time.sleep(0.2)
        assert process.poll() is None, process.communicate()
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=600)
    finally:
        process.kill()
    assert process.returncode == EXIT_INTERRUPTED, stderr
    assert "Traceback" not in stderr and "interrupted" in stderr and str(output) in stderr
    table = pd.read_csv(output)
    assert 2 <= len(table) < 200 and list(table["case"]) == list(range(len(table)))
    assert set(table["status"]) == {"ok"}


@pytest.mark.parametrize("options", [{"workers": -1}, {"batch_size": 0}, {"batch_size": -3}, {"retries": -1}])
def test_options_that_would_never_return_are_refused(model, options):
    with pytest.raises(InputError, match=next(iter(options))):
        sweep(model, parameters={"tau": [0.0]}, initial_states=([1.0, 0.5, 1.5], [0.0, 0, 0]), t_span=(0, 1),
              **{"workers": 0, **options})


def test_cli_refuses_negative_workers(capsys):
    assert main(["sweep", "four_bar", "--grid", "tau=0", "--workers", "-1"]) == EXIT_BAD_INPUT
    assert "workers" in capsys.readouterr().err


def test_batches_take_one_pass_over_the_cases():
    class Counted(list):
        reads = 0

        def __iter__(self):
            for item in super().__iter__():
                Counted.reads += 1
                yield item

    cases = Counted((i, {"tau": float(i)}) for i in range(5000))  # the (index, case) pairs
    batches = list(_batches(cases, 1))
    assert len(batches) == 5000 and batches[4999] == [(4999, {"tau": 4999.0})]
    assert Counted.reads == 5000  # the old slicing of list(enumerate(cases)) per batch read 5000 per batch
    assert [len(batch) for batch in _batches(list(range(10)), 4)] == [4, 4, 2]
