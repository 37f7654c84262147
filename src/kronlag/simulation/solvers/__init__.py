"""The integration methods, one a module, each a :class:`~kronlag.simulation.problem.Solver` subclass
that declares its formulation and order; :data:`METHODS` names them for ``simulate(method=...)``."""

from __future__ import annotations

from ..problem import Solver
from .ali3p import Index3Solver
from .baumgarte import BaumgarteSolver
from .compiled import CompiledSolver
from .compiled_dop853 import CompiledDOP853Solver
from .ggl import GGLSolver
from .projection import ProjectionSolver
from .switching import SwitchingSolver

__all__ = ["METHODS", "AUTO_PREFERENCE", "SAMPLED_PREFERENCE", "BaumgarteSolver", "ProjectionSolver", "GGLSolver", "CompiledSolver", "CompiledDOP853Solver",
           "Index3Solver", "SwitchingSolver"]


#: Methods by name (``"auto"`` picks among them in :func:`simulate`).
METHODS: dict[str, type[Solver]] = {
    BaumgarteSolver.name: BaumgarteSolver,
    ProjectionSolver.name: ProjectionSolver,
    GGLSolver.name: GGLSolver,
    CompiledSolver.name: CompiledSolver,
    CompiledDOP853Solver.name: CompiledDOP853Solver,
    Index3Solver.name: Index3Solver,
    SwitchingSolver.name: SwitchingSolver,
}


#: What ``method="auto"`` picks: the first of these that supports the model.
AUTO_PREFERENCE = (SwitchingSolver.name, CompiledSolver.name, ProjectionSolver.name)

#: What ``method="auto"`` picks under a :class:`~kronlag.simulation.controllers.Sampled` controller: a
#: one-step method first, since the integrator restarts at every sample and CVODE (multistep) restarts at
#: order 1 with its smallest steps (cart-pole at 1 kHz, rtol 1e-8: 8 CVODE steps and 29 evaluations per
#: sample against 1.3 ALI3-P steps; bench/bench_controllers.py).
SAMPLED_PREFERENCE = (Index3Solver.name, CompiledSolver.name, ProjectionSolver.name)
