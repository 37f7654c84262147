"""Exported code: C and Fortran compile and, called through ctypes, agree with the
symbolic matrices; Python runs and agrees; Octave and Julia are syntax-checked
when their tools are installed."""

from __future__ import annotations

import ctypes
import json
import random
import shutil
import subprocess

import numpy as np
import pytest
import sympy as sp
from helpers import derived, evaluate

from kronlag.symbolic.export import EXPORTED, LANGUAGES, export_code, exported_matrices, format_equations

MODELS = ["four_bar", "heavy_top", "chaplygin_sleigh", "quick_return"]


def expected_matrices(eom, values: dict) -> dict[str, np.ndarray]:
    """The matrices at ``values`` by substitution into the symbolic ones; ``gamma`` from the chain
    rule ``-(d(Phi_q qd)/dq) qd``, independent of :func:`kronlag.calculus.time_derivative`."""
    qd = sp.Matrix(eom.speeds)
    gamma = -(eom.Phi_q * qd).jacobian(sp.Matrix(eom.coordinates)) * qd if eom.Phi.rows else sp.zeros(0, 1)
    symbolic = {name: getattr(eom, name) for name in EXPORTED if name != "gamma"} | {"gamma": gamma}
    return {name: np.array(evaluate(matrix, values), dtype=float).reshape(matrix.shape)
            for name, matrix in symbolic.items()}


def random_state(eom, seed: int = 1) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray, float]:
    rng = random.Random(seed)
    q = np.array([rng.uniform(-3, 3) for _ in eom.coordinates])
    qd = np.array([rng.uniform(-3, 3) for _ in eom.speeds])
    p = np.array([rng.uniform(0.5, 2) for _ in eom.parameters])
    time = 0.7
    values = dict(zip(eom.coordinates, q)) | dict(zip(eom.speeds, qd)) | dict(zip(eom.parameters, p))
    values[eom.time] = time
    return values, q, qd, p, time


def compile_library(tmp_path, source: str, suffix: str, compiler: list[str]) -> ctypes.CDLL:
    source_file = tmp_path / f"exported.{suffix}"
    source_file.write_text(source)
    library = tmp_path / "libexported.so"
    subprocess.run([*compiler, "-shared", "-fPIC", "-o", str(library), str(source_file)], check=True,
                   capture_output=True, text=True)
    return ctypes.CDLL(str(library))


def pointer(array: np.ndarray):
    return array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
@pytest.mark.parametrize("name", MODELS)
def test_c_export_compiles_and_agrees(tmp_path, name):
    eom = derived(name)
    library = compile_library(tmp_path, export_code(eom, "c"), "c", ["gcc", "-std=c99", "-Wall", "-Werror"])
    values, q, qd, p, time = random_state(eom)
    expected = expected_matrices(eom, values)
    for matrix in EXPORTED:
        out = np.full(expected[matrix].size, np.nan)
        getattr(library, f"{name}_{matrix}")(ctypes.c_double(time), pointer(q), pointer(qd), pointer(p), pointer(out))
        np.testing.assert_allclose(out.reshape(expected[matrix].shape), expected[matrix], rtol=1e-12, atol=1e-12,
                                   err_msg=matrix)


@pytest.mark.skipif(shutil.which("gfortran") is None, reason="gfortran is not installed")
@pytest.mark.parametrize("name", ["four_bar", "heavy_top"])
def test_fortran_export_compiles_and_agrees(tmp_path, name):
    eom = derived(name)
    library = compile_library(tmp_path, export_code(eom, "fortran"), "f90", ["gfortran", "-std=f2008"])
    values, q, qd, p, time = random_state(eom)
    expected = expected_matrices(eom, values)
    for matrix in EXPORTED:
        out = np.full(expected[matrix].shape, np.nan, order="F")
        subroutine = getattr(library, f"{name}_{matrix}".lower() + "_")
        subroutine(ctypes.byref(ctypes.c_double(time)), pointer(q), pointer(qd), pointer(p), pointer(out))
        np.testing.assert_allclose(out, expected[matrix], rtol=1e-12, atol=1e-12, err_msg=matrix)


