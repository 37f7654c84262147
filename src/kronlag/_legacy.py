"""The module paths of kronlag before its layers (``kronlag.numeric`` ... ``kronlag.workflows``), kept working.

Users' scripts import ``kronlag.trajectory.Trajectory``, ``kronlag.codegen.cache_directory`` or
``from kronlag.system import ModelError``.  Since those names moved into the layers
(``kronlag.simulation.trajectory``, ``kronlag.numeric.codegen``, ``kronlag.core.errors``, ...),
:data:`MOVED` maps every old module to the modules that hold its names now, and an import hook
(:class:`_LegacyFinder`, installed by ``kronlag/__init__.py``) answers ``import kronlag.<old>``:

* an old module whose names all live in one new module *is* that module (the same object, so
  that ``monkeypatch.setattr`` and identity checks keep working);
* an old module split over several new ones is a read-only view that looks a name up in each,
  in order, on first access (nothing is imported before it is used).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
from collections.abc import Sequence

__all__ = ["MOVED", "install"]

#: Old module -> the modules that hold its names now, searched in this order.
MOVED: dict[str, tuple[str, ...]] = {
    "kronlag.analysis": ("kronlag.studies.equilibrium", "kronlag.studies.linearization"),
    "kronlag.animation": ("kronlag.views.animation",),
    "kronlag.calculus": ("kronlag.symbolic.calculus",),
    "kronlag.cli": ("kronlag.app.cli", "kronlag.app.commands", "kronlag.app.outputs"),
    "kronlag.cli_analysis": ("kronlag.app.analysis_commands",),
    "kronlag.codegen": ("kronlag.numeric.codegen",),
    "kronlag.derivation": ("kronlag.symbolic.derivation",),
    "kronlag.drives": ("kronlag.studies.drives",),
    "kronlag.energy": ("kronlag.simulation.energy",),
    "kronlag.equations": ("kronlag.symbolic.equations",),
    "kronlag.export": ("kronlag.symbolic.export",),
    "kronlag.expressions": ("kronlag.model.expressions",),
    "kronlag.frames": ("kronlag.model.frames", "kronlag.model.rotations", "kronlag.symbolic.kinematics"),
    "kronlag.interop": ("kronlag.symbolic.interop",),
    "kronlag.joints": ("kronlag.model.joints", "kronlag.model.free_bodies"),
    "kronlag.modelfile": ("kronlag.model.modelfile", "kronlag.model.builtin", "kronlag.model.rotations"),
    "kronlag.models": ("kronlag.model.builtin",),
    "kronlag.plotting": ("kronlag.views.plotting",),
    "kronlag.reactions": ("kronlag.numeric.reactions", "kronlag.views.plotting"),
    "kronlag.sweeps": ("kronlag.studies.sweeps",),
    "kronlag.system": ("kronlag.model.system", "kronlag.model.bodies", "kronlag.model.symbols",
                       "kronlag.model.rotations", "kronlag.model.loads", "kronlag.core.errors"),
    "kronlag.tolerances": ("kronlag.numeric.tolerances",),
    "kronlag.trajectory": ("kronlag.simulation.trajectory",),
    "kronlag.workflows": ("kronlag.app.workflows",),
}


class _Combined(types.ModuleType):
    """An old module whose names now live in several modules: each name is looked up on first use."""

    def __init__(self, name: str, sources: Sequence[str]):
        super().__init__(name, f"The names of the former module {name}, now in {', '.join(sources)}.")
        self._sources = tuple(sources)

    def __getattr__(self, attribute: str):
        if attribute.startswith("__"):
            raise AttributeError(attribute)
        for source in self._sources:
            module = importlib.import_module(source)
            if hasattr(module, attribute):
                return getattr(module, attribute)
        raise AttributeError(f"module {self.__name__!r} has no attribute {attribute!r} (its names are now in "
                             f"{', '.join(self._sources)})")

    def __dir__(self) -> list[str]:
        names = set(super().__dir__())
        for source in self._sources:
            names.update(getattr(importlib.import_module(source), "__all__", ()))
        return sorted(names)


class _LegacyLoader(importlib.abc.Loader):
    def __init__(self, sources: Sequence[str]):
        self.sources = tuple(sources)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        return _Combined(spec.name, self.sources)

    def exec_module(self, module: types.ModuleType) -> None:
        if len(self.sources) == 1:
            # the import machinery returns whatever sys.modules holds after exec_module: the module itself
            sys.modules[module.__name__] = importlib.import_module(self.sources[0])


class _LegacyFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname: str, path=None, target=None) -> importlib.machinery.ModuleSpec | None:
        sources = MOVED.get(fullname)
        if sources is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _LegacyLoader(sources))


def install() -> None:
    """Answer imports of the old module paths (once per process)."""
    if not any(isinstance(finder, _LegacyFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, _LegacyFinder())
