"""Safety of the numeric core: a private, content-checked cache of compiled code, constants that reach
the generated code exactly, a fallback when the compiler fails, calls from several threads, and user
strings that cannot escape the comments of exported code or the working directory."""

from __future__ import annotations

import ast
import os
import shlex
import shutil
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import derived

import kronlag
from kronlag.numeric import codegen
from kronlag.numeric.codegen import c_backend
from kronlag.symbolic.export import LANGUAGES, export_code, file_stem

needs_compiler = pytest.mark.skipif(codegen.c_compiler() is None, reason="no C compiler")
FOUR_BAR = dict(l1=1.0, l2=2.0, l3=2.0, l4=2.0, m1=1.0, m2=2.0, m3=2.0, I1=1 / 12, I2=2 / 3, I3=2 / 3, g=9.81,
                tau=1.0)


def point_mass(mass, *, name: str = "point") -> kronlag.Equations:
    """One point of mass ``mass`` (an expression in the parameter m1) moving along x: M = [[mass]]."""
    q1, = kronlag.coordinates("q1")
    m1 = sp.Symbol("m1")
    system = kronlag.System([q1], parameters=[m1], name=name)
    system.add_body(kronlag.PointMass("p", mass=mass * m1, position=(q1, 0)))
    return kronlag.derive(system)


def build_double_pendulum(cache: Path) -> None:
    """Build the double pendulum's C model in a fresh process with the cache ``cache``."""
    script = textwrap.dedent("""
        import kronlag
        from kronlag import models
        values = dict(l1=1.0, l2=1.0, m1=1.0, m2=1.0, I1=0.1, I2=0.1, g=9.81)
        model = kronlag.derive(models.double_pendulum()).numeric(values, backend="c")
        result = model.forward_dynamics([0.3, 0.2], [0.0, 0.0])
        print(float(result.qdd[0]))
    """)
    environment = {**os.environ, "KRONLAG_CACHE": str(cache)}
    process = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=environment,
                             timeout=600)
    assert process.returncode == 0, process.stderr
    return float(process.stdout)


# -- the cache of compiled code ------------------------------------------------------------------


@needs_compiler
def test_cache_directory_is_created_private(tmp_path, monkeypatch):
    cache = tmp_path / "new" / "cache"
    monkeypatch.setenv("KRONLAG_CACHE", str(cache))
    point_mass(1).numeric({"m1": 1.0}, backend="c")
    assert cache.stat().st_mode & 0o777 == 0o700
    libraries = list(cache.glob("kronlag_*.so"))
    assert libraries and all(Path(f"{library}.sha256").is_file() for library in libraries)


def check_fallback(cache: Path, reason: str) -> None:
    """A C model built with the cache ``cache`` in a fresh process warns once (CacheWarning naming
    ``cache`` and ``reason``), computes the right M and leaves nothing in ``cache``."""
    script = textwrap.dedent("""
        import warnings
        import sympy as sp
        import kronlag
        q1, = kronlag.coordinates("q1")
        m1 = sp.Symbol("m1")
        system = kronlag.System([q1], parameters=[m1], name="point")
        system.add_body(kronlag.PointMass("p", mass=3 * m1, position=(q1, 0)))
        system.add_generalized_force([1])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(2):  # a second model: no second warning
                model = kronlag.derive(system).numeric({"m1": 2.0})
                values = (model.backend, model.M([0.0])[0, 0], model.forward_dynamics([0.0], [0.0]).qdd[0])
        print(*values)
        for warning in caught:
            print(warning.category.__name__, warning.message)
    """)
    process = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600,
                             env={**os.environ, "KRONLAG_CACHE": str(cache)})
    assert process.returncode == 0, process.stderr
    values, *warnings = process.stdout.splitlines()
    backend, mass, acceleration = values.split()
    assert (backend, float(mass)) == ("c", 6.0) and float(acceleration) == pytest.approx(1 / 6, rel=1e-14)
    assert len(warnings) == 1 and warnings[0].startswith("CacheWarning"), warnings
    assert str(cache) in warnings[0] and reason in warnings[0] and "private temporary directory" in warnings[0]


@needs_compiler
def test_world_writable_cache_directory_is_not_used(tmp_path):
    cache = tmp_path / "shared"
    cache.mkdir()
    cache.chmod(0o777)
    check_fallback(cache, "writable by its group and others")
    assert not list(cache.iterdir())


@needs_compiler
def test_cache_directory_inside_a_world_writable_directory_is_not_used(tmp_path):
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)  # no sticky bit: anyone may rename the cache away and put their own in its place
    check_fallback(shared / "cache", f"inside {shared}, which everyone may write to")
    assert not list((shared / "cache").iterdir())


