"""Bounded inputs (issue 17): every input with a size has a stated limit (:mod:`kronlag.core.limits`)
checked before any work, and ends in one line (CLI: exit 2) or an InputError / ModelFileError (API),
never a traceback, a hang or an exhausted memory; non-finite guesses are named, not "SVD did not
converge"; a long chain of derived parameters loads in about linear time."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time

import numpy as np
import pytest
from helpers import numeric

import kronlag
from kronlag.core.errors import InputError, ModelFileError
from kronlag.core.limits import MAX_ENTRIES, MAX_MODEL_FILE_BYTES, MAX_NESTING, MAX_OUTPUT_POINTS
from kronlag.model.modelfile import load_model, loads_model

POINT = """\
name = "point"
coordinates = ["x"]
[parameters]
m = 1.0
[[bodies]]
name = "b"
type = "point"
mass = "m"
position = ["x", 0]
"""

#: The hostile model files, by name: their text (a function of nothing, built on demand).
HOSTILE_FILES = {
    "too_large": lambda: POINT + ("# " + "x" * 1000 + "\n") * (MAX_MODEL_FILE_BYTES // 1000),
    "nested_arrays": lambda: POINT.replace("m = 1.0", "m = 1.0\ndeep = " + "[" * 5000 + "]" * 5000),
    "nested_tables": lambda: POINT + "[initial]\nq = " + "{a = " * 5000 + "1" + "}" * 5000 + "\n",
    "nested_dotted_keys": lambda: POINT + "[drawing_options]\n" + ".".join(["a"] * 100) + " = 1\n",
    "ten_thousand_bodies": lambda: POINT + "".join(
        f'[[bodies]]\nname = "b{i}"\ntype = "point"\nmass = "m"\nposition = ["x", {i}]\n' for i in range(10_000)),
}

#: What each hostile file's one-line message says.
HOSTILE_MESSAGES = {
    "too_large": f"larger than {MAX_MODEL_FILE_BYTES // 2**20} MiB",
    "nested_arrays": f"nested more than {MAX_NESTING} levels deep",
    "nested_tables": f"nested more than {MAX_NESTING} levels deep",
    "nested_dotted_keys": f"nested more than {MAX_NESTING} levels deep",
    "ten_thousand_bodies": f"bodies: 10001 entries, more than the limit of {MAX_ENTRIES}",
}


def run_cli(*arguments: str) -> subprocess.CompletedProcess:
    """``python -m kronlag ARGUMENTS`` in a process of at most 4 GB (a grid of 10^9 points fails
    there rather than exhausting the machine), stopped after 10 minutes."""

    def limit_memory() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (4 * 2**30, 4 * 2**30))

    return subprocess.run([sys.executable, "-m", "kronlag", *arguments], capture_output=True, text=True,
                          timeout=600, preexec_fn=limit_memory, env=os.environ.copy())


def assert_one_line_error(process: subprocess.CompletedProcess, expected: str) -> None:
    assert process.returncode == 2, process.stderr
    assert "Traceback" not in process.stderr
    lines = process.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kronlag: error: ") and expected in lines[0], process.stderr


# -- model files ------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(HOSTILE_FILES))
def test_hostile_model_file_is_refused_by_the_api(name, tmp_path):
    path = tmp_path / f"{name}.toml"
    path.write_text(HOSTILE_FILES[name]())
    with pytest.raises(ModelFileError, match=HOSTILE_MESSAGES[name]) as error:
        load_model(path)
    assert str(error.value).startswith(f"{path}: ") and "\n" not in str(error.value)
    with pytest.raises(ModelFileError, match=HOSTILE_MESSAGES[name]):
        loads_model(path.read_text())


@pytest.mark.parametrize("name", list(HOSTILE_FILES))
def test_hostile_model_file_is_one_line_and_exit_2_in_the_cli(name, tmp_path):
    path = tmp_path / f"{name}.toml"
    path.write_text(HOSTILE_FILES[name]())
    assert_one_line_error(run_cli("check", str(path)), HOSTILE_MESSAGES[name])


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero")
def test_endless_model_file_is_read_only_up_to_the_limit():
    with pytest.raises(ModelFileError, match=f"/dev/zero: the file is larger than {MAX_MODEL_FILE_BYTES // 2**20} MiB"):
        load_model("/dev/zero")
    assert_one_line_error(run_cli("check", "/dev/zero"), "larger than")


def test_many_entries_of_the_parameters_table_are_allowed_up_to_their_own_limit():
    text = POINT.replace("m = 1.0", "m = 1.0\n" + "".join(f"p{i} = {i}\n" for i in range(MAX_ENTRIES + 1)))
    assert len(loads_model(text).values) == MAX_ENTRIES + 2


def test_a_3000_parameter_chain_loads_in_near_linear_time():
    chain = "p1 = 1\n" + "".join(f'p{i} = "p{i - 1}+1"\n' for i in range(2, 3001))
    text = POINT.replace("m = 1.0", "m = 1.0\n" + chain)
    started = time.perf_counter()
    model = loads_model(text)
    elapsed = time.perf_counter() - started
    values = model.numeric_values()
    assert values["p3000"] == 3000.0 and len(values) == 3001
    print(f"3000-parameter chain loaded in {elapsed:.2f} s")
    assert elapsed < 30  # 57 s (on a quiet machine) before; generous: the machine may be shared


def test_a_parameter_cycle_and_a_missing_parameter_are_still_named():
    cycle = POINT.replace("m = 1.0", 'm = 1.0\na = "b + 1"\nb = "a + 1"\nc = "b * 2"')
    with pytest.raises(ModelFileError, match="parameters: parameter values depend on each other in a cycle: a, b, c"):
        loads_model(cycle)
    missing = POINT.replace("m = 1.0", 'm = 1.0\nz = {unit = "m"}\nw = "2 * z"')
    with pytest.raises(ModelFileError, match="parameters without a value: z"):
        loads_model(missing)


# -- output grids -----------------------------------------------------------------------------------


@pytest.mark.parametrize("arguments, expected", [
    (("--points", "1000000000"), f"--points 1000000000: more than the limit of {MAX_OUTPUT_POINTS}"),
    (("--dt", "1e-9", "--t-end", "1000"), f"more than the limit of {MAX_OUTPUT_POINTS}: give a larger --dt"),
])
def test_huge_output_grid_is_one_line_and_exit_2_in_the_cli(arguments, expected):
    assert_one_line_error(run_cli("simulate", "double_pendulum", *arguments), expected)


def test_huge_sweep_output_grid_is_one_line_and_exit_2_before_any_case():
    result = run_cli("sweep", "double_pendulum", "--grid", "m1=1,2", "--workers", "0", "--points", "1000000000")
    assert_one_line_error(result, f"--points 1000000000: more than the limit of {MAX_OUTPUT_POINTS}")


def test_huge_t_eval_is_an_input_error():
    model = numeric("double_pendulum", "python")
    with pytest.raises(InputError, match=f"t_eval has {MAX_OUTPUT_POINTS + 1} output times, more than the limit"):
        kronlag.simulate(model, (0.0, 1.0), [0.3, 0.2], [0.0, 0.0], t_eval=np.linspace(0.0, 1.0, MAX_OUTPUT_POINTS + 1))


# -- non-finite guesses -------------------------------------------------------------------------------


@pytest.mark.parametrize("call, expected", [
    (lambda model: model.assemble([np.nan, 0.5, 1.0]), r"q_guess is not finite for q1 \(nan\)"),
    (lambda model: model.assemble([1.5, 0.5, np.inf]), r"q_guess is not finite for q3 \(inf\)"),
    (lambda model: model.assemble([1.5, 0.5, 1.0], qd_guess=[0.0, np.nan, 0.0]), r"qd_guess is not finite for q2"),
    (lambda model: model.assemble([1.5, 0.5, 1.0], fixed={"q1": np.nan}),
     r"q_guess \(with the held values\) is not finite for q1 \(nan\)"),
    (lambda model: model.equilibrium([np.nan, 0.5, 1.0]), r"q_guess is not finite for q1 \(nan\)"),
])
def test_non_finite_guess_is_named(call, expected):
    model = numeric("four_bar", "python")
    with pytest.raises(InputError, match=expected):
        call(model)
