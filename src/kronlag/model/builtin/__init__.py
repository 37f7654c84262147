"""The built-in models: one place that feeds tests, docs, examples and the CLI.

Every function returns a fresh :class:`kronlag.System` whose symbols carry the
names given in its docstring, so scripts can rely on them.
The Python builders are in :mod:`.planar`, :mod:`.spatial` and :mod:`.arms`; the model files in
``files/`` give their parameter values, initial states and run settings (and a few models of
their own), read by :func:`load_example`.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources
from pathlib import Path

from ...core.errors import InputError, ModelError
from ..modelfile import ModelFile, load_model
from ..modelfile.model_file import settle_drives
from ..modelfile.reader import ROBOT_SUFFIXES
from ..system import System
from .arms import panda, ur5
from .planar import (
    andrews_squeezer,
    chaplygin_sleigh,
    closed_chain,
    double_pendulum,
    five_bar,
    four_bar,
    n_four_bar,
    pendulum_cartesian,
    quick_return,
    slider_crank,
    slider_crank_engine,
)
from .spatial import bricard, flyball_governor, heavy_top

__all__ = [
    "four_bar",
    "quick_return",
    "closed_chain",
    "double_pendulum",
    "slider_crank",
    "slider_crank_engine",
    "five_bar",
    "heavy_top",
    "chaplygin_sleigh",
    "pendulum_cartesian",
    "n_four_bar",
    "andrews_squeezer",
    "bricard",
    "flyball_governor",
    "ur5",
    "panda",
    "BUILTIN_MODELS",
    "IFTOMM",
    "example_names",
    "example_path",
    "load_example",
    "resolve_model",
]

#: The folder of the shipped model files.
_FILES = "files"

#: Built-in models by name (the CLI and model files use these names).
BUILTIN_MODELS: dict[str, Callable[[], System]] = {
    "four_bar": four_bar,
    "quick_return": quick_return,
    "double_pendulum": double_pendulum,
    "slider_crank": slider_crank,
    "slider_crank_engine": slider_crank_engine,
    "five_bar": five_bar,
    "heavy_top": heavy_top,
    "chaplygin_sleigh": chaplygin_sleigh,
    "pendulum_cartesian": pendulum_cartesian,
    "n_four_bar": n_four_bar,
    "andrews_squeezer": andrews_squeezer,
    "bricard": bricard,
    "flyball_governor": flyball_governor,
    "ur5": ur5,
    "panda": panda,
}

#: The IFToMM benchmark problems A01-A05 (references in :mod:`kronlag.benchmarks.iftomm`).
IFTOMM: dict[str, Callable[..., System]] = {
    "A01": pendulum_cartesian,
    "A02": n_four_bar,
    "A03": andrews_squeezer,
    "A04": bricard,
    "A05": flyball_governor,
}


def example_names() -> list[str]:
    """Names of the example model files shipped with kronlag."""
    folder = resources.files(__package__) / _FILES
    return sorted(item.name.removesuffix(".toml") for item in folder.iterdir() if item.name.endswith(".toml"))


def example_path(name: str) -> Path:
    """The path of the shipped example file ``name`` (``"four_bar"`` -> ``.../builtin/files/four_bar.toml``)."""
    if name not in example_names():
        raise ModelError(f"no example model named {name!r}; examples are {', '.join(example_names())}")
    return Path(str(resources.files(__package__) / _FILES / f"{name}.toml"))


def load_example(name: str, *, apply_drives: bool | None = None) -> ModelFile:
    """A shipped example; for a built-in model (:data:`BUILTIN_MODELS`) its system
    is the Python model's and the file supplies the numbers.  ``apply_drives``: the
    file's ``[[drives]]`` as :func:`~kronlag.model.modelfile.load_model` treats them."""
    model = load_model(example_path(name), apply_drives=False)
    if name in BUILTIN_MODELS:
        model.system = BUILTIN_MODELS[name]()
    return settle_drives(model, apply_drives)


def resolve_model(model: str | Path, *, coordinates: str = "joint", floating_base: bool = False) -> ModelFile:
    """A model given as a path to a TOML file or robot file or as the name of a built-in model or
    example, its ``[[drives]]`` left out of the system (the command line applies them where it uses
    them); ``coordinates`` and ``floating_base`` as :func:`~kronlag.model.modelfile.load_model` takes them."""
    path = Path(model)
    if path.suffix in (".toml", *ROBOT_SUFFIXES) or path.exists():
        return load_model(path, apply_drives=False, coordinates=coordinates, floating_base=floating_base)
    if coordinates != "joint" or floating_base:
        raise InputError(f"{model}: --coordinates and --floating-base apply to robot files "
                         f"({', '.join(ROBOT_SUFFIXES)}), not to a built-in model")
    return load_example(str(model), apply_drives=False)