@needs_compiler
def test_cache_directory_that_cannot_be_created_is_not_used(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a regular file, so no directory can be made below it")
    check_fallback(blocker / "cache", "cannot be created")


@needs_compiler
@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes to a mode-500 directory")
def test_read_only_cache_directory_is_not_used(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o500)
    check_fallback(cache, "not writable")


@needs_compiler
@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="needs root to chown")
def test_cache_directory_of_another_user_is_not_used(tmp_path):
    import pwd

    nobody = pwd.getpwnam("nobody")
    cache = tmp_path / "planted"
    cache.mkdir(mode=0o700)
    os.chown(cache, nobody.pw_uid, nobody.pw_gid)
    check_fallback(cache, f"owned by uid {nobody.pw_uid}")
    assert not list(cache.iterdir())


@needs_compiler
def test_swapped_libraries_with_their_digests_are_rebuilt(tmp_path):
    """The files of two models exchanged, digests included: each model still computes its own M."""
    script = textwrap.dedent("""
        import sys
        import sympy as sp
        import kronlag
        factor = int(sys.argv[1])
        q1, = kronlag.coordinates("q1")
        m1 = sp.Symbol("m1")
        system = kronlag.System([q1], parameters=[m1], name="point")
        system.add_body(kronlag.PointMass("p", mass=factor * m1, position=(q1, 0)))
        system.add_generalized_force([1])
        model = kronlag.derive(system).numeric({"m1": 1.0}, backend="c")
        print(model.M([0.0])[0, 0], model.forward_dynamics([0.0], [0.0]).qdd[0])
    """)
    cache = tmp_path / "cache"

    def run(factor: int) -> tuple[float, float]:
        process = subprocess.run([sys.executable, "-W", "error", "-c", script, str(factor)], capture_output=True,
                                 text=True, timeout=600, env={**os.environ, "KRONLAG_CACHE": str(cache)})
        assert process.returncode == 0, process.stderr
        return tuple(map(float, process.stdout.split()))

    assert run(2) == pytest.approx((2.0, 0.5), rel=1e-14)  # the symbolic M = 2 m1 and qdd = 1 / M
    first = {path: path.stat().st_mtime_ns for path in cache.glob("kronlag_*.so")}
    assert run(3) == pytest.approx((3.0, 1 / 3), rel=1e-14)
    second = sorted(set(cache.glob("kronlag_*.so")) - set(first), key=lambda path: path.stat().st_mtime_ns)
    first = sorted(first, key=first.get)
    assert len(first) == len(second) == 2  # the dynamics, then the other matrices (M)
    for a, b in zip(first, second):  # the libraries built in the same order play the same part
        for suffix in ("", ".sha256"):
            a_file, b_file, swap = Path(f"{a}{suffix}"), Path(f"{b}{suffix}"), tmp_path / "swap"
            os.replace(a_file, swap)
            os.replace(b_file, a_file)
            os.replace(swap, b_file)
    assert run(2) == pytest.approx((2.0, 0.5), rel=1e-14)  # still its own M, not the other model's
    assert run(3) == pytest.approx((3.0, 1 / 3), rel=1e-14)
    assert len(list(cache.glob("kronlag_*.so"))) == 4


@needs_compiler
def test_truncated_or_replaced_library_is_rebuilt_not_loaded(tmp_path):
    cache = tmp_path / "cache"
    expected = build_double_pendulum(cache)
    library, = cache.glob("kronlag_*.so")
    content = library.read_bytes()
    # truncated in place (a crash that left part of the file): loading it would crash with SIGBUS
    with open(library, "r+b") as handle:
        handle.truncate(3000)
    assert build_double_pendulum(cache) == expected
    assert library.read_bytes() == content
    # replaced by another library (valid, but not what was built from this source)
    other = tmp_path / "other"
    subprocess.run([*codegen.c_compiler().command, "-shared", "-fPIC", "-o", str(other), "-x", "c", "-"],
                   input="int kronlag_dynamics;\n", text=True, check=True)
    shutil.copyfile(other, library)
    assert build_double_pendulum(cache) == expected
    assert library.read_bytes() == content


# -- constants --------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", [pytest.param("c", marks=needs_compiler), "python"])
@pytest.mark.parametrize("factor", [10**20, 2**64, sp.Rational(10**30, 3), sp.Rational(10**20 + 1, 3),
                                    sp.Float("1e-300"), sp.Rational(1, 3), 7,
                                    # parts of 16 digits: exact doubles, but SymEngine prints 15 digits
                                    sp.Rational(10**15 + 1, 1024), sp.Float(0.99999968)])
def test_constants_reach_the_code_correctly_rounded(factor, backend, tmp_path, monkeypatch):
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    model = point_mass(factor).numeric({"m1": 1.0}, backend=backend)
    assert model.M([0.0])[0, 0] == float(factor)  # the double nearest to the constant, exactly
    assert model.forward_dynamics([0.0], [0.0]).qdd[0] == 0.0


