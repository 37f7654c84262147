"""The architecture holds: layers import one way, no import circles, small modules that say what they
hold, the old module paths kept, the packaging habits (docs/architecture.md)."""

from __future__ import annotations

import ast
import importlib
import importlib.metadata
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import kronlag
from kronlag._legacy import MOVED

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "kronlag"
#: The layers from the bottom up, as in pyproject.toml and docs/architecture.md.
LAYERS = ("core", "model", "symbolic", "numeric", "simulation", "studies", "views", "app")
#: "Modules of one concept, at most about 600 lines each".
MAX_LINES = 600


def lint_imports(config: Path, *, cwd: Path, path: Path | None = None) -> subprocess.CompletedProcess:
    """import-linter's contracts of ``config``, run as a user would (``lint-imports``)."""
    environment = None if path is None else {"PYTHONPATH": str(path), "PATH": str(Path(sys.executable).parent)}
    command = [sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
               "sys.exit(lint_imports_command())", "--config", str(config), "--no-cache"]
    return subprocess.run(command, cwd=cwd, env=environment, capture_output=True, text=True, timeout=600)


def test_layers_import_one_way_and_no_package_imports_itself_in_a_circle():
    result = lint_imports(ROOT / "pyproject.toml", cwd=ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "2 kept, 0 broken" in result.stdout


def test_the_contract_lists_the_layers_of_the_architecture_page():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (layers,) = [contract["layers"] for contract in config["contracts"] if contract["type"] == "layers"]
    listed = [name.removeprefix("kronlag.") for entry in reversed(layers) for name in entry.split(" | ")]
    assert [name for name in listed if name != "benchmarks"] == list(LAYERS)
    page = (ROOT / "docs" / "architecture.md").read_text()
    assert " -> ".join(LAYERS) in page
    packages = sorted(path.name for path in PACKAGE.iterdir() if (path / "__init__.py").exists())
    assert packages == sorted([*LAYERS, "benchmarks"]), "a subpackage outside the layers of the contract"


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    """A copy of the package under another name (its imports are relative) with the contract renamed:
    a plant in it is checked by the same contract without touching the installed package."""
    base = tmp_path_factory.mktemp("planted")
    copy = base / "kronlag_copy"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so", "files"))
    config = re.sub(r"\bkronlag\b", "kronlag_copy", (ROOT / "pyproject.toml").read_text())
    (base / "pyproject.toml").write_text(config)
    return base


@pytest.mark.parametrize("module, planted_import, contract", [
    ("model/system.py", "from ..app import cli", "Each layer imports only from the layers below it"),
    ("numeric/linalg.py", "from ..simulation import trajectory", "Each layer imports only from the layers below it"),
    ("model/bodies.py", "from . import system", "No import circle between the modules and subpackages"),
])
def test_a_planted_upward_import_or_circle_breaks_a_contract(planted, module, planted_import, contract):
    target = planted / "kronlag_copy" / module
    original = target.read_text()
    result = lint_imports(planted / "pyproject.toml", cwd=planted, path=planted)
    assert result.returncode == 0, result.stdout + result.stderr  # the copy itself is clean
    try:
        target.write_text(original + f"\n{planted_import}  # planted\n")
        result = lint_imports(planted / "pyproject.toml", cwd=planted, path=planted)
    finally:
        target.write_text(original)
    assert result.returncode != 0
    assert f"{contract}" in result.stdout and "BROKEN" in result.stdout, result.stdout


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda path: str(path.relative_to(PACKAGE)))
def test_each_module_is_small_and_opens_with_what_it_holds(path):
    text = path.read_text()
    assert len(text.splitlines()) <= MAX_LINES, f"{path.name}: {len(text.splitlines())} lines"
    docstring = ast.get_docstring(ast.parse(text))
    assert docstring and len(docstring.split()) >= 5, f"{path}: no module docstring saying what it holds"


