"""Packaging: the type check of the public API (mypy, on a user's script and on the package as
pyproject.toml's [tool.mypy] scopes it), and the wheel and sdist of ``python -m build``: what the wheel
holds, and its install into a fresh virtual environment running the README's first command.

The build and the install need the package registry (build isolation, the dependencies; pip's cache
is used): without it those tests are skipped, saying so.
"""

import ast
import os
import re
import shlex
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from kronlag._legacy import MOVED
from kronlag.numeric.accessors import ACCESSOR_MATRICES

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "kronlag"

#: What pip prints when it cannot reach the package registry (then the test is skipped): a failed
#: connection, or no version at all of a requirement (a registry that answers lists some: a conflict fails).
_UNREACHABLE = re.compile(r"Failed to establish a new connection|Temporary failure in name resolution|"
                          r"Network is unreachable|Max retries exceeded|Connection refused|ProxyError|"
                          r"Read timed out|Could not find a version that satisfies the requirement .*"
                          r"\(from versions: none\)")

#: A user's script: the public API as the README and the documentation use it, annotated.
USER_SCRIPT = '''
import numpy as np

import kronlag
from kronlag.model.builtin import load_example

example = load_example("four_bar", apply_drives=False)
equations: kronlag.Equations = kronlag.derive(example.system)
model: kronlag.NumericModel = equations.numeric(example.values)
q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 6.0})
mass: np.ndarray = model.M(q0)
jacobian: np.ndarray = model.Phi_q(q0, 0.0)
coriolis: np.ndarray = model.C(q0, qd0)
lam: np.ndarray = model.forward_dynamics(q0, qd0).lam
trajectory: kronlag.Trajectory = kronlag.simulate(model, (0.0, 0.1), q0, qd0, t_eval=np.linspace(0.0, 0.1, 5))
status: int = trajectory.status
success: bool = trajectory.success
names: tuple[str, ...] = trajectory.coordinate_names
q: np.ndarray = trajectory.q
energy: np.ndarray = trajectory.total_energy
columns: dict[str, np.ndarray] = trajectory.columns()
events: tuple[kronlag.SingularPassage | kronlag.LimitEvent | kronlag.StictionEvent, ...] = trajectory.events
result: kronlag.Result = trajectory.result
trajectory.to_csv("run.csv")
swept: kronlag.SweepResult = kronlag.sweep(model, parameters={"tau": [0.0, 1.0]}, initial_states=(q0, qd0),
                                           t_span=(0.0, 0.1), workers=0)
four_bar: kronlag.System = kronlag.models.four_bar()
frame: kronlag.Frame = kronlag.frames.Frame()
'''

#: Mistakes the type check must catch in that script (so that the API is typed, not Any).
MISTAKES = {
    "label: str = trajectory.status": "Incompatible types in assignment",
    "model.M(q0, 0.0, 1)": 'Too many arguments for "M"',
    "trajectory.energy": 'has no attribute "energy"',
    "kronlag.models.four_bars()": 'has no attribute "four_bars"',
    "kronlag.simulate(model, 1.0, q0, qd0)": 'Argument 2 to "simulate" has incompatible type "float"',
}


def _mypy(*arguments: str, cwd: Path, cache: Path) -> subprocess.CompletedProcess:
    """mypy with pyproject.toml's configuration (a fresh cache: a stale one can hide the stubs' changes)."""
    pytest.importorskip("mypy")
    return subprocess.run([sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
                           "--cache-dir", str(cache), *arguments],
                          cwd=cwd, capture_output=True, text=True, env={**os.environ, "MYPYPATH": str(ROOT / "src")})


def test_py_typed_is_shipped():
    assert (PACKAGE / "py.typed").is_file()
    assert re.search(r'kronlag = \[[^]]*"py\.typed", "\*\.pyi"', (ROOT / "pyproject.toml").read_text())


def test_the_stubs_of_the_former_module_paths_follow_moved():
    """``kronlag.models`` and the other former modules the facade imports are made by an import hook,
    which type checkers cannot run: a stub gives each its names, from the modules MOVED lists."""
    facade = ast.parse((PACKAGE / "__init__.py").read_text())
    imported = {alias.name for node in facade.body if isinstance(node, ast.ImportFrom) and node.level == 1
                and node.module is None for alias in node.names}
    legacy = {name for name in imported if f"kronlag.{name}" in MOVED}
    assert legacy == {"calculus", "frames", "joints", "models"}
    assert {path.stem for path in PACKAGE.glob("*.pyi")} == legacy
    for name in legacy:
        stub = ast.parse((PACKAGE / f"{name}.pyi").read_text())
        sources = tuple(node.module for node in stub.body if isinstance(node, ast.ImportFrom))
        assert sources == MOVED[f"kronlag.{name}"], name


def test_the_declared_accessors_are_the_catalogues():
    """The matrix accessors set at run time and declared for type checkers are the same, with ``qd``
    exactly where the matrix depends on the speeds."""
    tree = ast.parse((PACKAGE / "numeric" / "accessors.py").read_text())
    declared = {node.name: [argument.arg for argument in node.args.args]
                for node in ast.walk(tree) if isinstance(node, ast.FunctionDef) and node.name[0] != "_"
                and node.name not in ("of_speeds", "of_positions")}
    assert set(declared) == {entry.name for entry in ACCESSOR_MATRICES}
    for entry in ACCESSOR_MATRICES:
        assert declared[entry.name] == (["self", "q", "qd", "t"] if entry.speeds else ["self", "q", "t"]), entry.name


