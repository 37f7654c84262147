"""The exact Jacobians of static equilibrium and linearization: taken symbolically from the
:class:`~kronlag.symbolic.equations.Equations` (:func:`tangent_matrices`) and evaluated by the
numeric model's kernels (:meth:`~kronlag.numeric.NumericModel.evaluate_expressions`, with the
accelerations and multipliers as extra inputs)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel
    from ..symbolic.equations import Equations

__all__ = ["tangent_matrices", "TangentEvaluator"]


@functools.lru_cache(maxsize=8)
def tangent_matrices(equations: Equations) -> dict[str, sp.ImmutableMatrix]:
    """The symbolic Jacobians of the linearization (full coordinates), shapes with m, r::

        K        (m, m)  d(M qdd + C qd + g - f_Q + Phi_q^T lambda)/dq
        H_qd     (m, m)  d(C qd - f_Q)/dqd
        gamma_q  (r, m)  d gamma/dq         gamma_qd (r, m)  d gamma/dqd
        V        (r, m)  d(Phi_q qd)/dq     W        (r, m)  d(Phi_q qdd)/dq
        f_Q_p    (m, P)  d f_Q/dp (the input directions of the parameters)
        static   (m, 1)  g - f_Q(q, 0) + Phi_q^T lambda
        K_static (m, m)  d static/dq

    in the symbols ``q``, ``qd``, ``qdd`` (``eq.accelerations``), ``lambda``
    (``eq.lambdas``), the parameters and ``t``.
    """
    eq = equations
    q, qd, qdd = sp.Matrix(eq.coordinates), sp.Matrix(eq.speeds), sp.Matrix(eq.accelerations)
    lam = sp.Matrix(eq.lambdas)
    reaction = eq.Phi_q.T * lam if eq.Phi.rows else sp.zeros(eq.M.rows, 1)
    dynamic = eq.M * qdd + eq.Cqd + eq.g - eq.f_Q + reaction
    static = (eq.g - eq.f_Q).subs(dict.fromkeys(eq.speeds, 0)) + reaction
    constraint_rate = eq.Phi_q * qd
    matrices = {
        "K": dynamic.jacobian(q),
        "H_qd": (eq.Cqd - eq.f_Q).jacobian(qd),
        "gamma_q": eq.gamma.jacobian(q),
        "gamma_qd": eq.gamma.jacobian(qd),
        "V": constraint_rate.jacobian(q),
        "W": (eq.Phi_q * qdd).jacobian(q),
        "f_Q_p": eq.f_Q.jacobian(sp.Matrix(eq.parameters)) if eq.parameters else sp.zeros(eq.M.rows, 0),
        "static": static,
        "K_static": static.jacobian(q),
    }
    return {name: sp.ImmutableMatrix(matrix) for name, matrix in matrices.items()}


class TangentEvaluator:
    """Some of :func:`tangent_matrices` (and ``M``, ``Phi``, ``Phi_q``) of ``model``, evaluated at
    ``(t, q, qd, qdd, lambda)`` with the model's parameters; compiled on first use.

    Parameters
    ----------
    model : NumericModel
        With holonomic constraints only.
    group : str
        Names the compiled kernel (one per group and model).
    names : sequence of str
        The matrices of the group.
    """

    def __init__(self, model: NumericModel, group: str, names: Sequence[str]):
        if model.s:
            raise NotImplementedError(f"{model.equations.system.name}: equilibrium and linearization support "
                                      f"holonomic constraints only (the model has s = {model.s} nonholonomic ones)")
        self.model, self.group, self.names = model, group, tuple(names)
        eq = model.equations
        self.extra = (*eq.accelerations, *eq.lambdas)

    def _matrices(self) -> dict[str, sp.MatrixBase]:
        eq = self.model.equations
        available = dict(tangent_matrices(eq), M=eq.M, Phi=eq.Phi, Phi_q=eq.Phi_q)
        return {name: available[name] for name in self.names}

    def __call__(self, t: float, q, qd, qdd, lam) -> dict[str, np.ndarray]:
        """The group's matrices by name, each of its symbolic shape."""
        values = dict(zip(self.extra, np.concatenate([np.asarray(qdd, dtype=float), np.asarray(lam, dtype=float)])))
        return self.model.evaluate_expressions(self.group, self._matrices, q, qd, t, extra=values)
