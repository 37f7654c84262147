"""The switching method: CVODE away from singular configurations, ALI3-P through them (the default)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...numeric.projection import project_positions
from ...numeric.tolerances import REDUNDANCY_PROBE, REDUNDANCY_PROBE_RESIDUAL, matrix_rank
from ..drivers import Segment, require, segment_status, solution_of
from ..problem import MultibodyProblem, Solution, Solver
from ..trajectory import MethodInterval
from .ali3p import Index3Solver, index3_segment
from .compiled import CompiledSolver, cvode_segment

if TYPE_CHECKING:
    from ...numeric.numeric_model import NumericModel

__all__ = ["SwitchingSolver", "redundant_at"]


#: Why a segment of each integrator began after the other one's (:attr:`MethodInterval.reason`).
_HANDED_OVER = {True: "the approach to a singular configuration (where the rank of Phi_q changes)",
                False: "the motion clear of the singular configuration"}


def redundant_at(model: NumericModel, q: np.ndarray, t: float) -> bool:
    """Whether ``Phi_q`` is rank deficient at the configuration ``q`` because of redundant constraints:
    deficient there and of the same rank at the configurations on the constraints
    :data:`~kronlag.numeric.tolerances.REDUNDANCY_PROBE` (times ``1 + max |q|``) away along two fixed
    combinations of its null space, both ways.  False at a singular configuration (the rank rises
    nearby) and where ``Phi_q`` has full rank."""
    Phi_q = model.Phi_q(q, t)
    rank = matrix_rank(Phi_q, model.rank_rtol)
    if rank == model.r:
        return False
    _, singular_values, Vt = np.linalg.svd(Phi_q)
    null_space = Vt[rank:].T
    if not null_space.size:  # every coordinate held: nothing can move, the rank cannot change
        return True
    distance = REDUNDANCY_PROBE * (1.0 + np.max(np.abs(q)))
    tol = REDUNDANCY_PROBE_RESIDUAL * model.rank_rtol * singular_values[0]
    weights = np.random.default_rng(0).standard_normal((null_space.shape[1], 2))  # generic, reproducible
    for direction in (null_space @ weights).T:
        for sign in (1.0, -1.0):
            probe = project_positions(model, q + sign * distance * direction / np.linalg.norm(direction), t, tol=tol)
            if not probe.accepted(tol) or matrix_rank(probe.terms["Phi_q"], model.rank_rtol) != rank:
                return False
    return True


class SwitchingSolver(Solver):
    """CVODE (:class:`CompiledSolver`) away from singular configurations, ALI3-P
    (:class:`Index3Solver`) through them; the default.

    The fast high-order method integrates while ``Phi_q`` is well conditioned; at
    the approach to a singular configuration (:data:`kronlag.tolerances.APPROACH_RTOL`)
    the index-3 method takes over from the projected state and passes it on the
    branch the motion is on; once the motion is clear of it
    (:data:`~kronlag.tolerances.LEAVE_RTOL`) CVODE continues.  ``Phi_q`` rank deficient
    at the start: redundant constraints when the rank is the same nearby on the constraints
    (:func:`redundant_at`), and CVODE starts, counting the rank at the start as the independent
    rows (the accelerations are unique, the multipliers the minimum-norm ones: a
    :class:`~kronlag.RedundantConstraintsWarning` says so); else the start is a singular
    configuration, and ALI3-P starts and hands over as soon as its watch allows.  CVODE stops,
    as at an approach, should a further row become clearly independent.  Which integrator ran
    where, and why, is in :attr:`Solution.intervals` (``Trajectory.intervals``).  Smooth problems
    cost what :class:`CompiledSolver` costs.
    """

    name = "switching"
    formulation = "CVODE on the Baumgarte ODE; ALI3-P near singular configurations (both compiled)"
    integrator = (f"{CompiledSolver.integrator} away from singular configurations, {Index3Solver.integrator} "
                  "near them")
    #: CVODE's orders, which include ALI3-P's 2; ``SolverOptions.max_order`` caps CVODE's.
    order, min_order = CompiledSolver.order, CompiledSolver.min_order
    requirements = Index3Solver.requirements
    supports = staticmethod(Index3Solver.supports)
    stabilization = CompiledSolver.stabilization
    samples_inside = True

    def solve(self, problem: MultibodyProblem) -> Solution:
        require(self, problem.model)
        model, options = problem.model, self.options
        index3, reason = _first_integrator(problem)
        segments: list[Segment] = []
        intervals: list[MethodInterval] = []
        t, y = problem.t0, problem.y0
        while True:
            steps_left = options.max_steps - sum(segment.steps for segment in segments)
            budget = replace(options, max_steps=max(steps_left, 0))
            if index3:
                segment = index3_segment(problem, budget, t, y, handback=True)
            else:
                segment = cvode_segment(problem, budget, t, y)
            method = Index3Solver.name if index3 else CompiledSolver.name
            intervals.append(MethodInterval(method, t, float(segment.t_end), segment.steps, reason))
            segments.append(segment.without_first_row() if segments and problem.t_eval is None else segment)
            if not segment.hands_over:
                solution = solution_of(segments, *segment_status(segment, model, "index3" if index3 else "cvode"))
                return replace(solution, intervals=tuple(intervals))
            t, y, index3 = segment.t_end, segment.y_end, not index3
            reason = _HANDED_OVER[index3]


def _first_integrator(problem: MultibodyProblem) -> tuple[bool, str]:
    """Whether ALI3-P starts (else CVODE), and why."""
    model, q0, t0 = problem.model, problem.q0, problem.t0
    rank = matrix_rank(model.Phi_q(q0, t0), model.rank_rtol) if model.r else 0
    if rank == model.r:
        return False, "Phi_q of full rank at the start"
    if redundant_at(model, q0, t0):
        model.forward_dynamics(q0, problem.qd0, t0)  # its RedundantConstraintsWarning, once per model
        return False, (f"redundant constraints (Phi_q of rank {rank} < {model.r} on the constraints): "
                       "the multipliers are the minimum-norm ones")
    return True, f"a singular configuration at the start (Phi_q of rank {rank} < {model.r}, higher nearby)"