@pytest.mark.parametrize("name", MODELS)
def test_python_export_runs_and_agrees(name):
    eom = derived(name)
    namespace: dict = {}
    exec(compile(export_code(eom, "python"), f"<{name} export>", "exec"), namespace)
    values, q, qd, p, time = random_state(eom, seed=2)
    for matrix, expected in expected_matrices(eom, values).items():
        result = namespace[f"{name}_{matrix}"](time, q, qd, p)
        np.testing.assert_allclose(np.reshape(result, expected.shape), expected, rtol=1e-12, atol=1e-12,
                                   err_msg=matrix)


@pytest.mark.parametrize("lang, tool, check", [
    ("octave", "octave", ["octave", "--no-gui", "--eval", "source('{path}')"]),
    ("julia", "julia", ["julia", "--startup-file=no", "-e", "include(\"{path}\")"]),
])
def test_script_exports_load(tmp_path, lang, tool, check):
    if shutil.which(tool) is None:
        pytest.skip(f"{tool} is not installed")
    path = tmp_path / f"four_bar.{lang}"
    path.write_text(export_code(derived("four_bar"), lang))
    subprocess.run([part.format(path=path) for part in check], check=True, timeout=1800)


@pytest.mark.parametrize("lang", LANGUAGES)
def test_header_lists_the_argument_order(lang):
    code = export_code(derived("slider_crank"), lang)
    header = code[:code.index("slider_crank_M")]
    first = "0" if lang in ("c", "python") else "1"
    for text in ("(t, q, qd, p)", f"q{'[' if lang in ('c', 'python', 'julia') else '('}{first}", "= q1",
                 "= x", "= xd", "= l1", "= tau"):
        assert text in header, (lang, text)
    for function in EXPORTED:
        assert f"slider_crank_{function}" in code


def test_parameter_order_and_builtin_values():
    eom = derived("double_pendulum")
    namespace: dict = {}
    exec(export_code(eom, "python", parameters={"g": 9.81, "l1": 1.0}), namespace)
    values = {"l2": 0.5, "m1": 1.2, "m2": 0.8, "I1": 0.1, "I2": 0.02}
    reordered: dict = {}
    exec(export_code(eom, "python", parameters=["g", "l1", "l2", "m1", "m2", "I1", "I2"]), reordered)
    q, qd = np.array([0.3, -0.4]), np.zeros(2)
    left = namespace["double_pendulum_g"](0.0, q, qd, np.array([values[k] for k in ("l2", "m1", "m2", "I1", "I2")]))
    right = reordered["double_pendulum_g"](0.0, q, qd, np.array([9.81, 1.0, *values.values()]))
    np.testing.assert_allclose(left, right, rtol=1e-14)
    with pytest.raises(ValueError, match="missing: I2"):
        export_code(eom, "c", parameters=["g", "l1", "l2", "m1", "m2", "I1"])
    with pytest.raises(ValueError, match="'k' is not a parameter"):
        export_code(eom, "c", parameters={"k": 1.0})
    with pytest.raises(ValueError, match="unknown language 'cobol'"):
        export_code(eom, "cobol")


def test_gamma_is_minus_the_time_derivative_of_phi_q_times_qd():
    eom = derived("four_bar")
    qd = sp.Matrix(eom.speeds)
    chain_rule = -(eom.Phi_q * qd).jacobian(sp.Matrix(eom.coordinates)) * qd
    assert sp.simplify(exported_matrices(eom)["gamma"] - chain_rule) == sp.zeros(2, 1)


@pytest.mark.parametrize("fmt", ["text", "latex", "markdown", "json"])
def test_format_equations(fmt):
    eom = derived("chaplygin_sleigh")
    report = format_equations(eom, fmt)
    if fmt == "json":
        data = json.loads(report)
        assert data["shape"] == {"m": 3, "r": 0, "s": 1}
        assert data["matrices"]["A"] == [[sp.sstr(entry) for entry in eom.A]]
        assert len(data["equations"]) == 4 and "C_christoffel" in data["matrices"]
    else:
        assert "C_christoffel" in report and "f_Q" in report and "Phi_q" not in report
    with pytest.raises(ValueError, match="unknown format"):
        format_equations(eom, "html")
