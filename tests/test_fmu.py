"""FMU export (issue 20.2): FMPy's validation of the model description, and FMPy's simulations of
the exported four-bar and slider-crank (model exchange with FMPy's CVode, co-simulation with the
FMU's own CVODE) against ``kronlag.simulate``; tunable parameters and inputs; reactions by joint
name; bad input.  FMPy runs in a child process that never imports kronlag (the FMU must load
without it)."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import kronlag
from kronlag.app.cli import main
from kronlag.model.builtin import resolve_model
from kronlag.numeric.reactions import reaction_columns
from kronlag.views import fmu as fmu_export

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("fmpy.validation")

pytestmark = pytest.mark.skipif(kronlag.numeric.codegen.c_compiler() is None, reason="needs a C compiler")

#: The FMI versions written.
VERSIONS = ("2.0", "3.0")

#: Output grid and end of the comparisons.
T_END, DT = 2.0, 0.01

#: The child process: FMPy simulates the FMU (never importing kronlag) and prints the results as JSON.
_SIMULATE = """
import json, sys
from fmpy import simulate_fmu
path, kind, names, start, tolerance = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4]), \\
    float(sys.argv[5])
result = simulate_fmu(path, fmi_type=kind, stop_time=%r, output_interval=%r, relative_tolerance=tolerance,
                      start_values=start, output=names)