#: A few names of every old module, each with the module that holds it now.
OLD_NAMES = {
    "kronlag.analysis": {"equilibrium": "kronlag.studies.equilibrium", "linearize": "kronlag.studies.linearization",
                         "EquilibriumError": "kronlag.core.errors", "tangent_matrices": "kronlag.studies.tangent"},
    "kronlag.animation": {"animate": "kronlag.views.animation", "render_frame": "kronlag.views.animation"},
    "kronlag.calculus": {"kron": "kronlag.symbolic.calculus", "time_derivative": "kronlag.symbolic.calculus"},
    "kronlag.cli": {"main": "kronlag.app.cli", "build_parser": "kronlag.app.cli", "ProgressBar": "kronlag.app.commands",
                    "IncompleteRun": "kronlag.app.outputs"},
    "kronlag.cli_analysis": {"add_commands": "kronlag.app.analysis_commands"},
    "kronlag.codegen": {"LAYOUTS": "kronlag.numeric.codegen.layouts", "CLibrary": "kronlag.numeric.codegen.c_backend",
                        "cache_directory": "kronlag.numeric.codegen.build", "CompilerError": "kronlag.core.errors"},
    "kronlag.derivation": {"derive": "kronlag.symbolic.derivation"},
    "kronlag.drives": {"kinematic_analysis": "kronlag.studies.drives", "Kinematics": "kronlag.studies.drives"},
    "kronlag.energy": {"nonconservative_work": "kronlag.simulation.energy"},
    "kronlag.equations": {"Equations": "kronlag.symbolic.equations", "MATRIX_NAMES": "kronlag.symbolic.equations"},
    "kronlag.export": {"export_code": "kronlag.symbolic.export", "format_equations": "kronlag.symbolic.export"},
    "kronlag.expressions": {"parse_expression": "kronlag.model.expressions", "ExpressionError": "kronlag.core.errors"},
    "kronlag.frames": {"Frame": "kronlag.model.frames", "euler_sequence": "kronlag.model.rotations",
                       "point_velocity": "kronlag.symbolic.kinematics", "BodyPoint": "kronlag.model.frames"},
    "kronlag.interop": {"casadi_functions": "kronlag.symbolic.interop", "jax_functions": "kronlag.symbolic.interop"},
    "kronlag.joints": {"add_joint": "kronlag.model.joints", "free_body": "kronlag.model.free_bodies",
                       "mechanism": "kronlag.model.free_bodies", "JOINT_KINDS": "kronlag.model.joints"},
    "kronlag.modelfile": {"load_model": "kronlag.model.modelfile.reader", "to_toml": "kronlag.model.modelfile.writer",
                          "ModelFile": "kronlag.model.modelfile.model_file", "load_example": "kronlag.model.builtin",
                          "resolve_model": "kronlag.model.builtin", "ModelFileError": "kronlag.core.errors",
                          "elementary_rotation": "kronlag.model.rotations"},
    "kronlag.models": {"four_bar": "kronlag.model.builtin.planar", "BUILTIN_MODELS": "kronlag.model.builtin"},
    "kronlag.numeric": {"NumericModel": "kronlag.numeric.numeric_model", "solve_augmented": "kronlag.numeric.linalg",
                        "SingularConfigurationError": "kronlag.core.errors"},
    "kronlag.plotting": {"plot_trajectory": "kronlag.views.plotting"},
    "kronlag.reactions": {"joint_reaction": "kronlag.numeric.reactions", "Reaction": "kronlag.numeric.reactions",
                          "plot_reactions": "kronlag.views.plotting"},
    "kronlag.simulation": {"simulate": "kronlag.simulation.simulate", "METHODS": "kronlag.simulation.solvers",
                           "InitialStateWarning": "kronlag.core.errors"},
    "kronlag.sweeps": {"sweep": "kronlag.studies.sweeps", "grid": "kronlag.studies.sweeps"},
    "kronlag.system": {"System": "kronlag.model.system", "ModelError": "kronlag.core.errors",
                       "PlanarBody": "kronlag.model.bodies", "RotationSequence": "kronlag.model.rotations",
                       "t": "kronlag.model.symbols", "check_parameter_values": "kronlag.model.bodies"},
    "kronlag.tolerances": {"RANK_RTOL": "kronlag.numeric.tolerances", "numerical_rank": "kronlag.numeric.tolerances"},
    "kronlag.trajectory": {"Trajectory": "kronlag.simulation.trajectory", "Result": "kronlag.simulation.trajectory"},
    "kronlag.workflows": {"simulate_model": "kronlag.app.workflows", "check_model": "kronlag.app.workflows"},
}


def test_every_old_module_path_is_listed():
    assert set(OLD_NAMES) == set(MOVED) | {"kronlag.numeric", "kronlag.simulation"}


@pytest.mark.parametrize("old", sorted(OLD_NAMES))
def test_old_module_paths_give_the_same_objects(old):
    module = importlib.import_module(old)
    for name, home in OLD_NAMES[old].items():
        assert getattr(module, name) is getattr(importlib.import_module(home), name), f"{old}.{name}"
    exec(f"from {old} import {', '.join(OLD_NAMES[old])}", {})  # noqa: S102 - our own text


def test_an_old_module_of_one_new_module_is_that_module():
    import kronlag.trajectory
    import kronlag.simulation.trajectory

    assert kronlag.trajectory is kronlag.simulation.trajectory
    with pytest.raises(AttributeError, match="now in"):
        kronlag.system.no_such_name  # noqa: B018


def test_the_command_line_runs_as_a_module():
    result = subprocess.run([sys.executable, "-m", "kronlag", "models"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0 and "four_bar" in result.stdout, result.stderr


def test_version_comes_from_the_package_metadata_only():
    assert kronlag.__version__ == importlib.metadata.version("kronlag")
    sources = [path for path in _modules() if re.search(r"\b0\.1\.0\b|__version__ = \"\d", path.read_text())]
    assert not sources, sources


def test_the_package_is_typed_for_users():
    assert (PACKAGE / "py.typed").is_file()
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["kronlag"]
    assert "py.typed" in data


@pytest.mark.parametrize("name", ["derive", "Equations"])
def test_the_paper_is_referenced(name):
    assert "10.1016/j.mechrescom.2011.04.004" in getattr(kronlag, name).__doc__
    assert "References" in getattr(kronlag, name).__doc__


def test_the_calculus_module_references_the_paper():
    assert "10.1016/j.mechrescom.2011.04.004" in kronlag.calculus.__doc__
