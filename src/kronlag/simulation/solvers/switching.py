"""The switching method: CVODE away from singular configurations, ALI3-P through them (the default)."""

from __future__ import annotations

from dataclasses import replace


from ...numeric.tolerances import matrix_rank
from ..drivers import Segment, require, segment_status, solution_of
from ..problem import MultibodyProblem, Solution, Solver
from .ali3p import Index3Solver, index3_segment
from .compiled import CompiledSolver, cvode_segment

__all__ = ["SwitchingSolver"]


class SwitchingSolver(Solver):
    """CVODE (:class:`CompiledSolver`) away from singular configurations, ALI3-P
    (:class:`Index3Solver`) through them; the default.

    The fast high-order method integrates while ``Phi_q`` is well conditioned; at
    the approach to a singular configuration (:data:`kronlag.tolerances.APPROACH_RTOL`)
    the index-3 method takes over from the projected state and passes it on the
    branch the motion is on; once the motion is clear of it
    (:data:`~kronlag.tolerances.LEAVE_RTOL`) CVODE continues.  ``Phi_q`` rank deficient
    at the start (redundant constraints, or a start at a singular configuration) starts
    with ALI3-P, which hands over as soon as its watch allows; CVODE counts the rank at its
    own start as the independent rows and stops, as at an approach, should a further row
    become clearly independent.  Smooth problems cost what :class:`CompiledSolver` costs.
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
        # rank deficient at the start: redundant rows or a singular configuration, which one a single
        # state cannot tell; ALI3-P starts either way and hands over once its watch allows
        deficient = model.r and matrix_rank(model.Phi_q(problem.q0, problem.t0), model.rank_rtol) < model.r
        segments: list[Segment] = []
        t, y, index3 = problem.t0, problem.y0, bool(deficient)
        while True:
            steps_left = options.max_steps - sum(segment.steps for segment in segments)
            budget = replace(options, max_steps=max(steps_left, 0))
            if index3:
                segment = index3_segment(problem, budget, t, y, handback=True)
            else:
                segment = cvode_segment(problem, budget, t, y)
            segments.append(segment.without_first_row() if segments and problem.t_eval is None else segment)
            if not segment.hands_over:
                return solution_of(segments, *segment_status(segment, model, "index3" if index3 else "cvode"))
            t, y, index3 = segment.t_end, segment.y_end, not index3
