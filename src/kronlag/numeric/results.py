"""The results of forward and inverse dynamics at one or many states."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ForwardDynamicsResult", "InverseDynamicsResult", "ForwardDynamicsBatch", "forward_dynamics_outcome"]


@dataclass(slots=True, eq=False)
class ForwardDynamicsResult:
    """Solution of the augmented system at one state.

    Attributes
    ----------
    qdd : (m,) accelerations.
    lam : (r,) multipliers ``lambda`` of the holonomic constraints.
    mu : (s,) multipliers ``mu`` of the nonholonomic constraints.
    unique_multipliers : bool
        False when ``[Phi_q; A]`` is rank deficient (redundant constraints); then
        ``(lam, mu)`` is the minimum-norm solution (``qdd`` is still unique).
    rank : int
        Numerical rank of ``[Phi_q; A]``.
    """

    qdd: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    unique_multipliers: bool
    rank: int


def forward_dynamics_outcome(qdd, lam, mu, rank: int) -> ForwardDynamicsResult | int:
    """What a backend's forward dynamics returns: the result, or the rank alone when it marks a failure
    (< 0).  The C call layer (``codegen/_call.c``, ``ForwardDynamics``) builds the same in C: keep the
    fields plain slots stored by ``__init__``."""
    if rank < 0:
        return int(rank)
    return ForwardDynamicsResult(qdd, lam, mu, rank == len(lam) + len(mu), rank)


@dataclass(slots=True, eq=False)
class InverseDynamicsResult:
    """Actuator forces and multipliers for a prescribed motion.

    Attributes
    ----------
    forces : (n_a,) or (N, n_a)
        Generalized forces on the actuated coordinates.
    lam : (r,) or (N, r)
    mu : (s,) or (N, s)
    unique : bool
        False when ``[B, Phi_q^T, A^T]`` is column rank deficient; then the
        minimum-norm solution is returned.
    """

    forces: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    unique: bool


@dataclass(slots=True, eq=False)
class ForwardDynamicsBatch:
    """Solutions of the augmented system at N states (:meth:`NumericModel.forward_dynamics_batch`).

    Attributes
    ----------
    qdd : (N, m) accelerations.
    lam : (N, r) multipliers ``lambda``.
    mu : (N, s) multipliers ``mu``.
    rank : (N,) int
        Numerical rank of ``[Phi_q; A]`` at each state; -1 marks a singular
        configuration, whose row of ``qdd``, ``lam`` and ``mu`` is NaN.
    """

    qdd: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    rank: np.ndarray

