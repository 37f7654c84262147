"""The C compiler kronlag chooses (:func:`kronlag.numeric.codegen.c_compiler`): a ``$CC`` that does not
work is reported in one line, and where no system compiler is found the one of the ``ziglang`` package
(``pip install kronlag[compiler]``) builds the kernels and the compiled drivers, with the results of GCC."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from kronlag.core.errors import CompilerWarning
from kronlag.numeric import codegen

needs_ziglang = pytest.mark.skipif(importlib.util.find_spec("ziglang") is None,
                                   reason="the ziglang package is not installed (pip install kronlag[compiler])")

#: The four-bar run in a fresh process: the compiler chosen, forward dynamics at a few states, and a
#: simulation by the default method (CVODE's driver) and by ALI3-P (the index-3 driver).
FOUR_BAR_RUN = """
import sys, warnings
import numpy as np
import kronlag
from kronlag.numeric import codegen

warnings.simplefilter("always")
values = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1, m2=3, m3=2.5, I1=0.0033, I2=0.09, I3=0.052, g=9.81, tau=0.7)
model = kronlag.derive(kronlag.models.four_bar()).numeric(values, backend="c")
q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 2.0})
rng = np.random.default_rng(7)
states = [model.assemble(q0 + rng.normal(0, 0.3, 3), qd_fixed={"q1": rng.normal(0, 3)}) for _ in range(5)]
qdd = np.array([model.forward_dynamics(q, qd).qdd for q, qd in [(q0, qd0), *states]])
t_eval = np.linspace(0.0, 2.0, 201)
runs = {method: kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method, t_eval=t_eval)
        for method in ("auto", "ali3p")}
np.savez(sys.argv[1], compiler=codegen.c_compiler().name, qdd=qdd,
         **{f"{method}_q": run.q for method, run in runs.items()},
         **{f"{method}_status": run.status for method, run in runs.items()},
         **{f"{method}_method": run.method for method, run in runs.items()})
