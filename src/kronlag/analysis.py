"""Static equilibrium and linearization of the constrained equations of motion.

For the holonomically constrained system (Van Khang 2011, Eq. 23 with s = 0)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + g(q) = f_Q(q, qd, t),   Phi(q) = 0

* :func:`equilibrium` solves the static equations (``qd = qdd = 0``, some
  coordinates held)::

      g(q) - f_Q(q, 0, t) + Phi_q(q)^T lambda = 0,   Phi(q) = 0

  by Newton's method on the combined system, with the exact Jacobian
  ``[[K, Phi_q^T], [Phi_q, 0]]`` where ``K = d(g - f_Q + Phi_q^T lambda)/dq``.
* :func:`linearize` linearizes the motion about a state ``(q0, qd0)`` on the
  constraint manifold, in independent coordinates ``z`` (a subset of ``q``).
  With ``P`` (m, r) solving the constraints for the dependent coordinates and
  ``R = (I - P Phi_q) E`` (m, n) the velocity transformation (``E`` selects ``z``,
  ``Phi_q R = 0``), perturbations on the manifold are, to first order::

      dq   = R dz
      dqd  = R dzd - P V dq                                   V = d(Phi_q qd0)/dq
      dqdd = R dzdd + P (gamma_q dq + gamma_qd dqd - W dq)    W = d(Phi_q qdd0)/dq

  and projecting the dynamics with ``R^T`` (which removes ``lambda``; its
  variation leaves the multiplier stiffness ``d(Phi_q^T lambda0)/dq``) gives::

      M_r dzdd + D_r dzd + K_r dz = R^T B_u du
      M_r = R^T M R
      D_r = R^T (H_qd + M P gamma_qd) R
      K_r = R^T (K + M P (gamma_q - gamma_qd P V - W) - H_qd P V) R
      K   = d(M qdd0 + C qd0 + g - f_Q + Phi_q^T lambda0)/dq,   H_qd = d(C qd - f_Q)/dqd

  At an equilibrium (``qd0 = qdd0 = 0``) ``V``, ``W``, ``gamma_q`` and
  ``gamma_qd`` vanish and ``K_r = R^T (g_q - f_Q,q + d(Phi_q^T lambda0)/dq) R``.

The Jacobians are exact: taken symbolically from the matrices of the
:class:`~kronlag.equations.Equations` (:func:`tangent_matrices`) and evaluated
with the model's parameter values.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg
import sympy as sp

from . import codegen
from .numeric import AssemblyError, _names

if TYPE_CHECKING:
    from .equations import Equations
    from .numeric import NumericModel

__all__ = ["EquilibriumError", "Equilibrium", "LinearModel", "equilibrium", "linearize", "tangent_matrices",
           "symbolic_linearization"]


class EquilibriumError(RuntimeError):
    """:func:`equilibrium` found no static equilibrium near the guess; ``residual`` says how far."""

    def __init__(self, message: str, residual: float):
        self.residual = residual
        super().__init__(message)


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
    """

    q: np.ndarray
    lam: np.ndarray
    holding_forces: dict[str, float]
    residual: float
    iterations: int

    @property
    def reactions(self) -> np.ndarray:
        return self.lam


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


class _TangentFunctions:
    """:func:`tangent_matrices` (and M, Phi, Phi_q) as NumPy functions of ``(t, q, qd, qdd, lam, p)``."""

    def __init__(self, equations: Equations):
        eq = equations
        arguments = [eq.time, list(eq.coordinates), list(eq.speeds), list(eq.accelerations), list(eq.lambdas),
                     list(eq.parameters)]
        matrices = dict(tangent_matrices(eq), M=eq.M, Phi=eq.Phi, Phi_q=eq.Phi_q)
        self.shapes = {name: matrix.shape for name, matrix in matrices.items()}
        self.functions = {name: sp.lambdify(arguments, matrix, modules="numpy", cse=True)
                          for name, matrix in matrices.items()}

    def __call__(self, name: str, t: float, q, qd, qdd, lam, p) -> np.ndarray:
        value = self.functions[name](t, q, qd, qdd, lam, p)
        return np.array(value, dtype=float).reshape(self.shapes[name])


