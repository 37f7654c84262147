"""The ``"python"`` backend: kernels as generated Python functions, no compiler needed."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from ...core.errors import InputError
from ...core.kernels import ARRAY_NAMESPACE, SCALAR_NAMESPACE, Kernel, python_functions, python_source
from ..linalg import solve_augmented
from ..results import ForwardDynamicsResult, forward_dynamics_outcome
from ..tolerances import RANK_RTOL
from ..friction import solve_with_friction
from .layouts import dynamics_shape, layout, split_terms

__all__ = ["KernelLibrary", "PythonLibrary", "solve_dynamics_terms"]


def solve_dynamics_terms(kernel: Kernel, flat: np.ndarray, qd: np.ndarray, alpha: float,
                         beta: float, *, rank_rtol: float = RANK_RTOL) -> tuple:
    """Forward dynamics from the flat output of the ``"dynamics"`` kernel with :func:`solve_augmented`.

    Returns ``(qdd, lam, mu, rank)``, or ``(None, None, None, -1)`` at a singular configuration:
    the Python backend's twin of ``kronlag_forward_dynamics_packed`` in ``numeric/codegen/c/augmented.c``.
    """
    terms = split_terms(dynamics_shape(kernel), flat)
    r = len(terms["Phi"])
    G = np.vstack([terms["Phi_q"], terms["A"]])
    c = np.concatenate([terms["gamma"] - 2 * alpha * (terms["Phi_q"] @ qd + terms["Phi_t"]) - beta ** 2 * terms["Phi"],
                        terms["gamma_nh"] - alpha * (terms["A"] @ qd + terms["b"])])
    solution = solve_augmented(terms["M"], terms["h"], G, c, rank_rtol=rank_rtol)
    if solution is None:
        return None, None, None, -1
    qdd, nu, rank = solution
    return qdd, nu[:r], nu[r:], rank



def _vector(value, n: int, what: str) -> np.ndarray:
    """``value`` as a float64 vector of length ``n``; ValueError naming ``what`` otherwise."""
    vector = np.ascontiguousarray(value, dtype=float)
    if vector.shape != (n,):
        raise InputError(f"{what} must have shape ({n},), got {vector.shape}")
    return vector


class KernelLibrary(Protocol):
    """What :class:`~kronlag.numeric.NumericModel` needs from a backend (see ``codegen.BACKENDS``).

    Inputs: ``t`` float, ``q``/``qd`` (m,), ``p`` (P,); batched: ``t`` (N,), ``q``/``qd`` (N, m),
    ``p`` (N, P) or (P,) for all states.
    """

    kernels: dict[str, Kernel]
    source: str

    def evaluator(self, name: str, shape: tuple[int, ...]) -> Callable[..., np.ndarray]:
        """``f(t, q, qd, p)`` -> the output of kernel ``name`` shaped ``shape`` (``qd`` may be None)."""

    def evaluate_batch(self, name: str, t: np.ndarray, q: np.ndarray, qd: np.ndarray | None,
                       p: np.ndarray) -> np.ndarray:
        """(N, size): the flat output of kernel ``name`` at every state."""

    def forward_dynamics_function(self) -> Callable[..., ForwardDynamicsResult | int]:
        """``f(t, q, qd, p, alpha, beta)`` -> a :class:`ForwardDynamicsResult`, or its rank alone when that
        marks a failure (-1 singular, -2 the joints' friction did not converge)."""

    def forward_dynamics_batch(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, p: np.ndarray,
                               alpha: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
        """``(out (N, m + r + s) = [qdd, lam, mu], rank (N,))``; rank -1 marks a singular state."""


class PythonLibrary:
    """Kernels as generated Python functions, no compiler needed (:class:`KernelLibrary`).

    One state runs on floats with :mod:`math`; a batch of states runs the same
    source on NumPy arrays, vectorised over the states.  Forward dynamics solves
    the output of the ``"dynamics"`` kernel with
    :func:`solve_dynamics_terms`.
    """

    def __init__(self, kernels: Sequence[Kernel], *, m: int, n_parameters: int, rank_rtol: float = RANK_RTOL):
        self.kernels = {kernel.name: kernel for kernel in kernels}
        self.m, self.n_parameters, self.rank_rtol = m, n_parameters, rank_rtol
        self.source = "\n\n".join(python_source(kernel) for kernel in kernels)
        self.scalar = python_functions(self.source, list(self.kernels), SCALAR_NAMESPACE)
        self.vectorised = python_functions(self.source, list(self.kernels), ARRAY_NAMESPACE)

    def evaluator(self, name: str, shape: tuple[int, ...]) -> Callable[..., np.ndarray]:
        return functools.partial(self._evaluate, self.scalar[name], shape)

    def _evaluate(self, function: Callable, shape: tuple[int, ...], t: float, q, qd, p: np.ndarray) -> np.ndarray:
        q = _vector(q, self.m, "q").tolist()
        qd = [0.0] * self.m if qd is None else _vector(qd, self.m, "qd").tolist()
        return np.array(function(float(t), q, qd, p.tolist()), dtype=float).reshape(shape)

    def evaluate_batch(self, name: str, t: np.ndarray, q: np.ndarray, qd: np.ndarray | None,
                       p: np.ndarray) -> np.ndarray:
        n = len(q)
        qd = np.zeros_like(q) if qd is None else qd
        parameters = p.T if p.ndim == 2 else p
        values = self.vectorised[name](t, q.T, qd.T, parameters)
        out = np.empty((self.kernels[name].size, n))
        for row, value in zip(out, values):
            row[...] = value
        return out.T.copy()

    def forward_dynamics_function(self) -> Callable[..., ForwardDynamicsResult | int]:
        return self._forward_dynamics

    def _forward_dynamics(self, t: float, q, qd, p: np.ndarray, alpha: float,
                          beta: float) -> ForwardDynamicsResult | int:
        qd = _vector(qd, self.m, "qd")
        kernel = self.kernels["dynamics"]
        flat = self._evaluate(self.scalar[kernel.name], (kernel.size,), t, q, qd, p)
        return forward_dynamics_outcome(*self._solve(flat, t, q, qd, p, alpha, beta))

    def _solve(self, flat: np.ndarray, t: float, q, qd: np.ndarray, p: np.ndarray, alpha: float,
               beta: float) -> tuple:
        """Forward dynamics from the dynamics kernel's output, with the joints' friction if any."""
        kernel = self.kernels["dynamics"]

        def solve(terms: np.ndarray) -> tuple:
            return solve_dynamics_terms(kernel, terms, qd, alpha, beta, rank_rtol=self.rank_rtol)

        if "friction" not in self.kernels:
            return solve(flat)
        records = self._evaluate(self.scalar["friction"], (self.kernels["friction"].size,), t, q, qd, p)
        h_offset = dict((name, offset) for name, offset, _ in layout("dynamics", *dynamics_shape(kernel)))["h"]
        return solve_with_friction(solve, flat, h_offset, records, qd)

    def forward_dynamics_batch(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, p: np.ndarray,
                               alpha: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
        kernel = self.kernels["dynamics"]
        terms = self.evaluate_batch(kernel.name, t, q, qd, p)
        out = np.full((len(q), sum(dynamics_shape(kernel))), np.nan)
        ranks = np.empty(len(q), dtype=np.int32)
        times = np.broadcast_to(t, len(q))
        for i, (row, velocity) in enumerate(zip(terms, qd)):
            parameters = p[i] if p.ndim == 2 else p
            qdd, lam, mu, ranks[i] = self._solve(row, float(times[i]), q[i], velocity, parameters, alpha, beta)
            if ranks[i] >= 0:
                out[i] = np.concatenate([qdd, lam, mu])
        return out, ranks

