"""Dense linear algebra of the constrained equations, with the rank policy of :mod:`.tolerances`.

:func:`solve_augmented` solves the augmented system of forward dynamics by a null-space method
that stays correct for redundant constraints, :func:`least_norm` gives the minimum-norm
corrections of the projections and of assembly, :func:`pseudo_inverses` the stacked
pseudo-inverses of inverse dynamics.  The C twins are in ``numeric/codegen/c/linalg.c`` and
``augmented.c``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .tolerances import CHOLESKY_RTOL, RANK_RTOL, numerical_rank

__all__ = ["solve_augmented", "least_norm", "pseudo_inverses", "velocity_constraints"]


def pseudo_inverses(matrices: np.ndarray, rank_rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-inverses (N, c, r) of the stacked matrices (N, r, c) and their numerical ranks (N,), from
    one SVD each, with the rank policy of :func:`kronlag.tolerances.numerical_rank`."""
    n, rows, columns = matrices.shape
    if rows == 0 or columns == 0:
        return np.zeros((n, columns, rows)), np.zeros(n, dtype=int)
    U, S, Vt = np.linalg.svd(matrices, full_matrices=False)
    ranks = np.array([numerical_rank(values, rank_rtol) for values in S], dtype=int)
    kept = np.arange(S.shape[1]) < ranks[:, None]  # the singular values come sorted, largest first
    inverse = np.where(kept, 1.0 / np.where(kept, S, 1.0), 0.0)
    return (np.swapaxes(Vt, 1, 2) * inverse[:, None, :]) @ np.swapaxes(U, 1, 2), ranks


def velocity_constraints(terms: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``B = [Phi_q; A]`` (r + s, m) and ``c = [Phi_t; b]`` (r + s,) from :func:`split_terms` of
    one state: the velocity constraints of both kinds are ``B qd + c = 0``."""
    return (np.vstack([terms["Phi_q"], terms["A"]]), np.concatenate([terms["Phi_t"], terms["b"]]))


def solve_augmented(M: np.ndarray, h: np.ndarray, G: np.ndarray, c: np.ndarray, *,
                    rank_rtol: float = RANK_RTOL) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Solve ``[[M, G^T], [G, 0]] [qdd; nu] = [h; c]`` by the null-space method.

    ``G = [Phi_q; A]`` (k, m) may be rank deficient.  With the SVD
    ``G = U1 S1 V1^T`` of numerical rank ``rho`` (``S1``: the singular values
    above ``rank_rtol`` times the largest, :func:`kronlag.tolerances.numerical_rank`) and ``Z`` (m, m - rho) completing
    ``V1`` to an orthogonal ``V = [V1, Z]`` (``Z`` spans the null space of ``G``),
    ``qdd = V1 y1 + Z y2`` with::

        y1 = S1^{-1} U1^T c                              (least squares if inconsistent)
        (Z^T M Z) y2 = Z^T h - Z^T M V1 y1               (Cholesky)
        nu = U1 S1^{-1} V1^T (h - M qdd)                 (minimum-norm multipliers)

    The C backend (``kronlag_solve`` in ``src/kronlag/c/augmented.c``) does
    the same with a column-pivoted QR in place of the SVD.

    Parameters
    ----------
    M : (m, m)
    h : (m,)
    G : (k, m)
    c : (k,)

    Returns
    -------
    (qdd (m,), nu (k,), rank) or None
        None when ``Z^T M Z`` is not positive definite (a singular configuration).
    """
    m, k = len(h), len(c)
    if k:
        U, S, Vt = np.linalg.svd(G)
        rank = numerical_rank(S, rank_rtol)
        U1, S1, V = U[:, :rank], S[:rank], Vt.T
    else:
        U1, S1, V, rank = np.zeros((0, 0)), np.zeros(0), np.eye(m), 0
    B = V.T @ M @ V
    y = V.T @ h
    y1 = (U1.T @ c) / S1
    B22 = B[rank:, rank:]
    y2 = np.zeros(0)
    if m > rank:
        try:
            L = np.linalg.cholesky(B22)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.diag(L) ** 2 > CHOLESKY_RTOL * np.max(np.diag(B22))):
            return None
        y2 = np.linalg.solve(B22, y[rank:] - B[rank:, :rank] @ y1)
    qt = np.concatenate([y1, y2])
    nu = U1 @ ((y - B @ qt)[:rank] / S1)
    return V @ qt, nu, rank


def least_norm(G: np.ndarray, b: np.ndarray, *, rank_rtol: float = RANK_RTOL) -> np.ndarray:
    """The least-norm least-squares solution ``x`` of ``G x = b`` over the independent rows of ``G``
    (singular values above ``rank_rtol`` times the largest, :func:`kronlag.tolerances.numerical_rank`):
    the correction of the projections and of :meth:`NumericModel.assemble`, shape (columns,)."""
    if G.size == 0:
        return np.zeros(G.shape[1])
    U, S, Vt = np.linalg.svd(G, full_matrices=False)
    rank = numerical_rank(S, rank_rtol)
    return Vt[:rank].T @ ((U[:, :rank].T @ b) / S[:rank])

