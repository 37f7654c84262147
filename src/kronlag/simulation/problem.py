"""The problem and the solution of a time integration, and the interface every solver implements.

The layout follows ``scipy.integrate`` and diffrax: a :class:`MultibodyProblem`
(the model, the time span, the initial state), a :class:`Solver` class per method
(each declares its formulation and order; :mod:`kronlag.simulation.solvers`) and a
:class:`Solution` of raw states are separate types joined by one driver,
:func:`kronlag.simulation.simulate`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..core.errors import ProjectionError
from ..numeric.projection import project_positions, project_velocities
from ..numeric.tolerances import integrator_tolerances
from .control import RunControl
from .energy import Segment
from .trajectory import MethodInterval, Result, SingularPassage
from .watch import LimitStop, LimitWatch

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel

__all__ = ["MultibodyProblem", "Solution", "SolverOptions", "Solver", "derived_shapes"]


@dataclass(frozen=True, eq=False)
class MultibodyProblem:
    """Initial-value problem for ``y = [q, qd]`` (length 2 m) on ``[t0, t1]``.

    Attributes
    ----------
    model : NumericModel
    t0, t1 : float
    q0, qd0 : (m,)
        Initial state (projected onto the constraints by :func:`simulate`).
    t_eval : (K,) or None
        Output times in ``[t0, t1]``, increasing; ``None``: every accepted step.
    alpha, beta : float
        Baumgarte parameters of :meth:`rhs`.
    """

    model: NumericModel
    t0: float
    t1: float
    q0: np.ndarray
    qd0: np.ndarray
    t_eval: np.ndarray | None
    alpha: float
    beta: float
    #: Limits: what this run watches (:mod:`.impacts` sets it; None: no limits).
    watch: LimitWatch | None = None

    @property
    def m(self) -> int:
        return self.model.m

    @property
    def y0(self) -> np.ndarray:
        """``[q0, qd0]``, shape (2 m,)."""
        return np.concatenate([self.q0, self.qd0])

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """Index-1 right-hand side ``[qd, qdd]`` with Baumgarte stabilization, shape (2 m,).

        ``qdd`` solves ``[[M, Phi_q^T, A^T], [Phi_q, 0, 0], [A, 0, 0]] [qdd; lam; mu] =
        [f_Q - C qd - g; gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi; gamma_nh - alpha (A qd + b)]``.
        """
        q, qd = y[:self.m], y[self.m:]
        result = self.model.forward_dynamics(q, qd, t, alpha=self.alpha, beta=self.beta)
        return np.concatenate([qd, result.qdd])

    def project(self, t: float, y: np.ndarray, tol: float) -> np.ndarray:
        """Project ``y = [q, qd]`` onto the constraint manifold, shape (2 m,).

        Positions by Gauss-Newton on ``Phi(q, t) = 0`` until ``max |Phi| <= tol`` or a step is at
        rounding level, then velocities onto ``B qd + c = 0`` with ``B = [Phi_q; A]`` (r + s, m)
        and ``c = [Phi_t; b]`` in one step (:mod:`kronlag.numeric.projection`, minimum-norm
        corrections over the independent rows: redundant constraints keep working).

        Raises
        ------
        ProjectionError
            If the Gauss-Newton iteration does not converge (the residual is in the error).
        """
        m = self.m
        positions = project_positions(self.model, y[:m], t, tol=tol)
        if not positions.accepted(tol):
            raise ProjectionError(f"the position projection did not converge at t = {t!r}, "
                                  f"q = {positions.q.tolist()}: max |Phi| = {positions.residual:.3g} after "
                                  f"{positions.iterations} Gauss-Newton steps (tol {tol:.3g})", positions.residual)
        return np.concatenate([positions.q, project_velocities(self.model, positions.q, y[m:], t,
                                                               terms=positions.terms)])


def derived_shapes(rows: int, m: int, r: int, s: int) -> dict[str, tuple[int, ...]]:
    """The quantities derived at ``rows`` outputs (:attr:`Solution.derived`) and their shapes, by name."""
    return {"qdd": (rows, m), "lam": (rows, r), "mu": (rows, s), "kinetic_energy": (rows,),
            "potential_energy": (rows,), "position_residual": (rows, r), "velocity_residual": (rows, r + s)}


@dataclass(frozen=True, eq=False)
class Solution:
    """Raw solver output: states ``y = [q, qd]`` at the output times.

    Attributes
    ----------
    t : (N,)
    y : (N, 2 m)
    result : Result
        How it ended (on failure ``t``, ``y`` hold what was computed before it).
    message : str
    nfev, njev, steps : int
        Right-hand-side or residual evaluations, Jacobian evaluations, accepted steps.
    derived : dict or None
        ``qdd`` (N, m), ``lam`` (N, r), ``mu`` (N, s), ``kinetic_energy`` (N,),
        ``potential_energy`` (N,), ``position_residual`` (N, r), ``velocity_residual``
        (N, r + s) at the outputs, when the solver computed them (else :func:`simulate` does).
    events : tuple of SingularPassage
        Singular configurations passed.
    stop : LimitStop or None
        Limits: where a run with a ``problem.watch`` ended at an event (``result`` :attr:`Result.LIMIT`).
    parameters : (N, P) or None
        Under a controller (:mod:`.controllers`), the parameter values at the outputs, when the
        solver recorded them (else :func:`simulate` does).
    intervals : tuple of MethodInterval
        Which integrator ran where, when the solver changes integrators (else :func:`simulate`
        records one interval of its method).
    turns : (n, 2 + 4 m) or None
        Exact stiction: the sliding directions the compiled driver turned itself at kinematic dead points
        (``kl_turn`` in ``c/cvode.c``), a row per joint turned: ``t``, the joint's index among those with
        friction, ``[q, qd]`` before and after the projection there; the outputs after a turn were computed
        with the turned directions (:mod:`.impacts` splits them into pieces).
    segments : tuple of Segment
        A run with events (limits, exact stiction): the model of each piece and its outputs
        (:class:`~.energy.Segment`); empty for a run of the problem's model throughout.
    """

    t: np.ndarray
    y: np.ndarray
    result: Result
    message: str
    nfev: int
    njev: int
    steps: int
    derived: dict[str, np.ndarray] | None = None
    events: tuple[SingularPassage, ...] = ()
    stop: LimitStop | None = None
    parameters: np.ndarray | None = None
    intervals: tuple[MethodInterval, ...] = ()
    segments: tuple[Segment, ...] = ()
    turns: np.ndarray | None = None

    #: The keys of :attr:`derived` (:func:`derived_shapes`).
    DERIVED: ClassVar[tuple[str, ...]] = tuple(derived_shapes(0, 0, 0, 0))

    @property
    def status(self) -> int:
        """0 success, -1 failure (``result.status``)."""
        return self.result.status


@dataclass(frozen=True)
class SolverOptions:
    """Options common to every solver (see :func:`simulate`).

    ``max_order`` caps the order of a variable-order method (None: it uses every order up to its
    :attr:`Solver.order`); :func:`simulate` leaves it None, a :class:`Solver` subclass may set it
    (the order tests do, to check each order).
    """

    rtol: float
    atol: float
    max_step: float
    max_steps: int
    progress: Callable[[float], object] | None
    max_order: int | None = None
    #: What ends the run early (Ctrl-C, an exception in a callback): every solver asks it after each
    #: accepted step (``control.report(progress, t)``, or the compiled drivers' ``progress``).
    control: RunControl = field(default_factory=RunControl)

    @property
    def projection_tol(self) -> float:
        """Residual tolerance of the position projection: ``atol / 100``."""
        return self.atol / 100

    def scaled(self, scale: float, tightest: tuple[float, float]) -> SolverOptions:
        """These options with ``rtol`` and ``atol`` both divided by ``scale``, neither below ``tightest``
        (:func:`kronlag.numeric.tolerances.integrator_tolerances`): what an integrator whose global
        error exceeds its local tolerance by about ``scale`` is given."""
        rtol, atol = integrator_tolerances(self.rtol, self.atol, scale, tightest)
        return replace(self, rtol=rtol, atol=atol)


class Solver(ABC):
    """A time-integration method for a :class:`MultibodyProblem`.

    Subclasses declare ``name``, ``formulation`` (the equations integrated), ``integrator``
    (the scheme, in words), ``order`` and, where they need more than any model,
    ``requirements`` and :meth:`supports`, and implement :meth:`solve`.  A subclass can be
    passed to :func:`simulate` as ``method`` (like scipy's ``solve_ivp`` takes an ``OdeSolver``).

    The order is a number: the global error of a fixed-order method falls like ``h^order``
    with the step ``h``.  A variable-order method (CVODE's Adams-Moulton, IDA's BDF, the
    switching method) chooses its order step by step between ``min_order`` and ``order`` (its
    highest); with its order capped at ``q`` (``SolverOptions.max_order``) its error falls like
    ``h^q``.  A class that declares ``order`` alone has a fixed order: ``min_order`` follows
    (``tests/test_solver_order.py`` checks every declaration).
    """

    name: ClassVar[str]
    formulation: ClassVar[str]
    #: The integration scheme and where it comes from, in words.
    integrator: ClassVar[str]
    #: The order of convergence; the highest order of a variable-order method.
    order: ClassVar[int]
    #: The lowest order a variable-order method uses (``order`` for a fixed-order method).
    min_order: ClassVar[int]
    #: What a model needs for this method (said when :meth:`supports` is False).
    requirements: ClassVar[str] = "nothing"
    #: Default Baumgarte ``alpha`` and ``beta`` of the index-1 ODE it integrates (0: none).
    stabilization: ClassVar[float] = 0.0
    #: It stops at the sample instants of a :class:`~kronlag.simulation.controllers.Sampled` controller
    #: itself (a compiled driver); else :func:`simulate` runs it from one sample instant to the next.
    samples_inside: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "order" in vars(cls) and "min_order" not in vars(cls):
            cls.min_order = cls.order

    @classmethod
    def variable_order(cls) -> bool:
        """Whether the method chooses its order between ``min_order`` and ``order``."""
        return cls.min_order < cls.order

    @staticmethod
    def supports(model: NumericModel) -> bool:
        """Whether the method can integrate ``model``."""
        return True

    def __init__(self, options: SolverOptions):
        self.options = options

    @abstractmethod
    def solve(self, problem: MultibodyProblem) -> Solution:
        """Integrate ``problem``; failures are reported in the solution, not raised."""

    def __repr__(self) -> str:
        orders = f"{self.min_order}-{self.order}" if self.variable_order() else f"{self.order}"
        return f"{type(self).__name__}(formulation={self.formulation!r}, order={orders}, {self.integrator})"