def _tangent(model: NumericModel) -> _TangentFunctions:
    """The model's tangent functions, built on first use (sympy.lambdify) and kept on the model."""
    functions = model.__dict__.get("_tangent_functions")
    if functions is None:
        if model.s:
            raise NotImplementedError(f"{model.equations.system.name}: equilibrium and linearization support "
                                      f"holonomic constraints only (the model has s = {model.s} nonholonomic ones)")
        functions = model.__dict__["_tangent_functions"] = _TangentFunctions(model.equations)
    return functions


# -- static equilibrium -----------------------------------------------------------------------------


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
    functions = _tangent(model)
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
    held = sorted(model._held(fixed, q.copy()))
    free = [i for i in range(m) if i not in held]
    p = model.parameter_vector(t)
    zeros = np.zeros(m)

    def evaluate(name, q, lam):
        return functions(name, t, q, zeros, zeros, lam, p)

    Phi_q = evaluate("Phi_q", q, np.zeros(r))
    lam = np.linalg.lstsq(Phi_q[:, free].T, -evaluate("static", q, np.zeros(r))[free, 0], rcond=None)[0] \
        if r else np.zeros(0)
    scale = max(1.0, float(np.max(np.abs(evaluate("static", q, np.zeros(r))))))

    def residual_of(q, lam):
        rows = np.concatenate([evaluate("static", q, lam)[free, 0] / scale, evaluate("Phi", q, lam)[:, 0]])
        return rows, float(np.max(np.abs(rows))) if len(rows) else 0.0

    rows, residual = residual_of(q, lam)
    iterations = 0
    while residual > tol and iterations < max_iterations:
        iterations += 1
        Phi_q = evaluate("Phi_q", q, lam)
        jacobian = np.block([[evaluate("K_static", q, lam)[np.ix_(free, free)] / scale, Phi_q[:, free].T / scale],
                             [Phi_q[:, free], np.zeros((r, r))]])
        step = np.linalg.lstsq(jacobian, -rows, rcond=None)[0]
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
    forces = evaluate("static", q, lam)[:, 0]
    holding = {model.coordinate_names[i]: float(forces[i]) for i in held}
    return Equilibrium(q, lam, holding, residual, iterations)