@pytest.mark.slow
def test_a_users_script_type_checks(tmp_path):
    (tmp_path / "usage.py").write_text(USER_SCRIPT)
    checked = _mypy("usage.py", cwd=tmp_path, cache=tmp_path / "cache")
    assert checked.returncode == 0, checked.stdout + checked.stderr
    (tmp_path / "mistakes.py").write_text(USER_SCRIPT + "\n".join(MISTAKES) + "\n")
    checked = _mypy("mistakes.py", cwd=tmp_path, cache=tmp_path / "cache")
    assert checked.returncode == 1
    first = USER_SCRIPT.count("\n") + 1
    errors = dict(re.findall(r"^mistakes\.py:(\d+): error: (.*)$", checked.stdout, re.MULTILINE))
    assert sorted(map(int, errors)) == list(range(first, first + len(MISTAKES))), checked.stdout  # each, and only
    for (line, message), error in zip(MISTAKES.items(), errors.values()):
        assert message in error, (line, checked.stdout)


@pytest.mark.slow
def test_the_package_type_checks(tmp_path):
    """mypy on the package as pyproject.toml's [tool.mypy] scopes it (its ``exclude`` lists the
    modules not yet clean)."""
    checked = _mypy(cwd=ROOT, cache=tmp_path / "cache")
    assert checked.returncode == 0, checked.stdout + checked.stderr


def _skip_if_unreachable(run: subprocess.CompletedProcess, what: str) -> None:
    output = run.stdout + run.stderr
    if run.returncode and (match := _UNREACHABLE.search(output)):
        line = next(line for line in output.splitlines() if match.group(0) in line)
        pytest.skip(f"{what} needs the package registry, unreachable here (pip: {line.strip()})")
    assert run.returncode == 0, output[-4000:]


@pytest.fixture(scope="module")
def distributions(tmp_path_factory):
    """The sdist and the wheel built from it by ``python -m build`` (isolated: its build requirements
    come from the registry)."""
    pytest.importorskip("build")
    out = tmp_path_factory.mktemp("dist")
    built = subprocess.run([sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)],
                           capture_output=True, text=True)
    _skip_if_unreachable(built, "python -m build")
    (sdist,), (wheel,) = out.glob("*.tar.gz"), out.glob("*.whl")
    return sdist, wheel


@pytest.mark.slow
def test_the_wheel_holds_what_runs_and_nothing_else(distributions):
    sdist, wheel = distributions
    names = zipfile.ZipFile(wheel).namelist()
    shipped = {name for name in names if name.startswith("kronlag/")}
    tracked = subprocess.run(["git", "ls-files", "src/kronlag"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.split()
    sources = {path.removeprefix("src/") for path in tracked}
    assert sources <= shipped  # every module, C source the kernels and drivers compile, model file, stub, py.typed
    assert {"kronlag/py.typed", "kronlag/numeric/codegen/c/linalg.c", "kronlag/simulation/c/cvode.c",
            "kronlag/model/builtin/files/four_bar.toml", "kronlag/models.pyi"} <= shipped
    extension = [name for name in shipped - sources if re.fullmatch(r"kronlag/numeric/codegen/_call\..*\.(so|pyd)", name)]
    assert shipped - sources == set(extension)  # the compiled call layer only, nothing left over from a build
    assert all(name.startswith(("kronlag/", "kronlag-")) for name in names)
    assert not [name for name in names if "__pycache__" in name or name.endswith(".pyc") or "/tests/" in name
                or name.startswith("tests/")]
    with tarfile.open(sdist) as archive:
        members = {member.name.split("/", 1)[1] for member in archive.getmembers() if "/" in member.name}
    assert {"pyproject.toml", "setup.py", "README.md", "src/kronlag/simulation/c/index3.c",
            "src/kronlag/numeric/codegen/_call.c"} <= members


def _readme_commands() -> list[list[str]]:
    """The ``kronlag`` commands of the README's first command line (after its install)."""
    first = re.search(r"```bash\n(.*)\n", (ROOT / "README.md").read_text()).group(1)
    commands = [shlex.split(part) for part in first.split("&&")]
    return [command for command in commands if Path(command[0]).name == "kronlag"]


@pytest.mark.slow
def test_the_wheel_runs_the_readme_command_in_a_fresh_environment(distributions, tmp_path):
    _, wheel = distributions
    commands = _readme_commands()
    assert [command[1] for command in commands] == ["derive", "simulate"]
    environment = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(environment)], check=True)
    python, kronlag = environment / "bin" / "python", environment / "bin" / "kronlag"
    clean = {key: value for key, value in os.environ.items()
             if key not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PIP_NO_CACHE_DIR")}
    installed = subprocess.run([str(python), "-m", "pip", "install", "--quiet", str(wheel)], capture_output=True,
                               text=True, env=clean)
    _skip_if_unreachable(installed, "installing the wheel's dependencies")
    work = tmp_path / "work"  # not the repository: the installed wheel is what runs
    work.mkdir()
    run_env = {**clean, "KRONLAG_CACHE": str(tmp_path / "cache")}
    where = subprocess.run([str(python), "-c", "import kronlag; print(kronlag.__file__)"], cwd=work,
                           capture_output=True, text=True, env=run_env, check=True).stdout
    assert Path(where.strip()).is_relative_to(environment)
    for command in commands:
        done = subprocess.run([str(kronlag), *command[1:]], cwd=work, capture_output=True, text=True, env=run_env)
        assert done.returncode == 0, f"{shlex.join(command)}:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    from PIL import Image

    with Image.open(work / "out" / "four_bar.png") as figure:
        assert figure.size[0] > 500 and len(figure.getcolors(1 << 24)) > 10  # a figure drawn, not blank
    with Image.open(work / "out" / "four_bar.gif") as animation:
        assert animation.n_frames > 10
