"""Linearization of the constrained motion about a state on the constraint manifold.

:func:`linearize` linearizes the motion about a state ``(q0, qd0)`` on the
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
:class:`~kronlag.symbolic.equations.Equations` (:func:`~kronlag.studies.tangent.tangent_matrices`) and
evaluated by the model's kernels with its parameter values.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg
import sympy as sp

from ..core.errors import InputError
from ..numeric.friction import friction_joints
from ..numeric.linalg import pseudo_inverses
from ..numeric.tolerances import RANK_RTOL, matrix_rank, numerical_rank, zero_eigenvalue_threshold
from ..simulation.trajectory import Result, Trajectory
from .tangent import TangentEvaluator, tangent_matrices

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel
    from ..symbolic.equations import Equations

__all__ = ["LinearModel", "linearize", "symbolic_linearization", "independent_coordinates"]


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
    eigenvalue_scale : float
        ``max |K| / max |M|`` of the unreduced matrices (1/s^2): the scale against which an
        eigenvalue ``w^2`` is zero within rounding (:func:`kronlag.numeric.tolerances.zero_eigenvalue_threshold`).
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
    eigenvalue_scale: float = 0.0

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

        ``0`` for a neutral mode, whose ``w^2`` is zero within rounding (:attr:`neutral`);
        ``nan`` for a negative ``w^2`` beyond that (an unstable direction; see ``stiffness``).
        """
        values, _ = self._modes()
        with np.errstate(invalid="ignore"):
            return np.where(self.neutral, 0.0, np.where(values > 0, np.sqrt(np.abs(values)), np.nan))

    @property
    def neutral_threshold(self) -> float:
        """The largest ``|w^2|`` (rad^2/s^2) that is zero within rounding:
        :data:`~kronlag.numeric.tolerances.ZERO_EIGENVALUE_RTOL` times ``max(eigenvalue_scale, max |w^2|)``."""
        return zero_eigenvalue_threshold(self._modes()[0], self.eigenvalue_scale)

    @property
    def neutral(self) -> np.ndarray:
        """Which modes are neutral, ``|w^2| <= neutral_threshold`` (in the order of ``natural_frequencies``)."""
        return np.abs(self._modes()[0]) <= self.neutral_threshold

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

    def mode_shape(self, k: int) -> dict[str, float]:
        """Mode ``k``'s shape (column ``k`` of :attr:`mode_shapes`) by coordinate name."""
        return dict(zip(self.model.coordinate_names, self.mode_shapes[:, k].tolist()))

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
        model, frequency = self.model, self.natural_frequencies[k]
        if not np.isfinite(frequency) or frequency <= 0:
            raise InputError(f"mode {k} has no oscillation (w^2 <= 0); natural frequencies: "
                             f"{self.natural_frequencies.tolist()}")
        shape = self.mode_shapes[:, k]
        times = np.linspace(0.0, periods * 2 * np.pi / frequency, samples)
        q = np.empty((samples, model.m))
        guess = self.q.copy()
        for index, time in enumerate(times):
            target = self.q + amplitude * shape * np.sin(frequency * time)
            held = {name: target[model.coordinate_names.index(name)] for name in self.coordinates}
            guess, _ = model.assemble(target, fixed=held, t=self.t)
            q[index] = guess
        qd = np.gradient(q, times, axis=0)
        zeros, no_multipliers = np.zeros(samples), np.zeros((samples, model.r))
        return Trajectory(t=times, q=q, qd=qd, qdd=np.gradient(qd, times, axis=0), lam=no_multipliers,
                          mu=np.zeros((samples, model.s)), kinetic_energy=zeros, potential_energy=zeros,
                          position_residual=no_multipliers, velocity_residual=np.zeros((samples, model.r + model.s)),
                          coordinate_names=model.coordinate_names, model=model, method=f"mode {k}",
                          message=f"mode {k}: {frequency:.6g} rad/s", nfev=0, njev=0, steps=0, wall_time=0.0,
                          result=Result.SUCCESS)

    def animate_mode(self, k: int, path: str | PathLike | None = None, *, amplitude: float = 0.1,
                     periods: float = 2.0, **options):
        """Animate mode ``k`` (see :meth:`mode_trajectory`) with :func:`kronlag.animation.animate`;
        ``options`` go to ``animate`` (``fps``, ``duration``, ``width``, ...)."""
        from ..views.animation import animate  # a convenience above this layer (the layer contract)

        return animate(self.mode_trajectory(k, amplitude=amplitude, periods=periods), path, **options)


