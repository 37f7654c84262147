"""What a segment of a run with limits watches (:mod:`.impacts` builds it, every integrator honours it).

The watched functions, each positive while nothing happens and falling through zero at an event:
the gaps ``g_i(q)`` of the limit sides not in contact, then the contact forces ``-lambda_j`` of the
sides held as constraints (rows ``contact_rows`` of the segment's model), then per joint with friction
its exact stiction's function (:mod:`.stiction`).  An integrator that sees
one fall through zero ends its segment there with :attr:`~.trajectory.Result.LIMIT` and a
:class:`LimitStop`: the compiled ones by root finding (CVODE's ``CVodeRootInit``; ALI3-P by the
secant method on its step's interpolant), the Python ones by Brent's method on the dense output
(:func:`locate`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ..core.errors import SingularConfigurationError
from ..numeric.friction import friction_records, stiction_values
from ..numeric.limit_kernels import LimitKernels

__all__ = ["LimitStop", "LimitWatch", "locate"]


@dataclass(frozen=True, eq=False)
class LimitWatch:
    """The functions watched in one segment (see the module docstring).

    Attributes
    ----------
    kernels : LimitKernels
    watched : (n,) bool
        The sides whose gap is watched (False: held as a contact constraint).
    contact_rows : tuple of int
        The rows of ``lam`` of the segment's model that hold the contact sides, in side order.
    first_step : float
        After a rebound, a first step short enough to end inside the flight (0: the integrator's
        choice): a crossing is seen only from a step that ends with the gap open.
    parameters : (P,) or None
        The model's parameter vector when it is constant (None: asked of the model at each ``t``).
    friction : int
        The joints with friction, each watched after the contacts (exact stiction,
        :func:`~kronlag.numeric.friction.stiction_values`; 1 for a joint with the smooth law).
    at_rest : float
        Exact stiction: a sliding joint's rate within this is at rest; above 0, the compiled driver may
        turn a sliding direction itself at a kinematic dead point (``kl_turn`` in ``c/cvode.c``; the
        solution's ``turns``), 0: every event ends the segment.
    """

    kernels: LimitKernels
    watched: np.ndarray
    contact_rows: tuple[int, ...]
    first_step: float = 0.0
    parameters: np.ndarray | None = None
    friction: int = 0
    at_rest: float = 0.0

    @property
    def size(self) -> int:
        return len(self.kernels) + len(self.contact_rows) + self.friction

    def values(self, model, t: float, y: np.ndarray) -> np.ndarray:
        """The watched functions at ``(t, y)``; 1 for a side held as a constraint, shape (:attr:`size`,)."""
        m = model.m
        p = self.parameters if self.parameters is not None else model.parameter_vector(t)
        gaps = np.where(self.watched, self.kernels.gap(y[:m], p), 1.0) if len(self.kernels) else np.empty(0)
        if not self.contact_rows and not self.friction:
            return gaps
        try:
            solution = model.forward_dynamics(y[:m], y[m:], t)
            lam, nu = solution.lam, np.concatenate([solution.lam, solution.mu])
        except SingularConfigurationError:
            lam = nu = np.full(model.r + model.s, np.nan)
        values = [gaps, -lam[list(self.contact_rows)]]
        if self.friction:
            values.append(stiction_values(friction_records(model, t, y[:m], y[m:]), y[m:], nu))
        return np.concatenate(values)


@dataclass(frozen=True, eq=False)
class LimitStop:
    """Where a segment ended at an event: time, state ``[q, qd]`` and the watched functions that fell
    through zero (indices into :meth:`LimitWatch.values`)."""

    t: float
    y: np.ndarray
    triggered: tuple[int, ...]


def locate(values: Callable[[float], np.ndarray], t0: float, t1: float, before: np.ndarray,
           after: np.ndarray) -> tuple[float, tuple[int, ...]] | None:
    """The first time in ``(t0, t1]`` where a function positive at ``t0`` (``before``) has fallen to
    zero or below at ``t1`` (``after``), by Brent's method on ``values(t)`` (to rounding in t), and the
    functions that have fallen there; None when none has."""
    falling = np.flatnonzero((before > 0) & (after <= 0))
    if falling.size == 0:
        return None
    tolerance = 4 * np.finfo(float).eps * max(abs(t0), abs(t1), 1.0)
    start, end = values(t0), values(t1)  # the dense output's ends (the step's, up to rounding)
    roots = {}
    for i in (int(i) for i in falling):
        if start[i] <= 0 or end[i] >= 0:  # no sign change left on the interpolant: at an end
            roots[i] = t0 if start[i] <= 0 else t1
        else:
            roots[i] = brentq(lambda t, i=i: values(t)[i], t0, t1, xtol=tolerance)
    first = min(roots.values())
    return first, tuple(i for i, root in roots.items() if root <= first + 2 * tolerance)
