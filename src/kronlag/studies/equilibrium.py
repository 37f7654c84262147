"""Static equilibrium of the holonomically constrained equations (Van Khang 2011, Eq. 23, s = 0)::

    g(q) - f_Q(q, 0, t) + Phi_q(q)^T lambda = 0,   Phi(q) = 0

solved by Newton's method on the combined system with the exact Jacobian
``[[K, Phi_q^T], [Phi_q, 0]]``, ``K = d(g - f_Q + Phi_q^T lambda)/dq`` (:mod:`.tangent`),
some coordinates held (drives held).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import AssemblyError, EquilibriumError
from ..numeric.assembly import held_values
from ..numeric.linalg import least_norm
from ..numeric.reactions import Reaction, joint_reaction
from .tangent import TangentEvaluator

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel

__all__ = ["Equilibrium", "EquilibriumError", "equilibrium"]


@dataclass(frozen=True, eq=False)
class Equilibrium:
    """A static equilibrium ``g - f_Q + Phi_q^T lambda = 0``, ``Phi = 0`` (held coordinates excepted).

    Attributes
    ----------
    q : (m,)
        Coordinates.
    lam : (r,)
        Multipliers ``lambda`` (minimum-norm ones for redundant constraints).
    reactions : (r,)
        The constraint reactions as multipliers (the same numbers as ``lam``).
    holding_forces : dict of str -> float
        Generalized force an actuator must apply on each held coordinate,
        ``(g - f_Q + Phi_q^T lambda)_i``.
    residual : float
        ``max |[g - f_Q + Phi_q^T lambda (free rows); Phi]|`` at the solution.
    iterations : int
    t : float
        The time at which it holds.
    model : NumericModel
    """

    q: np.ndarray
    lam: np.ndarray
    holding_forces: dict[str, float]
    residual: float
    iterations: int
    t: float = 0.0
    model: NumericModel | None = field(default=None, repr=False)

    @property
    def reactions(self) -> np.ndarray:
        return self.lam

    def reaction(self, name: str, *, frame: str = "world") -> Reaction:
        """The reaction of joint ``name`` at the equilibrium, as :meth:`kronlag.Trajectory.reaction`
        gives it (one row: ``force`` (1, d), ``torque``, ``point``); see :mod:`kronlag.numeric.reactions`."""
        return joint_reaction(self.model, name, [self.t], self.q[None, :], self.lam[None, :], frame=frame)


def equilibrium(model: NumericModel, q_guess, *, fixed: Mapping | None = None, t: float = 0.0,
                tol: float = 1e-10, max_iterations: int = 50) -> Equilibrium:
    """Static equilibrium near ``q_guess`` with the coordinates in ``fixed`` held (drives held).

    Newton's method on the unknowns ``(q_free, lambda)`` of::

        (g(q) - f_Q(q, 0, t) + Phi_q(q)^T lambda)_free = 0,   Phi(q) = 0

    with the exact Jacobian ``[[K_ff, Phi_q,f^T], [Phi_q,f, 0]]``
    (``K = d(g - f_Q + Phi_q^T lambda)/dq``), minimum-norm steps (redundant
    constraints allowed) halved while the residual grows.  The start is the
    assembled guess (:meth:`~kronlag.numeric.NumericModel.assemble`) and the
    least-squares multipliers there.

    Parameters
    ----------
    model : NumericModel
    q_guess : (m,)
    fixed : mapping of coordinate name (or symbol) -> value, optional
        Coordinates held at a value; their equations are dropped and the force
        that holds them is reported in ``holding_forces``.
    t : float
        Time at which time-varying parameters (e.g. a torque ``tau(t)``) are evaluated.
    tol : float
        Convergence: ``max |residual| <= tol`` times the largest generalized force
        magnitude (at least 1) for the force rows, ``tol`` for ``Phi``.
    max_iterations : int

    Returns
    -------
    Equilibrium
        ``q`` (m,), ``lam`` (r,), ``reactions``, ``holding_forces``, ``residual``.

    Raises
    ------
    EquilibriumError
        No equilibrium near the guess (the message and ``residual`` say how far), or the
        drives move at ``t`` (``Phi_t != 0``).
    """
    evaluate_at = TangentEvaluator(model, "equilibrium", ("static", "K_static", "Phi", "Phi_q"))
    m, r = model.m, model.r
    try:
        q, _ = model.assemble(q_guess, fixed=fixed, t=t)
    except AssemblyError as error:
        raise EquilibriumError(f"no equilibrium: {error}", error.residual) from error
    moving = np.max(np.abs(model.Phi_t(q, t)), initial=0.0)
    if moving > tol:
        raise EquilibriumError(f"no static equilibrium of {model.equations.system.name} at t = {t:g}: its drives "
                               f"move there (max |Phi_t| = {moving:.3g}); hold coordinates with fixed=... instead",
                               moving)
    held = sorted(held_values(model, fixed, q.copy()))
    free = [i for i in range(m) if i not in held]
    zeros = np.zeros(m)

    def evaluate(q, lam):
        return evaluate_at(t, q, zeros, zeros, lam)

    start = evaluate(q, np.zeros(r))
    lam = least_norm(start["Phi_q"][:, free].T, -start["static"][free, 0], rank_rtol=model.rank_rtol)
    scale = max(1.0, float(np.max(np.abs(start["static"]))))

    def residual_of(q, lam):
        values = evaluate(q, lam)
        rows = np.concatenate([values["static"][free, 0] / scale, values["Phi"][:, 0]])
        return rows, float(np.max(np.abs(rows))) if len(rows) else 0.0

    rows, residual = residual_of(q, lam)
    iterations = 0
    while residual > tol and iterations < max_iterations:
        iterations += 1
        values = evaluate(q, lam)
        Phi_q = values["Phi_q"]
        jacobian = np.block([[values["K_static"][np.ix_(free, free)] / scale, Phi_q[:, free].T / scale],
                             [Phi_q[:, free], np.zeros((r, r))]])
        step = least_norm(jacobian, -rows, rank_rtol=model.rank_rtol)
        factor = 1.0
        while factor > 1e-6:
            trial_q = q.copy()
            trial_q[free] += factor * step[:len(free)]
            trial_lam = lam + factor * step[len(free):]
            trial_rows, trial_residual = residual_of(trial_q, trial_lam)
            if trial_residual < residual:
                break
            factor /= 2
        else:
            break
        q, lam, rows, residual = trial_q, trial_lam, trial_rows, trial_residual
    if residual > tol:
        raise EquilibriumError(f"no static equilibrium of {model.equations.system.name} found near the guess "
                               f"with {dict(fixed or {})} held: max |[g - f_Q + Phi_q^T lambda; Phi]| = "
                               f"{residual:.3g} > tol = {tol:g} after {iterations} Newton iterations "
                               f"(q = {q.tolist()})", residual)
    forces = evaluate(q, lam)["static"][:, 0]
    holding = {model.coordinate_names[i]: float(forces[i]) for i in held}
    return Equilibrium(q, lam, holding, residual, iterations, t, model)
