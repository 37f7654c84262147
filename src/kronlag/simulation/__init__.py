"""Time integration of the equations of motion (the differential-algebraic equations)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    Phi(q) = 0,   A(q) qd + b(q) = 0

The layout follows ``scipy.integrate`` and diffrax: a :class:`MultibodyProblem`
(:mod:`.problem`: the model, the time span, the initial state), a solver class per
method (:mod:`.solvers`, one a module; each declares its formulation and order) and a
:class:`Solution` of raw states are separate types joined by one driver,
:func:`simulate` (:mod:`.simulate`), which also recomputes the accelerations,
multipliers, energies and constraint residuals at the output times and returns a
:class:`~kronlag.simulation.trajectory.Trajectory`.  The Python-driven methods share
one stepping loop (:mod:`.stepping`); the compiled ones share the drivers of
:mod:`.drivers` (C in ``simulation/c/``; the options struct they take and the codes they return
are declared once, in :mod:`.interface`, and printed as C).  A solver's ``order`` is a number
(:class:`Solver`), checked against closed-form solutions by ``tests/test_solver_order.py``.
"""

from ..core.errors import InitialStateWarning, ProjectionError
from .problem import MultibodyProblem, Solution, Solver, SolverOptions
from .simulate import simulate
from .solvers import (
    AUTO_PREFERENCE,
    METHODS,
    BaumgarteSolver,
    CompiledSolver,
    GGLSolver,
    Index3Solver,
    ProjectionSolver,
    SwitchingSolver,
)
from .trajectory import MethodInterval, Result, SingularPassage, Trajectory

__all__ = [
    "simulate",
    "METHODS",
    "ProjectionError",
    "MultibodyProblem",
    "Solution",
    "SolverOptions",
    "Solver",
    "BaumgarteSolver",
    "ProjectionSolver",
    "GGLSolver",
    "CompiledSolver",
    "Index3Solver",
    "SwitchingSolver",
    "InitialStateWarning",
    "Result",
    "SingularPassage",
    "MethodInterval",
    "Trajectory",
    "AUTO_PREFERENCE",
]