# -- linearization ------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LinearModel:
    """Linearized motion ``x' = A x + B u``, ``y = C x + D u`` in independent coordinates.

    The state is ``x = [dz; dzd]`` (2n), ``z`` the independent coordinates
    ``coordinates``; the second-order form is ``mass dzdd + damping dzd +
    stiffness dz = R^T B_u du`` (see :mod:`kronlag.analysis`).

    Attributes
    ----------
    A : (2n, 2n)
    B : (2n, k)
        Columns: the ``inputs``.
    C : (l, 2n), D : (l, k)
        Rows: the ``outputs``.
    coordinates : tuple of str
        Names of the independent coordinates ``z`` (n of them).
    inputs, outputs : tuple of str
    mass, damping, stiffness : (n, n)
        ``M_r``, ``D_r``, ``K_r``.
    velocity_transformation : (m, n)
        ``R = dq/dz`` (``Phi_q R = 0``).
    q, qd, lam : the operating point, (m,), (m,), (r,).
    model : NumericModel
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    coordinates: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    mass: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray
    velocity_transformation: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    lam: np.ndarray
    t: float
    model: NumericModel = field(repr=False)

    def _modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Eigenvalues ``w^2`` (ascending by real part) and M_r-normalized vectors of ``K_r phi = w^2 M_r phi``."""
        values, vectors = scipy.linalg.eig(self.stiffness, self.mass)
        order = np.argsort(values.real)
        values, vectors = values[order].real, vectors[:, order].real
        norms = np.sqrt(np.abs(np.einsum("ik,ij,jk->k", vectors, self.mass, vectors)))
        return values, vectors / np.where(norms > 0, norms, 1.0)

    @property
    def natural_frequencies(self) -> np.ndarray:
        """Undamped natural frequencies ``w_k`` (rad/s, ascending), ``K_r phi = w^2 M_r phi``.

        ``nan`` for a negative ``w^2`` (an unstable direction; see ``stiffness``).
        """
        values, _ = self._modes()
        with np.errstate(invalid="ignore"):
            return np.where(values >= 0, np.sqrt(np.abs(values)), np.nan)

    @property
    def damping_ratios(self) -> np.ndarray:
        """Modal damping ratios ``phi_k^T D_r phi_k / (2 w_k)`` (M_r-normalized ``phi_k``;
        exact for proportional damping), in the order of ``natural_frequencies``."""
        _, vectors = self._modes()
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.einsum("ik,ij,jk->k", vectors, self.damping, vectors) / (2 * self.natural_frequencies)

    @property
    def mode_shapes(self) -> np.ndarray:
        """Mode shapes in all m coordinates, ``R phi_k``, shape (m, n): column k goes with
        ``natural_frequencies[k]``, scaled to a largest entry of +1."""
        _, vectors = self._modes()
        shapes = self.velocity_transformation @ vectors
        peaks = shapes[np.argmax(np.abs(shapes), axis=0), np.arange(shapes.shape[1])]
        return shapes / np.where(peaks != 0, peaks, 1.0)

    @property
    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of ``A`` (2n,), complex."""
        return np.linalg.eigvals(self.A)

    def to_control(self):
        """The system as a :class:`control.StateSpace` (needs python-control: ``pip install control``)."""
        try:
            import control
        except ImportError as error:
            raise ImportError("LinearModel.to_control needs python-control: pip install control "
                              "(or kronlag[control])") from error
        states = [f"{name}" for name in self.coordinates] + [f"{name}d" for name in self.coordinates]
        return control.ss(self.A, self.B, self.C, self.D, states=states, inputs=list(self.inputs) or None,
                          outputs=list(self.outputs) or None)

    def mode_trajectory(self, k: int, *, amplitude: float = 0.1, periods: float = 2.0, samples: int = 61):
        """A :class:`~kronlag.trajectory.Trajectory` of mode ``k`` swinging about the operating point.

        The independent coordinates follow ``z(t) = z0 + amplitude phi_k sin(w_k t)``
        (``phi_k`` scaled to a largest entry of 1 in ``q``); the dependent ones are
        assembled on ``Phi(q) = 0`` at every sample (so the motion is a true
        configuration of the mechanism, not ``q0 + a R phi`` off the manifold).
        """
        from .trajectory import Trajectory

        model, frequency = self.model, self.natural_frequencies[k]
        if not np.isfinite(frequency) or frequency <= 0:
            raise ValueError(f"mode {k} has no oscillation (w^2 <= 0); natural frequencies: "
                             f"{self.natural_frequencies.tolist()}")
        shape = self.mode_shapes[:, k]
        times = np.linspace(0.0, periods * 2 * np.pi / frequency, samples)
        q = np.empty((samples, model.m))
        guess = self.q.copy()
        for index, time in enumerate(times):
            target = self.q + amplitude * shape * np.sin(frequency * time)
            held = {name: target[model._coordinate_index[name]] for name in self.coordinates}
            guess, _ = model.assemble(target, fixed=held, t=self.t)
            q[index] = guess
        qd = np.gradient(q, times, axis=0)
        zeros, no_multipliers = np.zeros(samples), np.zeros((samples, model.r))
        return Trajectory(times, q, qd, np.gradient(qd, times, axis=0), no_multipliers,
                          np.zeros((samples, model.s)), zeros, zeros, no_multipliers,
                          np.zeros((samples, model.r + model.s)), model.coordinate_names, model,
                          f"mode {k}", 0, f"mode {k}: {frequency:.6g} rad/s", 0, 0, 0, 0.0)

    def animate_mode(self, k: int, path: str | PathLike | None = None, *, amplitude: float = 0.1,
                     periods: float = 2.0, **options):
        """Animate mode ``k`` (see :meth:`mode_trajectory`) with :func:`kronlag.animation.animate`;
        ``options`` go to ``animate`` (``fps``, ``duration``, ``width``, ...)."""
        from .animation import animate

        return animate(self.mode_trajectory(k, amplitude=amplitude, periods=periods), path, **options)


def independent_coordinates(Phi_q: np.ndarray, names: Sequence[str]) -> tuple[list[int], list[int]]:
    """``(independent, dependent)`` coordinate indices from a column-pivoted QR of ``Phi_q`` (r, m).

    The first ``rank`` pivot columns (the best conditioned) are the dependent
    coordinates; the others, in their original order, the independent ones.
    """
    m = len(names)
    if Phi_q.shape[0] == 0:
        return list(range(m)), []
    _, R, pivots = scipy.linalg.qr(Phi_q, pivoting=True, mode="economic")
    diagonal = np.abs(np.diag(R))
    rank = int(np.count_nonzero(diagonal > codegen.RANK_RTOL * diagonal[0])) if diagonal[0] > 0 else 0
    dependent = sorted(int(i) for i in pivots[:rank])
    return [i for i in range(m) if i not in dependent], dependent


def linearize(model: NumericModel, q, qd=None, *, t: float = 0.0, independent: Sequence | None = None,
              inputs: Sequence = (), outputs: Sequence = ()) -> LinearModel:
    """Linearize the constrained motion about ``(q, qd)`` (an equilibrium or a point of a trajectory).

    See :mod:`kronlag.analysis` for the equations: ``M_r dzdd + D_r dzd + K_r dz
    = R^T B_u du`` in the independent coordinates ``z``, as the state space
    ``x = [dz; dzd]``::

        A = [[0, I], [-M_r^-1 K_r, -M_r^-1 D_r]],   B = [[0], [M_r^-1 R^T B_u]]

    The operating point's accelerations and multipliers come from
    :meth:`~kronlag.numeric.NumericModel.forward_dynamics`.

    Parameters
    ----------
    model : NumericModel
        With holonomic, time-independent constraints only (s = 0, no drives).
    q : (m,)
        Must satisfy ``Phi(q) = 0`` (assemble it first).
    qd : (m,), optional
        Zero by default; must satisfy ``Phi_q qd = 0``.
    t : float
    independent : sequence of coordinate names, optional
        The independent coordinates ``z`` (``m - rank(Phi_q)`` of them);
        chosen by a column-pivoted QR of ``Phi_q`` when omitted.
    inputs : sequence of str
        Each a parameter name entering ``f_Q`` (e.g. a torque ``tau``; column
        ``d f_Q/d p``) or a coordinate name (a generalized force on it).
    outputs : sequence of str or SymPy expressions
        Each a coordinate name (``dq_i``), a speed name (``q1d``: ``dqd_i``) or an
        expression of the coordinates and parameters (a point's coordinate, say;
        ``dy = (dy/dq) R dz``, named ``str(expression)``); all m coordinates when empty.

    Returns
    -------
    LinearModel
    """
    if model.equations.rheonomic:
        raise ValueError(f"linearize: {model.equations.system.name} has time-dependent constraints (drives), so its "
                         "motion about a point is not that of a fixed linear system; linearize the model without "
                         "the drives, with the driven coordinates among the inputs")
    functions = _tangent(model)
    m, r = model.m, model.r
    q = model._vector(q, "q")
    qd = np.zeros(m) if qd is None else model._vector(qd, "qd")
    p = model.parameter_vector(t)
    zeros = np.zeros(m)
    Phi = functions("Phi", t, q, zeros, zeros, np.zeros(r), p)[:, 0]
    Phi_q = functions("Phi_q", t, q, zeros, zeros, np.zeros(r), p)
    scale = max(1.0, float(np.max(np.abs(Phi_q)))) if r else 1.0
    if r and (np.max(np.abs(Phi)) > 1e-8 or np.max(np.abs(Phi_q @ qd)) > 1e-8 * scale * max(1.0, np.max(np.abs(qd)))):
        raise ValueError(f"the operating point is not on the constraint manifold: max |Phi(q)| = "
                         f"{np.max(np.abs(Phi)):.3g}, max |Phi_q qd| = {np.max(np.abs(Phi_q @ qd)):.3g}; "
                         "use model.assemble or model.equilibrium first")
    names = model.coordinate_names
    chosen, dependent = independent_coordinates(Phi_q, names)
    if independent is not None:
        chosen = sorted(_names(list(independent), model._coordinate_index, "independent coordinate(s)"))
        dependent = [i for i in range(m) if i not in chosen]
        rank = np.linalg.matrix_rank(Phi_q) if r else 0
        if len(chosen) != m - rank or (r and np.linalg.matrix_rank(Phi_q[:, dependent]) != rank):
            raise ValueError(f"independent coordinates {[names[i] for i in chosen]} do not parametrize the "
                             f"constraint manifold at q: need {m - rank} coordinates whose complement "
                             f"{[names[i] for i in dependent]} has Phi_q columns of full rank {rank}")
    n = len(chosen)
    selection = np.zeros((m, n))
    selection[chosen, range(n)] = 1.0
    solve = np.zeros((m, r))
    if r:
        solve[dependent] = np.linalg.pinv(Phi_q[:, dependent], rcond=codegen.RANK_RTOL)
    R = (np.eye(m) - solve @ Phi_q) @ selection
    dynamics = model.forward_dynamics(q, qd, t)
    qdd, lam = dynamics.qdd, dynamics.lam

    def evaluate(name):
        return functions(name, t, q, qd, qdd, lam, p)

    M, K, H_qd = evaluate("M"), evaluate("K"), evaluate("H_qd")
    gamma_q, gamma_qd, V, W = (evaluate(name) for name in ("gamma_q", "gamma_qd", "V", "W"))
    mass, damping, stiffness = _reduced(R, solve, M, K, H_qd, gamma_q, gamma_qd, V, W)
    velocity_offset = solve @ V  # dqd = R dzd - velocity_offset dq
    input_forces = _input_directions(model, functions("f_Q_p", t, q, qd, qdd, lam, p), inputs)
    inverse_mass = np.linalg.inv(mass)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-inverse_mass @ stiffness, -inverse_mass @ damping]])
    B = np.vstack([np.zeros((n, len(inputs))), inverse_mass @ R.T @ input_forces])
    outputs = tuple(outputs) or names
    C = _output_rows(model, R, velocity_offset @ R, outputs, q, p)
    output_names = tuple(str(output) for output in outputs)
    return LinearModel(A, B, C, np.zeros((len(output_names), len(inputs))), tuple(names[i] for i in chosen),
                       tuple(inputs), output_names, mass, damping, stiffness, R, q, qd, lam, t, model)


def _reduced(R, solve, M, K, H_qd, gamma_q, gamma_qd, V, W):
    """``(M_r, D_r, K_r)`` of the module docstring (NumPy arrays or SymPy matrices alike)."""
    velocity_offset = solve @ V
    mass = R.T @ M @ R
    damping = R.T @ (H_qd + M @ solve @ gamma_qd) @ R
    stiffness = R.T @ (K + M @ solve @ (gamma_q - gamma_qd @ velocity_offset - W) - H_qd @ velocity_offset) @ R
    return mass, damping, stiffness


def symbolic_linearization(equations: Equations, independent: Sequence) -> dict[str, sp.Matrix]:
    """``M_r``, ``D_r``, ``K_r`` (n, n) and ``R`` (m, n) as SymPy matrices, for the independent
    coordinates ``independent`` (names), by the formulas of the module docstring.

    The entries are expressions of ``q``, ``qd``, ``qdd`` (``equations.accelerations``),
    ``lambda`` (``equations.lambdas``), the parameters and ``t``: substitute an operating point
    (at an equilibrium ``qd = qdd = 0``).  The dependent coordinates are solved with the
    symbolic inverse of their ``Phi_q`` columns (r of them: the constraints must be independent),
    so the expressions grow quickly with r; :func:`linearize` is the numeric route.
    """
    eq = equations
    m, r, s = eq.shape
    if s:
        raise NotImplementedError(f"{eq.system.name}: linearization supports holonomic constraints only")
    names = [q.name for q in eq.coordinates]
    unknown = [name for name in independent if name not in names]
    if unknown or len(set(independent)) != m - r:
        raise ValueError(f"independent coordinates {list(independent)}: expected {m - r} distinct names "
                         f"among {', '.join(names)}")
    chosen = [names.index(name) for name in independent]
    dependent = [i for i in range(m) if i not in chosen]
    selection = sp.zeros(m, m - r)
    for column, i in enumerate(chosen):
        selection[i, column] = 1
    solve = sp.zeros(m, r)
    if r:
        block = eq.Phi_q[:, dependent]
        if block.det() == 0:
            raise ValueError(f"the Phi_q columns of {[names[i] for i in dependent]} are singular: "
                             "choose other independent coordinates")
        inverse = block.inv()
        for row, i in enumerate(dependent):
            solve[i, :] = inverse[row, :]
    R = (sp.eye(m) - solve * eq.Phi_q) * selection
    tangent = tangent_matrices(eq)
    matrices = [sp.Matrix(x) for x in (eq.M, tangent["K"], tangent["H_qd"], tangent["gamma_q"],
                                       tangent["gamma_qd"], tangent["V"], tangent["W"])]
    mass, damping, stiffness = _reduced(R, solve, *matrices)
    return {"M_r": mass, "D_r": damping, "K_r": stiffness, "R": R}


def _input_directions(model: NumericModel, f_Q_p: np.ndarray, inputs: Sequence[str]) -> np.ndarray:
    """``B_u`` (m, k): column ``d f_Q/d p`` of a parameter input, a unit vector of a coordinate input."""
    parameters = {name: j for j, name in enumerate(model.parameter_names)}
    columns = []
    for name in inputs:
        if name in parameters:
            columns.append(f_Q_p[:, parameters[name]])
        elif name in model._coordinate_index:
            columns.append(np.eye(model.m)[model._coordinate_index[name]])
        else:
            raise ValueError(f"unknown input {name!r}: expected a parameter entering f_Q "
                             f"({', '.join(model.parameter_names)}) or a coordinate ({', '.join(model.coordinate_names)})")
    return np.column_stack(columns) if columns else np.zeros((model.m, 0))


def _output_rows(model: NumericModel, R: np.ndarray, speed_from_position: np.ndarray, outputs: Sequence,
                 q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``C`` (l, 2n): ``dq_i = R_i dz`` for a coordinate, ``dqd_i = R_i dzd - (P V R)_i dz`` for a
    speed, ``dy = (dy/dq) R dz`` for an expression ``y(q, p)`` (e.g. a coordinate of a point)."""
    index = model._coordinate_index
    speeds = {f"{name}d": i for name, i in index.items()}
    eq = model.equations
    rows = []
    for output in outputs:
        if isinstance(output, sp.Expr):
            unknown = output.free_symbols - set(eq.coordinates) - set(eq.parameters)
            if unknown:
                raise ValueError(f"output {output}: only coordinates and parameters may appear, not "
                                 f"{', '.join(sorted(map(str, unknown)))}")
            gradient = sp.lambdify([list(eq.coordinates), list(eq.parameters)],
                                   sp.Matrix([output]).jacobian(eq.coordinates), modules="numpy")
            slope = np.array(gradient(q, p), dtype=float).reshape(model.m)
            rows.append(np.concatenate([slope @ R, np.zeros(R.shape[1])]))
        elif output in index:
            rows.append(np.concatenate([R[index[output]], np.zeros(R.shape[1])]))
        elif output in speeds:
            i = speeds[output]
            rows.append(np.concatenate([-speed_from_position[i], R[i]]))
        else:
            raise ValueError(f"unknown output {output!r}: expected a coordinate ({', '.join(index)}), "
                             f"a speed ({', '.join(speeds)}) or a SymPy expression of the coordinates")
    return np.array(rows).reshape(len(rows), 2 * R.shape[1])
