"""The compiled method: the Baumgarte ODE integrated by SUNDIALS CVODE in C, outputs projected."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...numeric import codegen
from ...numeric.tolerances import CVODE_TIGHTEST
from ..drivers import Segment, has_driver, require, run, segment_status, solution_of
from ..problem import MultibodyProblem, Solution, Solver, SolverOptions
from ..stepping import ApproachWatch, approach_scales
from ..trajectory import Result

if TYPE_CHECKING:
    from ...numeric.numeric_model import NumericModel

__all__ = ["CompiledSolver", "compiled_solution", "cvode_segment"]

#: Exact stiction: the rows of directions a segment's driver may turn itself (a row per joint and instant);
#: past them, every event ends the segment (Python decides it).
_MAX_TURNS = 1000


class CompiledSolver(Solver):
    """The Baumgarte index-1 ODE integrated entirely in compiled code, outputs projected.

    The model's C source (``model.c_source``) and a small SUNDIALS driver
    (``src/kronlag/simulation/c/cvode.c``) are compiled once per model into a shared library
    (cached by hash) that calls the CVODE libraries of scikit-sundae.  CVODE
    (variable-order Adams-Moulton, Newton iteration with a dense
    difference-quotient Jacobian) integrates the Baumgarte-stabilized
    ``y = [q, qd]``, ``y' = [qd, qdd]`` of :class:`BaumgarteSolver`; every
    output is projected onto the constraints (least-norm corrections over the
    independent rows, :mod:`kronlag.tolerances`).  Python is called only at the
    start and the end (and for ``progress``); the accelerations, multipliers,
    energies and residuals at the outputs are computed in C too.  Needs the C
    backend and constant parameters.

    At the approach to a singular configuration (:data:`kronlag.tolerances.APPROACH_RTOL`)
    an index-1 formulation cannot tell the branches of the motion apart (IFToMM A02): the
    integration ends there with status -1 and a message naming the configuration;
    :class:`SwitchingSolver` (the default) passes it with ALI3-P.

    CVODE bounds a weighted RMS norm of the local error of a multistep method,
    and its global error at a given ``rtol`` is far larger than DOP853's
    (four-bar, 10 s, rtol 1e-8: 1.4e-4 against 4.7e-6 in q).  CVODE is
    therefore called with ``rtol / TOLERANCE_SCALE`` and ``atol /
    TOLERANCE_SCALE``, neither below :data:`~kronlag.numeric.tolerances.CVODE_TIGHTEST`
    (and the outputs projected to the ``projection_tol`` of these).  The scale was
    measured on IFToMM A02, whose motion passes close to an unstable equilibrium that
    amplifies velocity errors about 30 times per pass: with 1e4 the error of B0 stays
    below 10 ``rtol`` + 1e-5 m from rtol 1e-4 to 1e-10 (with 100 it was 3e-3 m at
    rtol 1e-4); the drift of the unprojected state stays below 1e-9 with the default
    ``alpha = beta = 10``.
    """

    name = "compiled"
    formulation = "index-1 ODE with Baumgarte stabilization, compiled; outputs projected"
    stabilization = 10.0
    integrator = "variable-order Adams-Moulton, SUNDIALS CVODE"
    order = 12
    min_order = 1
    requirements = "the C backend, constant parameters and a C compiler"
    samples_inside = True
    #: CVODE's tolerances are the requested ones divided by this (see above).
    TOLERANCE_SCALE = 1e4

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """Whether ``model`` can run compiled: C backend, no time-varying parameter."""
        return model.backend == "c" and not model.time_varying and (has_driver(model)
                                                                      or codegen.c_compiler() is not None)

    def solve(self, problem: MultibodyProblem) -> Solution:
        require(self, problem.model)
        return compiled_solution(problem, cvode_segment(problem, self.options, problem.t0, problem.y0, turns=True),
                                 "cvode")


def compiled_solution(problem: MultibodyProblem, segment: Segment, kind: str) -> Solution:
    """The :class:`Solution` of one run of the driver ``kind`` over the whole span; an approach to a
    singular configuration, where the run ended, is an event too."""
    if segment.flag == Result.APPROACH.code:
        approach = ApproachWatch(problem).observe(segment.t_end, segment.y_end)
        segment = replace(segment, events=segment.events + ((approach,) if approach else ()))
    return solution_of([segment], *segment_status(segment, problem.model, kind))


def cvode_segment(problem: MultibodyProblem, options: SolverOptions, t0: float, y0: np.ndarray, *,
                  turns: bool = False) -> Segment:
    """CVODE (Adams) on the Baumgarte ODE from ``(t0, y0)`` until ``t1`` or the approach to a
    singular configuration (:attr:`Result.APPROACH`); ``turns``: exact stiction's directions may be turned
    inside the run where the watch allows (:attr:`~..watch.LimitWatch.at_rest`; the caller passes the
    segment's ``turns`` on in its solution)."""
    watch = problem.watch
    if turns and watch is not None and watch.friction and watch.at_rest > 0:
        extra = {"max_turns": _MAX_TURNS, "at_rest": watch.at_rest}
    else:
        extra = {}
    scaled = options.scaled(CompiledSolver.TOLERANCE_SCALE, CVODE_TIGHTEST)
    # the outputs' projection no tighter than the floor either: |Phi| cannot be made smaller than rounding
    return run("cvode", problem, scaled, t0, y0, projection_tol=max(scaled.projection_tol, CVODE_TIGHTEST[1]),
               alpha=problem.alpha, beta=problem.beta, row_scale=approach_scales(problem), **extra)