"""


@pytest.fixture(autouse=True)
def fresh_choice():
    """Each test sees the choice made and reported anew (each compiler is still probed once)."""
    codegen.build._choose.cache_clear()
    codegen.build._candidates_for.cache_clear()
    yield
    codegen.build._choose.cache_clear()
    codegen.build._candidates_for.cache_clear()


def run_four_bar(tmp_path: Path, name: str, environment: dict[str, str]) -> tuple[dict, str]:
    """:data:`FOUR_BAR_RUN` in a subprocess with ``environment`` and a fresh cache: its results and stderr."""
    output = tmp_path / f"{name}.npz"
    process = subprocess.run([sys.executable, "-c", FOUR_BAR_RUN, str(output)], capture_output=True, text=True,
                             env={**environment, "KRONLAG_CACHE": str(tmp_path / f"cache_{name}")})
    assert process.returncode == 0, process.stderr
    with np.load(output) as results:
        return {key: results[key] for key in results.files}, process.stderr


def without_system_compiler(tmp_path: Path) -> dict[str, str]:
    """The environment less ``$CC``, with PATH a directory holding only the Python interpreter and
    harmless tools (no gcc, no cc)."""
    tools = tmp_path / "bin"
    tools.mkdir()
    for program in (sys.executable, "/bin/sh", "/bin/ls", "/bin/true"):
        if Path(program).exists():
            (tools / Path(program).name).symlink_to(program)
    environment = {key: value for key, value in os.environ.items() if key != "CC"}
    return environment | {"PATH": str(tools)}


@pytest.mark.slow
@needs_ziglang
def test_zig_builds_the_four_bar_as_gcc_does_where_no_system_compiler_is_found(tmp_path):
    system = codegen.c_compiler()
    if system is None or system.name == "zig cc":
        pytest.skip("no system C compiler to compare zig with")
    reference, _ = run_four_bar(tmp_path, "system", dict(os.environ))
    zig, report = run_four_bar(tmp_path, "zig", without_system_compiler(tmp_path))
    assert str(reference["compiler"]) != "zig cc" and str(zig["compiler"]) == "zig cc"
    # reported once, in one line, for the kernels and both drivers
    assert report.count("no C compiler found") == 1
    assert "using zig cc from the ziglang package" in report
    np.testing.assert_allclose(zig["qdd"], reference["qdd"], rtol=1e-12, atol=1e-12)
    for method in ("auto", "ali3p"):
        assert zig[f"{method}_status"] == reference[f"{method}_status"] == 0
        assert zig[f"{method}_method"] == reference[f"{method}_method"]
        # the same C compiled twice: the trajectories agree far below the tolerances (rtol 1e-8)
        np.testing.assert_allclose(zig[f"{method}_q"], reference[f"{method}_q"], rtol=0, atol=1e-8)
    assert str(reference["auto_method"]) in {"switching", "compiled"}


def test_a_broken_cc_is_reported_in_one_line_and_the_next_compiler_is_used(monkeypatch):
    monkeypatch.setenv("CC", "/bin/false")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compiler = codegen.c_compiler()
        assert codegen.c_compiler() == compiler  # reported once
    messages = [str(warning.message) for warning in caught if warning.category is CompilerWarning]
    assert len(messages) == 1 and "\n" not in messages[0]
    assert messages[0].startswith("$CC=/bin/false does not work: exit status 1 building a test library")
    assert compiler is None or compiler.name != "$CC"


def test_no_compiler_at_all_is_a_compiler_error_naming_what_was_tried(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "/bin/false")
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setitem(sys.modules, "ziglang", None)  # not installed
    with pytest.warns(CompilerWarning, match="no working C compiler found.*Python backend is used"):
        assert codegen.c_compiler() is None
    tried = r"\$CC=/bin/false does not work.*gcc: not on PATH.*ziglang package: not installed \(pip install kronlag"
    with pytest.raises(codegen.CompilerError, match=tried):
        codegen.compile_shared_library("int f(void) { return 1; }\n")


@needs_ziglang
def test_the_compiler_is_part_of_the_library_key(tmp_path, monkeypatch):
    system = codegen.c_compiler()
    if system is None or system.name == "zig cc":
        pytest.skip("no system C compiler besides zig")
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    source = "double kronlag_twice(double x) { return 2 * x; }\n"
    system = codegen.compile_shared_library(source)
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.delenv("CC", raising=False)
    with pytest.warns(CompilerWarning, match="using zig cc"):
        zig = codegen.compile_shared_library(source)
    assert zig != system and zig.is_file() and system.is_file()


def test_a_compiler_found_later_on_the_list_is_used_quietly(tmp_path, monkeypatch):
    system = codegen.c_compiler()
    if system is None or system.name == "zig cc":
        pytest.skip("no system C compiler")
    (tmp_path / "cc").symlink_to(system.command[0])  # gcc missing, cc there: nothing to report
    for tool in ("as", "ld"):  # which gcc runs from PATH
        if shutil.which(tool):
            (tmp_path / tool).symlink_to(shutil.which(tool))
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        compiler = codegen.c_compiler()
    assert compiler.name == "cc" and compiler.command == (str(tmp_path / "cc"), *system.command[1:])


def test_the_linked_libraries_are_part_of_the_library_key_and_its_run_path(tmp_path, monkeypatch):
    """A library linked with shared libraries (the compiled drivers with SUNDIALS) is keyed by their paths,
    and loads them itself (run paths), with nothing loaded with global symbols first."""
    if codegen.c_compiler() is None:
        pytest.skip("no C compiler")
    from kronlag.simulation.drivers import sundials_libraries

    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    source = "int SUNDIALSGetVersionNumber(int *, int *, int *, char *, int);\n" \
             "int kronlag_major(void) { int a = 0, b = 0, c = 0; char label[64];\n" \
             "    SUNDIALSGetVersionNumber(&a, &b, &c, label, 64); return a; }\n"
    libraries = tuple(sundials_libraries())
    linked = codegen.compile_shared_library(source, libraries=libraries)
    assert linked != codegen.compile_shared_library(source, libraries=libraries[:1])
    check = ("import ctypes, sys\nlibrary = ctypes.CDLL(sys.argv[1])\nprint(library.kronlag_major())\n")
    done = subprocess.run([sys.executable, "-c", check, str(linked)], capture_output=True, text=True, check=False)
    assert done.returncode == 0 and done.stdout.strip() == "7", done.stderr[-2000:]