assert "kronlag" not in sys.modules
print(json.dumps({name: result[name].tolist() for name in ["time"] + names}))
""" % (T_END, DT)


def fmpy_run(path, kind: str, names, start=None, tolerance: float = 1e-10) -> dict[str, np.ndarray]:
    """FMPy's simulation of the FMU ``path`` in a child process: the columns ``time`` and ``names``."""
    done = subprocess.run([sys.executable, "-c", _SIMULATE, str(path), kind, json.dumps(list(names)),
                           json.dumps(start or {}), repr(tolerance)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return {name: np.array(values) for name, values in json.loads(done.stdout).items()}


def file_model(name: str):
    """The model file's numeric model and its assembled initial state."""
    from kronlag.app.workflows import initial_state, numeric_model

    model_file = resolve_model(name)
    model = numeric_model(model_file)
    return model, *initial_state(model_file, model)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """name -> (model, q0, qd0, FMU path) of the four-bar, the slider-crank and the five-bar (joints),
    FMI 2.0; the FMI 3.0 FMUs of the first two under ``<name>@3.0``."""
    directory = tmp_path_factory.mktemp("fmu")
    built = {}
    for name, versions in (("four_bar", VERSIONS), ("slider_crank", VERSIONS), ("five_bar", ("2.0",))):
        model, q0, qd0 = file_model(name)
        for version in versions:
            key = name if version == "2.0" else f"{name}@{version}"
            path = kronlag.export_fmu(model, directory / f"{key}.fmu", q0=q0, qd0=qd0, stop_time=T_END,
                                      fmi_version=version)
            built[key] = (model, q0, qd0, path)
    return built


def reference(model, q0, qd0, **parameters):
    """``kronlag.simulate`` on the output grid, at tight tolerances."""
    if parameters:
        model = model.with_parameters(parameters)
    times = np.linspace(0.0, T_END, round(T_END / DT) + 1)
    return kronlag.simulate(model, (0.0, T_END), q0, qd0, rtol=1e-10, atol=1e-12, t_eval=times)


def q_error(result: dict[str, np.ndarray], trajectory) -> float:
    np.testing.assert_allclose(result["time"], trajectory.t, atol=1e-9)
    q = np.column_stack([result[name] for name in trajectory.coordinate_names])
    return float(np.max(np.abs(q - trajectory.q)))


@pytest.mark.parametrize("name", ["four_bar", "slider_crank", "five_bar", "four_bar@3.0", "slider_crank@3.0"])
def test_fmpy_validation_finds_no_problem(exported, name):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(exported[name][3])) == []


def test_variables_states_parameters_inputs_outputs(exported):
    model, q0, _, path = exported["four_bar"]
    description = fmpy.read_model_description(str(path))
    assert description.modelExchange.modelIdentifier == description.coSimulation.modelIdentifier == "four_bar"
    variables = {variable.name: variable for variable in description.modelVariables}
    assert [float(variables[name].start) for name in ("q1", "q2", "q3")] == q0.tolist()
    assert {(v.causality, v.variability) for name, v in variables.items() if name in ("l1", "m2", "g")} \
        == {("parameter", "tunable")}
    assert (variables["I1"].causality, variables["tau"].causality) == ("calculatedParameter", "input")
    assert len(description.derivatives) == 2 * model.m
    assert {"lambda[loop x]", "lambda[loop y]", "energy", "q1d"} <= {
        unknown.variable.name for unknown in description.outputs}
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
    assert {"binaries/linux64/four_bar.so", "sources/four_bar.c", "sources/fmi2Functions.h",
            "sources/buildDescription.xml"} <= names
    assert any(name.startswith("binaries/linux64/libsundials_cvode") for name in names)


def test_the_shipped_sources_build_the_fmu_again(exported, tmp_path):
    """sources/ (the C, the FMI headers) compiles with the shipped SUNDIALS libraries into a library
    exporting the FMI 2.0 functions; buildDescription.xml follows FMI 3.0's schema."""
    import ctypes
    import os

    from lxml import etree

    path = exported["four_bar"][3]
    with zipfile.ZipFile(path) as archive:
        archive.extractall(tmp_path)
    schema = Path(fmpy.__file__).parent / "schema" / "fmi3" / "fmi3BuildDescription.xsd"
    etree.XMLSchema(etree.parse(str(schema))).assertValid(etree.parse(str(tmp_path / "sources" / "buildDescription.xml")))
    binaries = tmp_path / "binaries" / "linux64"
    libraries = sorted(str(file) for file in binaries.glob("libsundials_*"))
    built = tmp_path / "rebuilt.so"
    compiler = kronlag.numeric.codegen.c_compiler()
    done = subprocess.run([*compiler.command, *compiler.flags, "-O1", "-fPIC", "-shared", "-std=gnu99", f"-I{tmp_path / 'sources'}", "-o",
                           str(built), str(tmp_path / "sources" / "four_bar.c"), *libraries,
                           f"-Wl,-rpath,{binaries}", "-lm"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    library = ctypes.CDLL(str(built), mode=os.RTLD_LOCAL)
    library.fmi2GetVersion.restype = ctypes.c_char_p
    assert library.fmi2GetVersion() == b"2.0"


def test_co_simulation_only(slider_crank_model, tmp_path):
    from fmpy.validation import validate_fmu

    model, q0, qd0 = slider_crank_model
    path = kronlag.export_fmu(model, tmp_path / "cs.fmu", q0=q0, qd0=qd0, kinds="co-simulation")
    description = fmpy.read_model_description(str(path))
    assert description.modelExchange is None and description.coSimulation is not None
    assert validate_fmu(str(path)) == []


def test_reaction_outputs_by_joint_name(exported):
    """The outputs carry every joint's reaction by name, and agree with kronlag's reactions at the FMU's states."""
    model, _, _, path = exported["five_bar"]
    joints = [joint.name for joint in model.equations.system.joints]
    columns = [f"{joint}.{component}" for joint in joints for component in ("Fx", "Fy", "Mz")]
    outputs = {variable.name for variable in fmpy.read_model_description(str(path)).modelVariables
               if variable.causality == "output"}
    assert joints and set(columns) <= outputs
    states = [*model.coordinate_names, *(symbol.name for symbol in model.equations.speeds)]
    result = fmpy_run(path, "CoSimulation", states + columns)
    q = np.column_stack([result[name] for name in states[:model.m]])
    qd = np.column_stack([result[name] for name in states[model.m:]])
    lam = np.array([model.forward_dynamics(a, b).lam for a, b in zip(q[::50], qd[::50])])
    expected = reaction_columns(model, result["time"][::50], q[::50], lam)
    for column in columns:
        np.testing.assert_allclose(result[column][::50], expected[column], rtol=1e-8, atol=1e-8)


@pytest.mark.slow
@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", ["four_bar", "slider_crank"])
@pytest.mark.parametrize("kind, tolerance", [("ModelExchange", 1e-12), ("CoSimulation", 1e-10)])
def test_fmpy_simulation_agrees_with_kronlag(exported, name, kind, tolerance, version):
    model, q0, qd0, path = exported[name if version == "2.0" else f"{name}@{version}"]
    trajectory = reference(model, q0, qd0)
    result = fmpy_run(path, kind, [*model.coordinate_names, "energy"], tolerance=tolerance)
    assert q_error(result, trajectory) <= 1e-6
    energy = trajectory.kinetic_energy + trajectory.potential_energy
    np.testing.assert_allclose(result["energy"], energy, rtol=1e-6, atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("key", ["four_bar", "four_bar@3.0"])
@pytest.mark.parametrize("kind, tolerance", [("ModelExchange", 1e-12), ("CoSimulation", 1e-10)])
def test_parameter_and_input_set_through_fmpy_change_the_motion_as_in_kronlag(exported, kind, tolerance, key):
    """A tunable parameter (the coupler's mass, which the calculated I2 follows) and the input tau set
    through FMPy move the four-bar as kronlag.simulate with those values does."""
    model, q0, qd0, path = exported[key]
    changed = {"m2": 4.0, "tau": 1.5}
    unchanged = reference(model, q0, qd0)
    trajectory = reference(model, q0, qd0, **changed)
    assert float(np.max(np.abs(trajectory.q - unchanged.q))) > 1e-2  # the change matters
    result = fmpy_run(path, kind, list(model.coordinate_names), start=changed, tolerance=tolerance)
    assert q_error(result, trajectory) <= 1e-6


#: The child process: the FMU's co-simulation stepped by hand through FMPy's FMU2Slave, the input
#: tau set to 0 until T_END / 2, then to 1.5; prints q at the communication points as JSON.
_STEP_INPUT = """
import json, shutil, sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path, names = sys.argv[1], json.loads(sys.argv[2])
description = read_model_description(path)
reference = {variable.name: variable.valueReference for variable in description.modelVariables}
directory = extract(path)
slave = FMU2Slave(guid=description.guid, unzipDirectory=directory,
                  modelIdentifier=description.coSimulation.modelIdentifier, instanceName="step")
slave.instantiate()
slave.setupExperiment(tolerance=1e-10, startTime=0.0)
slave.enterInitializationMode()
slave.exitInitializationMode()
rows, t = [], 0.0
for k in range(%d):
    slave.setReal([reference["tau"]], [0.0 if t < %r - 1e-12 else 1.5])
    slave.doStep(currentCommunicationPoint=t, communicationStepSize=%r)
    t = (k + 1) * %r
    rows.append([t] + slave.getReal([reference[name] for name in names]))
slave.terminate()
slave.freeInstance()
shutil.rmtree(directory, ignore_errors=True)
assert "kronlag" not in sys.modules
print(json.dumps(rows))
""" % (round(T_END / DT), T_END / 2, DT, DT)


@pytest.mark.slow
def test_an_input_changed_between_co_simulation_steps(exported):
    """The input tau switched from 0 to 1.5 halfway restarts the FMU's CVODE there: the motion is
    kronlag.simulate's with tau = 0, then from its state at T_END / 2 with tau = 1.5."""
    model, q0, qd0, path = exported["four_bar"]
    names = list(model.coordinate_names)
    done = subprocess.run([sys.executable, "-c", _STEP_INPUT, str(path), json.dumps(names)], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = np.array(json.loads(done.stdout))
    half = T_END / 2
    first = kronlag.simulate(model, (0.0, half), q0, qd0, rtol=1e-10, atol=1e-12, t_eval=rows[rows[:, 0] <= half, 0])
    pushed = model.with_parameters(tau=1.5)
    second = kronlag.simulate(pushed, (half, T_END), first.q[-1], first.qd[-1], rtol=1e-10, atol=1e-12,
                              t_eval=rows[rows[:, 0] > half + 1e-9, 0])
    expected = np.vstack([first.q, second.q])
    assert float(np.max(np.abs(rows[:, 1:] - expected))) <= 1e-6
    assert float(np.max(np.abs(second.q[-1] - reference(model, q0, qd0).q[-1]))) > 1e-2  # the input mattered


def test_a_model_with_the_python_backend_is_built_with_c(tmp_path):
    from kronlag.app.workflows import initial_state

    model_file = resolve_model("slider_crank")
    model = kronlag.derive(model_file.system).numeric(model_file.values, backend="python")
    q0, qd0 = initial_state(model_file, model)
    path = kronlag.export_fmu(model, tmp_path / "python.fmu", q0=q0, qd0=qd0)
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(path)) == []


def test_the_cli_exports_an_fmu(tmp_path, capsys):
    target = tmp_path / "slider.fmu"
    assert main(["export", "slider_crank", "--fmu", str(target)]) == 0
    assert "FMI 2.0 FMU" in capsys.readouterr().out
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(target)) == []
    variables = {v.name: v for v in fmpy.read_model_description(str(target)).modelVariables}
    assert (variables["q1"].unit, variables["q1d"].unit, variables["x"].unit, variables["energy"].unit) \
        == ("rad", "rad/s", "m", "J")


def test_the_cli_exports_an_fmi3_fmu(tmp_path, capsys):
    target = tmp_path / "four_bar.fmu"
    assert main(["export", "four_bar", "--fmu", str(target), "--fmi-version", "3.0"]) == 0
    assert "FMI 3.0 FMU" in capsys.readouterr().out
    description = fmpy.read_model_description(str(target))
    assert description.fmiVersion == "3.0" and {"q1", "time", "energy"} <= {v.name for v in description.modelVariables}


def test_export_needs_lang_or_fmu(capsys):
    assert main(["export", "four_bar"]) == 2
    assert capsys.readouterr().err.strip().count("\n") == 0


# -- bad input: one clear line -------------------------------------------------------------------

@pytest.fixture(scope="module")
def slider_crank_model():
    model, q0, qd0 = file_model("slider_crank")
    return model, q0, qd0


def test_time_varying_parameter_is_refused(slider_crank_model, tmp_path):
    model, q0, qd0 = slider_crank_model
    varying = model.with_parameters(tau=lambda t: np.sin(t))
    with pytest.raises(kronlag.InputError, match=r"parameter\(s\) tau vary with time"):
        kronlag.export_fmu(varying, tmp_path / "x.fmu", q0=q0, qd0=qd0)


def test_start_off_the_constraints_is_refused(slider_crank_model, tmp_path):
    model, q0, qd0 = slider_crank_model
    with pytest.raises(kronlag.InputError, match="violates the constraints"):
        kronlag.export_fmu(model, tmp_path / "x.fmu", q0=q0 + 0.1, qd0=qd0)


@pytest.mark.parametrize("options, message", [({"fmi_version": "1.0"}, "writes FMI 2.0 and 3.0 FMUs"),
                                              ({"kinds": "hybrid"}, "kinds must be"),
                                              ({"tolerance": "tight"}, "tolerance must be a positive number"),
                                              ({"alpha": -1.0}, "alpha must be a non-negative number"),
                                              ({"inputs": ["nope"]}, "'nope' is not a parameter"),
                                              ({"inputs": ["I1"]}, "defined by an expression")])
def test_bad_options_are_refused(slider_crank_model, tmp_path, options, message):
    model, q0, qd0 = slider_crank_model
    with pytest.raises(kronlag.InputError, match=message):
        kronlag.export_fmu(model, tmp_path / "x.fmu", q0=q0, qd0=qd0, **options)


def test_no_compiler_is_one_clear_error(slider_crank_model, tmp_path, monkeypatch):
    model, q0, qd0 = slider_crank_model
    monkeypatch.setattr(fmu_export.build.codegen, "c_compiler", lambda: None)
    with pytest.raises(kronlag.CompilerError, match="FMU export needs a C compiler"):
        kronlag.export_fmu(model, tmp_path / "x.fmu", q0=q0, qd0=qd0)


#: The child process: ``kronlag.simulate`` with the compiled methods (CVODE, ALI3-P), then FMPy's model
#: exchange (its own CVode) on the FMU in the same process; prints both final states as JSON.
_SAME_PROCESS = """
import json, sys
import kronlag
from kronlag.app.workflows import initial_state, numeric_model
from kronlag.model.builtin import resolve_model
from fmpy import simulate_fmu
model_file = resolve_model("four_bar")
model = numeric_model(model_file)
q0, qd0 = initial_state(model_file, model)
runs = [kronlag.simulate(model, (0.0, %r), q0, qd0, method=method, rtol=1e-10, atol=1e-12)
        for method in ("compiled", "switching", "ali3p")]
assert all(run.success for run in runs)
names = list(model.coordinate_names)
result = simulate_fmu(sys.argv[1], fmi_type="ModelExchange", stop_time=%r, output_interval=%r,
                      relative_tolerance=1e-10, output=names)
print(json.dumps({"kronlag": runs[0].q[-1].tolist(), "fmpy": [float(result[name][-1]) for name in names]}))
""" % (T_END, T_END, DT)


def test_fmpy_model_exchange_after_kronlag_simulate_in_the_same_process(exported):
    """The compiled drivers are linked with scikit-sundae's SUNDIALS (run paths), not loaded with global
    symbols: FMPy's own CVode loaded afterwards in the same process does not bind to them (it crashed)."""
    done = subprocess.run([sys.executable, "-c", _SAME_PROCESS, str(exported["four_bar"][3])], capture_output=True,
                          text=True, check=False)
    assert done.returncode == 0, f"exit status {done.returncode}: {done.stderr[-3000:]}"
    final = json.loads(done.stdout)
    np.testing.assert_allclose(final["fmpy"], final["kronlag"], atol=1e-5)