@pytest.mark.parametrize("constant, kind", [(sp.sqrt(-1), "complex"), (sp.oo, "non-finite"),
                                            (sp.Float("inf"), "non-finite")])
def test_complex_or_infinite_constant_is_a_model_error(constant, kind):
    with pytest.raises(kronlag.ModelError, match=rf"M\[0, 0\] = .*{kind} constant"):
        point_mass(constant).numeric({"m1": 1.0}, backend="python")


# -- a compiler that fails --------------------------------------------------------------------


@needs_compiler
def test_failing_compiler_falls_back_to_python_with_a_warning(tmp_path, monkeypatch):
    # a compiler that works (it builds the test library of codegen.c_compiler) but fails on the model's code
    failing = tmp_path / "failing-cc"
    system = shlex.join(codegen.c_compiler().command)
    failing.write_text(f'#!/bin/sh\ncase "$*" in *model.c*) exit 1;; esac\nexec {system} "$@"\n')
    failing.chmod(0o755)
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", str(failing))
    eom = derived("four_bar")
    with pytest.warns(RuntimeWarning, match="C compiler failed.*Python backend"):
        model = eom.numeric(FOUR_BAR)
    assert model.backend == "python"
    q = np.array([np.pi / 2, 0.5, 1.0])
    np.testing.assert_allclose(model.M(q), eom.numeric(FOUR_BAR, backend="python").M(q), rtol=0, atol=0)
    with pytest.raises(codegen.CompilerError, match="failing-cc"):
        eom.numeric(FOUR_BAR, backend="c")


# -- threads ----------------------------------------------------------------------------------


@pytest.mark.parametrize("fast_call", [pytest.param(True, marks=needs_compiler),
                                       pytest.param(False, marks=needs_compiler)])
def test_calls_from_four_threads_agree_with_serial_calls(fast_call, monkeypatch):
    if not fast_call:
        monkeypatch.setattr(c_backend, "FAST_CALL", None)
    elif codegen.FAST_CALL is None:
        pytest.skip("kronlag.numeric.codegen._call is not built")
    model = derived("four_bar").numeric({**FOUR_BAR, "tau": lambda t: np.sin(t)}, backend="c")
    rng = np.random.default_rng(3)
    states = [(rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3), float(rng.uniform(0, 5))) for _ in range(200)]
    expected = [(model.forward_dynamics(q, qd, t).qdd, model.M(q, t), model.f_Q(q, qd, t)) for q, qd, t in states]
    mismatches = []

    def work(offset: int) -> None:
        for repeat in range(10):
            for k in range(len(states)):
                i = (k + offset * 37 + repeat) % len(states)
                q, qd, t = states[i]
                got = (model.forward_dynamics(q, qd, t).qdd, model.M(q, t), model.f_Q(q, qd, t))
                if not all(np.array_equal(a, b) for a, b in zip(got, expected[i])):
                    mismatches.append(i)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert mismatches == []


# -- user strings in exported code and file names ------------------------------------------------

HOSTILE = "evil\nimport os; os.system('echo pwned') \\\r\n*/ #= %{\u2028x"


def test_hostile_model_name_stays_in_comments_of_exported_python():
    source = export_code(point_mass(1, name=HOSTILE), "python")
    tree = ast.parse(source)
    statements = [type(node).__name__ for node in tree.body]
    assert set(statements) <= {"Import", "FunctionDef"}
    assert [alias.name for node in tree.body if isinstance(node, ast.Import) for alias in node.names] \
        == ["math", "numpy"]
    assert all(line.startswith("#") for line in source.split("\n\n")[0].splitlines())


@pytest.mark.parametrize("lang", LANGUAGES)
def test_hostile_model_name_keeps_every_header_line_a_comment(lang):
    source = export_code(point_mass(1, name=HOSTILE), lang)
    header = source.split("\n\n")[0]
    comment = {"c": "//", "fortran": "!", "octave": "%", "julia": "#", "python": "#"}[lang]
    assert all(line.startswith(comment) for line in header.splitlines())
    assert not any(character in header for character in "\r\\\u2028")
    assert "evil_import_os__os_system__echo_pwned" in source  # the function names: identifiers


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_hostile_model_name_exports_c_that_compiles(tmp_path):
    source = tmp_path / "hostile.c"
    source.write_text(export_code(point_mass(1, name=HOSTILE), "c"))
    subprocess.run(["gcc", "-c", "-Wall", "-Werror", "-o", str(tmp_path / "hostile.o"), str(source)], check=True)


@pytest.mark.parametrize("name", ["../../etc/evil", "/tmp/evil", "..", "a/b\\c", "\n", "évil"])
def test_file_names_from_model_names_stay_in_the_directory(name, tmp_path):
    path = tmp_path / f"{file_stem(name)}-partial.npz"
    assert path.parent == tmp_path and path.resolve().parent == tmp_path.resolve()
    assert path.name.isascii() and not path.name.startswith(".")
