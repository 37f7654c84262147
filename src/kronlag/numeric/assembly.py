"""Assembly: consistent initial positions and speeds near a guess, some of them held."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import AssemblyError, InputError
from .linalg import velocity_constraints
from .projection import project_positions, project_velocities

if TYPE_CHECKING:
    from .numeric_model import NumericModel

__all__ = ["assemble", "held_values", "finite_guess"]


def assemble(model: NumericModel, q_guess, *, fixed: Mapping | None = None, qd_guess=None, qd_fixed: Mapping | None = None,
             tol: float = 1e-12, max_iterations: int = 50, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Consistent ``(q0, qd0)`` near a guess, with some coordinates and speeds held.

    Positions: Gauss-Newton on ``Phi(q) = 0`` over the free coordinates
    (minimum-norm steps ``Phi_q[:, free] dq = -Phi``, halved while the residual
    grows) until ``max |Phi| <= tol`` (:func:`kronlag.numeric.projection.project_positions`).
    Speeds: the least change of ``qd_guess``
    (zero if not given) in the free speeds that satisfies ``Phi_q qd + Phi_t = 0`` and
    ``A qd + b = 0`` (``Phi_t``, ``b`` and, for drives, ``Phi`` depend on ``t``).

    Parameters
    ----------
    q_guess : (m,)
    fixed, qd_fixed : mapping of coordinate name (or symbol) -> value, optional
    qd_guess : (m,), optional
    tol : float
    max_iterations : int
    t : float
        Time at which the drives and time-varying parameters are evaluated.

    Returns
    -------
    q0, qd0 : (m,)

    Raises
    ------
    InputError
        A guess or held value is not a finite number (the message names the coordinate).
    AssemblyError
        No solution near the guess (the message gives the residual).
    """
    q = model.state_vector(q_guess, "q_guess").copy()
    held = held_values(model, fixed, q)
    finite_guess(model, q, "q_guess" if not held else "q_guess (with the held values)")
    free = [i for i in range(model.m) if i not in held]
    positions = project_positions(model, q, t, tol=tol, free=free, max_iterations=max_iterations)
    q, residual = positions.q, positions.residual
    if residual > tol:
        raise AssemblyError(f"cannot assemble {model.equations.system.name} near the guess with "
                            f"{dict(fixed or {})} held: max |Phi| = {residual:.3g} > tol = {tol:g}; "
                            f"{_unsatisfied(model, positions.terms['Phi'], tol)}", residual)
    qd = np.zeros(model.m) if qd_guess is None else model.state_vector(qd_guess, "qd_guess").copy()
    held = held_values(model, qd_fixed, qd)
    finite_guess(model, qd, "qd_guess" if not held else "qd_guess (with the held values)")
    qd = project_velocities(model, q, qd, t, free=[i for i in range(model.m) if i not in held],
                            terms=positions.terms)
    if model.r + model.s:
        B, c = velocity_constraints(positions.terms)
        violation = float(np.max(np.abs(B @ qd + c)))
        allowed = tol * max(1.0, float(np.max(np.abs(B))) * float(np.max(np.abs(qd))))
        if violation > allowed:
            raise AssemblyError(f"no speeds with {dict(qd_fixed or {})} held satisfy the velocity "
                                f"constraints: max |[Phi_q qd + Phi_t; A qd + b]| = {violation:.3g}", violation)
    return q, qd


def _unsatisfied(model: NumericModel, Phi: np.ndarray, tol: float) -> str:
    """The constraint rows ``|Phi_j| > tol`` where the assembly ended, by name, largest first."""
    values = np.abs(np.ravel(Phi))
    rows = sorted(np.flatnonzero(values > tol), key=lambda j: -values[j])
    names = [constraint.name for constraint in model.equations.system.constraints]
    return "unsatisfied: " + ", ".join(f"{names[j]!r} (|Phi| = {values[j]:.3g})" for j in rows)


def held_values(model: NumericModel, values: Mapping | None, target: np.ndarray) -> set[int]:
    """Write the held ``values`` into ``target``; return their indices."""
    if not values:
        return set()
    indices = model.coordinate_indices(list(values))
    for i, value in zip(indices, values.values()):
        target[i] = float(value)
    return set(indices)


def finite_guess(model: NumericModel, vector: np.ndarray, what: str) -> None:
    """InputError naming the coordinates where ``vector`` (a guess, shape (m,)) is NaN or infinite:
    the iterations would otherwise stop in a linear-algebra error ("SVD did not converge")."""
    bad = [f"{name} ({value})" for name, value in zip(model.coordinate_names, vector) if not np.isfinite(value)]
    if bad:
        raise InputError(f"{what} is not finite for {', '.join(bad)}")