def independent_coordinates(Phi_q: np.ndarray, names: Sequence[str], *,
                            rank_rtol: float = RANK_RTOL) -> tuple[list[int], list[int]]:
    """``(independent, dependent)`` coordinate indices from a column-pivoted QR of ``Phi_q`` (r, m).

    The first ``rank`` pivot columns (the best conditioned) are the dependent
    coordinates; the others, in their original order, the independent ones (the rank
    by :func:`kronlag.numeric.tolerances.numerical_rank`).
    """
    m = len(names)
    if Phi_q.shape[0] == 0:
        return list(range(m)), []
    _, R, pivots = scipy.linalg.qr(Phi_q, pivoting=True, mode="economic")
    rank = numerical_rank(np.diag(R), rank_rtol)
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
    if friction_joints(model.equations.system):
        raise InputError(f"linearize: {model.equations.system.name} has joint friction, which the linearization "
                         "does not include")
    if model.equations.rheonomic:
        raise InputError(f"linearize: {model.equations.system.name} has time-dependent constraints (drives), so its "
                         "motion about a point is not that of a fixed linear system; linearize the model without "
                         "the drives, with the driven coordinates among the inputs")
    m, r = model.m, model.r
    q = model.state_vector(q, "q")
    qd = np.zeros(m) if qd is None else model.state_vector(qd, "qd")
    evaluate_at = TangentEvaluator(model, "linearization",
                                   ("M", "K", "H_qd", "gamma_q", "gamma_qd", "V", "W", "f_Q_p", "Phi", "Phi_q"))
    terms = model.dynamics_terms(q, np.zeros(m), t)
    Phi, Phi_q = terms["Phi"], terms["Phi_q"]
    scale = max(1.0, float(np.max(np.abs(Phi_q)))) if r else 1.0
    if r and (np.max(np.abs(Phi)) > 1e-8 or np.max(np.abs(Phi_q @ qd)) > 1e-8 * scale * max(1.0, np.max(np.abs(qd)))):
        raise InputError(f"the operating point is not on the constraint manifold: max |Phi(q)| = "
                         f"{np.max(np.abs(Phi)):.3g}, max |Phi_q qd| = {np.max(np.abs(Phi_q @ qd)):.3g}; "
                         "use model.assemble or model.equilibrium first")
    names = model.coordinate_names
    chosen, dependent = independent_coordinates(Phi_q, names, rank_rtol=model.rank_rtol)
    if independent is not None:
        chosen = sorted(model.coordinate_indices(list(independent)))
        dependent = [i for i in range(m) if i not in chosen]
        rank = matrix_rank(Phi_q, model.rank_rtol)
        if len(chosen) != m - rank or (r and matrix_rank(Phi_q[:, dependent], model.rank_rtol) != rank):
            raise InputError(f"independent coordinates {[names[i] for i in chosen]} do not parametrize the "
                             f"constraint manifold at q: need {m - rank} coordinates whose complement "
                             f"{[names[i] for i in dependent]} has Phi_q columns of full rank {rank}")
    n = len(chosen)
    selection = np.zeros((m, n))
    selection[chosen, range(n)] = 1.0
    solve = np.zeros((m, r))
    if r:
        solve[dependent] = pseudo_inverses(Phi_q[None, :, dependent], model.rank_rtol)[0][0]
    R = (np.eye(m) - solve @ Phi_q) @ selection
    dynamics = model.forward_dynamics(q, qd, t)
    qdd, lam = dynamics.qdd, dynamics.lam

    values = evaluate_at(t, q, qd, qdd, lam)
    M, K, H_qd = values["M"], values["K"], values["H_qd"]
    gamma_q, gamma_qd, V, W = (values[name] for name in ("gamma_q", "gamma_qd", "V", "W"))
    mass, damping, stiffness = _reduced(R, solve, M, K, H_qd, gamma_q, gamma_qd, V, W)
    velocity_offset = solve @ V  # dqd = R dzd - velocity_offset dq
    input_forces = _input_directions(model, values["f_Q_p"], inputs)
    inverse_mass = np.linalg.inv(mass)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-inverse_mass @ stiffness, -inverse_mass @ damping]])
    B = np.vstack([np.zeros((n, len(inputs))), inverse_mass @ R.T @ input_forces])
    outputs = tuple(outputs) or names
    C = _output_rows(model, R, velocity_offset @ R, outputs, q, t)
    output_names = tuple(str(output) for output in outputs)
    eigenvalue_scale = float(np.max(np.abs(K), initial=0.0)) / max(float(np.max(np.abs(M), initial=0.0)), 1e-300)
    return LinearModel(A, B, C, np.zeros((len(output_names), len(inputs))), tuple(names[i] for i in chosen),
                       tuple(inputs), output_names, mass, damping, stiffness, R, q, qd, lam, t, model,
                       eigenvalue_scale)


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
        raise InputError(f"independent coordinates {list(independent)}: expected {m - r} distinct names "
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
            raise InputError(f"the Phi_q columns of {[names[i] for i in dependent]} are singular: "
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
        elif name in model.coordinate_names:
            columns.append(np.eye(model.m)[model.coordinate_names.index(name)])
        else:
            raise InputError(f"unknown input {name!r}: expected a parameter entering f_Q "
                             f"({', '.join(model.parameter_names)}) or a coordinate ({', '.join(model.coordinate_names)})")
    return np.column_stack(columns) if columns else np.zeros((model.m, 0))


def _output_rows(model: NumericModel, R: np.ndarray, speed_from_position: np.ndarray, outputs: Sequence,
                 q: np.ndarray, t: float) -> np.ndarray:
    """``C`` (l, 2n): ``dq_i = R_i dz`` for a coordinate, ``dqd_i = R_i dzd - (P V R)_i dz`` for a
    speed, ``dy = (dy/dq) R dz`` for an expression ``y(q, p)`` (e.g. a coordinate of a point)."""
    index = dict(zip(model.coordinate_names, range(model.m)))
    speeds = {f"{name}d": i for name, i in index.items()}
    eq = model.equations
    rows = []
    for output in outputs:
        if isinstance(output, sp.Expr):
            unknown = output.free_symbols - set(eq.coordinates) - set(eq.parameters)
            if unknown:
                raise InputError(f"output {output}: only coordinates and parameters may appear, not "
                                 f"{', '.join(sorted(map(str, unknown)))}")
            slope = model.evaluate_expressions(f"output:{output}",
                                               lambda: {"slope": sp.Matrix([output]).jacobian(eq.coordinates)},
                                               q, t=t)["slope"].reshape(model.m)
            rows.append(np.concatenate([slope @ R, np.zeros(R.shape[1])]))
        elif output in index:
            rows.append(np.concatenate([R[index[output]], np.zeros(R.shape[1])]))
        elif output in speeds:
            i = speeds[output]
            rows.append(np.concatenate([-speed_from_position[i], R[i]]))
        else:
            raise InputError(f"unknown output {output!r}: expected a coordinate ({', '.join(index)}), "
                             f"a speed ({', '.join(speeds)}) or a SymPy expression of the coordinates")
    return np.array(rows).reshape(len(rows), 2 * R.shape[1])
