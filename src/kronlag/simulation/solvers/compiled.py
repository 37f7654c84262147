"""The compiled method: the Baumgarte ODE integrated by SUNDIALS CVODE in C, outputs projected."""

from __future__ import annotations

import ctypes
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...numeric import codegen
from ..drivers import (
    _MAX_EVENTS,
    _PROGRESS,
    Segment,
    driver,
    output_rows,
    passage,
    require,
    segment_status,
    solution_of,
)
from ..problem import MultibodyProblem, Solution, Solver, SolverOptions
from ..stepping import ApproachWatch

if TYPE_CHECKING:
    from ...numeric.numeric_model import NumericModel

__all__ = ["CompiledSolver", "cvode_segment"]


class CompiledSolver(Solver):
    """The Baumgarte index-1 ODE integrated entirely in compiled code, outputs projected.

    The model's C source (``model.c_source``) and a small SUNDIALS driver
    (``src/kronlag/c/cvode.c``) are compiled once per model into a shared library
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
    TOLERANCE_SCALE``; then its error (2.3e-6) is below that of the DOP853
    methods at the requested tolerance, and the drift of the unprojected state
    stays below 1e-9 (3e-10) with the default ``alpha = beta = 10``.
    """

    name = "compiled"
    formulation = "index-1 ODE with Baumgarte stabilization, compiled; outputs projected"
    stabilization = 10.0
    order = "1-12 (variable-order Adams-Moulton, SUNDIALS CVODE)"
    requirements = "the C backend, constant parameters and a C compiler"
    #: CVODE's tolerances are the requested ones divided by this (see above).
    TOLERANCE_SCALE = 100.0

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """Whether ``model`` can run compiled: C backend, no time-varying parameter."""
        return model.backend == "c" and not model.time_varying and codegen.c_compiler() is not None

    def solve(self, problem: MultibodyProblem) -> Solution:
        require(self, problem.model)
        segment = cvode_segment(problem, self.options, problem.t0, problem.y0)
        if segment.flag == 2:  # the approach is an event too
            approach = ApproachWatch(problem).observe(segment.t_end, segment.y_end)
            segment = replace(segment, events=segment.events + ((approach,) if approach else ()))
        return solution_of([segment], *segment_status(segment, problem.model, "cvode"))


def cvode_segment(problem: MultibodyProblem, options: SolverOptions, t0: float, y0: np.ndarray) -> Segment:
    """CVODE (Adams) on the Baumgarte ODE from ``(t0, y0)`` until ``t1`` or the approach to a
    singular configuration (``flag`` 2)."""
    model = problem.model
    library = driver(model, "cvode")
    times, rows = output_rows(problem, t0, options)
    t_out, y_out = np.empty(rows), np.empty((rows, 2 * problem.m))
    written, event_count, t_end = ctypes.c_int(0), ctypes.c_int(0), ctypes.c_double(t0)
    stats, events, y_end = np.zeros(4, dtype=np.int64), np.empty((_MAX_EVENTS, 5 + model.m)), np.empty(2 * model.m)
    p, y0 = model.parameter_vector(t0), np.ascontiguousarray(y0, dtype=float)
    callback = _PROGRESS(options.progress) if options.progress is not None else _PROGRESS()
    flag = library.kronlag_cvode(
        p.ctypes.data, t0, problem.t1, y0.ctypes.data, len(times), times.ctypes.data,
        options.rtol / CompiledSolver.TOLERANCE_SCALE, options.atol / CompiledSolver.TOLERANCE_SCALE, problem.alpha,
        problem.beta, options.max_step if np.isfinite(options.max_step) else 0.0, options.max_steps, len(t_out),
        t_out.ctypes.data, y_out.ctypes.data, ctypes.byref(written), stats.ctypes.data, events.ctypes.data,
        _MAX_EVENTS, ctypes.byref(event_count), ctypes.byref(t_end), y_end.ctypes.data, callback)
    n = written.value
    t_out, y_out = t_out[:n].copy(), y_out[:n].copy()
    derived = {"qdd": np.empty((n, model.m)), "lam": np.empty((n, model.r)), "mu": np.empty((n, model.s)),
               "kinetic_energy": np.empty(n), "potential_energy": np.empty(n),
               "position_residual": np.empty((n, model.r)), "velocity_residual": np.empty((n, model.r + model.s))}
    library.kronlag_outputs(p.ctypes.data, n, t_out.ctypes.data, y_out.ctypes.data,
                            *(derived[key].ctypes.data for key in derived))
    passages = tuple(passage(model, record) for record in events[:min(event_count.value, _MAX_EVENTS)])
    return Segment(t=t_out, y=y_out, derived=derived, events=passages, flag=flag, t_end=t_end.value, y_end=y_end,
                    steps=int(stats[0]), nfev=int(stats[1]), njev=int(stats[2]))
