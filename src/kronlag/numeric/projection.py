"""The projection onto the constraint manifold, one algorithm for assembly and for the integrators.

Positions: Gauss-Newton on ``Phi(q, t) = 0`` over the free coordinates, each step the
minimum-norm correction over the independent rows (:func:`~kronlag.numeric.linalg.least_norm`,
the rank policy of :mod:`.tolerances`)::

    Phi_q[:, free] dq = -Phi(q)

halved while ``max |Phi|`` grows, until ``max |Phi| <= tol``, a step at rounding level
(:data:`~kronlag.numeric.tolerances.STALL`) or ``max_iterations`` steps.  Velocities: the least
change of ``qd`` in the free speeds onto ``B qd + c = 0``, ``B = [Phi_q; A]``, ``c = [Phi_t; b]``,
in one step.  Both read the ``"dynamics"`` kernel (:meth:`NumericModel.dynamics_terms`), which is
compiled with the model.  ``kl_project`` in ``simulation/c/cvode.c`` does the same in C with the
limits of :mod:`.tolerances` as macros.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .linalg import least_norm, velocity_constraints
from .tolerances import MAX_PROJECTION_ITERATIONS, STALL

if TYPE_CHECKING:
    from .numeric_model import NumericModel

__all__ = ["PositionProjection", "project_positions", "project_velocities", "MIN_STEP_FACTOR"]

#: A Gauss-Newton step halved below this fraction without reducing ``max |Phi|`` ends the iteration.
MIN_STEP_FACTOR = 1e-6


@dataclass(frozen=True)
class PositionProjection:
    """Where :func:`project_positions` ended.

    Attributes
    ----------
    q : (m,)
    residual : float
        ``max |Phi(q, t)|``.
    iterations : int
    stalled : bool
        The last step was at rounding level: ``residual`` is as small as ``q`` allows.
    terms : dict
        :meth:`NumericModel.dynamics_terms` at ``q`` (zero speeds), for :func:`project_velocities`.
    """

    q: np.ndarray
    residual: float
    iterations: int
    stalled: bool
    terms: Mapping[str, np.ndarray]

    def accepted(self, tol: float) -> bool:
        """Converged to ``tol``, or as close as rounding allows."""
        return self.residual <= tol or self.stalled


def _residual(phi: np.ndarray) -> float:
    return float(np.max(np.abs(phi))) if len(phi) else 0.0


def project_positions(model: NumericModel, q, t: float, *, tol: float, free: Sequence[int] | None = None,
                      max_iterations: int = MAX_PROJECTION_ITERATIONS) -> PositionProjection:
    """Gauss-Newton onto ``Phi(q, t) = 0`` from ``q`` over the coordinates ``free`` (default: all).

    Parameters
    ----------
    model : NumericModel
    q : (m,)
    t : float
    tol : float
        Target ``max |Phi|``.
    free : sequence of int, optional
        The coordinates that may move.
    max_iterations : int

    Returns
    -------
    PositionProjection
    """
    q = np.array(q, dtype=float)
    free = slice(None) if free is None else list(free)  # a view for all coordinates: no copies per step
    zero = np.zeros(model.m)
    terms = model.dynamics_terms(q, zero, t)
    residual, stalled, iterations = _residual(terms["Phi"]), False, 0
    while residual > tol and not stalled and iterations < max_iterations and model.r:
        step = least_norm(terms["Phi_q"][:, free], -terms["Phi"], rank_rtol=model.rank_rtol)
        if np.all(np.abs(step) <= STALL * (1 + np.abs(q[free]))):
            stalled = True  # the correction is at rounding level: Phi is as small as q allows
            break
        factor = 1.0
        while True:
            trial = q.copy()
            trial[free] += factor * step
            trial_terms = model.dynamics_terms(trial, zero, t)
            trial_residual = _residual(trial_terms["Phi"])
            if trial_residual < residual or factor <= MIN_STEP_FACTOR:
                break
            factor /= 2
        if not trial_residual < residual:
            break  # no descent along the Gauss-Newton direction
        iterations += 1
        q, terms, residual = trial, trial_terms, trial_residual
    return PositionProjection(q, residual, iterations, stalled, terms)


def project_velocities(model: NumericModel, q, qd, t: float, *, free: Sequence[int] | None = None,
                       terms: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """``qd`` changed least, in the speeds ``free`` (default: all), so that ``B qd + c = 0``
    (``B = [Phi_q; A]``, ``c = [Phi_t; b]`` at ``(q, t)``; ``terms``: :meth:`NumericModel.dynamics_terms`
    there when already at hand), shape (m,)."""
    qd = np.array(qd, dtype=float)
    if not model.r + model.s:
        return qd
    free = slice(None) if free is None else list(free)  # a view for all coordinates: no copies per step
    if terms is None:
        terms = model.dynamics_terms(np.asarray(q, dtype=float), np.zeros(model.m), t)
    B, c = velocity_constraints(terms)
    qd[free] -= least_norm(B[:, free], B @ qd + c, rank_rtol=model.rank_rtol)
    return qd
