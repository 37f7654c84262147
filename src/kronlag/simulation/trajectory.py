"""The result of :func:`kronlag.simulate`: a sampled solution of the equations of motion.

A :class:`Trajectory` holds, at every output time ``t[k]``, the state of::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0

with time along the first axis of every array, and exports it as columns.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from functools import cached_property
from os import PathLike
from typing import TYPE_CHECKING, Any

import numpy as np

from ..numeric.reactions import Reaction, joint_reaction, reaction_columns
from .energy import nonconservative_work

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel

__all__ = ["Trajectory", "SingularPassage", "Result"]


class Result(enum.Enum):
    """How an integration ended; the value is the message (``Trajectory.message`` adds where).

    ``status`` is 0 for :attr:`SUCCESS` and -1 for every other result.  :attr:`code` is the
    number a compiled driver returns for it, ``KRONLAG_RESULT_<NAME>`` in their C
    (:mod:`kronlag.simulation.interface` prints the macros from this enum): 0 for success,
    positive for a segment that ends to hand over to the other method of the switching solver,
    negative for a failure.  The failure codes lie below -999, apart from the flags of
    SUNDIALS CVODE (-1 to -99), which :meth:`of_code` reads as :attr:`SOLVER_FAILED`.

    :attr:`INTERRUPTED` (Ctrl-C) and :attr:`RAISED` end a run that :func:`kronlag.simulate` does
    not return: it raises (:class:`KeyboardInterrupt`, or the callback's exception) with the
    partial trajectory as the exception's attribute ``trajectory``.
    """

    SUCCESS = 0, "The integration reached the end of the time span."
    MAX_STEPS = -1001, "reached the maximum number of steps"
    APPROACH = 2, ("the motion approaches a singular configuration (Phi_q nearly loses rank), where an "
                   "index-1 formulation cannot tell the branches of the motion apart; method='ali3p' or "
                   "'switching' (the default) passes it")
    SINGULAR = -1003, ("singular configuration: M is not positive definite on the null space of [Phi_q; A], "
                       "the accelerations are not determined (e.g. Euler angles at gimbal lock)")
    STEP_TOO_SMALL = -1004, "the step size fell below the smallest step (error test failures)"
    NEWTON_FAILED = -1005, "Newton's method did not converge at the smallest step"
    PROJECTION_FAILED = -1002, "the projection onto the constraints failed"
    OUTPUTS_FULL = -1006, "more steps than output rows: pass t_eval to choose the outputs"
    INTERRUPTED = -1007, "interrupted (Ctrl-C, SIGINT)"
    RAISED = -1008, "a callback (a controller, a time-varying parameter or progress) raised an exception"
    SOLVER_FAILED = -1000, "the integrator failed"

    code: int

    def __new__(cls, code: int, message: str) -> Result:
        member = object.__new__(cls)
        member._value_ = message
        member.code = code
        return member

    @property
    def status(self) -> int:
        """0 for success, -1 otherwise."""
        return 0 if self is Result.SUCCESS else -1

    @classmethod
    def of_code(cls, code: int) -> Result:
        """The result a compiled driver's return ``code`` stands for (:attr:`SOLVER_FAILED` for a
        code that is no member's, such as CVODE's own flags)."""
        return next((member for member in cls if member.code == code), cls.SOLVER_FAILED)


@dataclass(frozen=True)
class SingularPassage:
    """A passage of the motion through or near a singular configuration, where the constraint
    Jacobian ``Phi_q`` (nearly) loses rank at an instant (see :mod:`kronlag.tolerances`).

    Attributes
    ----------
    t : float
        Time of the closest approach (the smallest ``ratio``).
    t_enter, t_exit : float
        The accepted steps just before and after the closest approach.
    q : (m,)
        Coordinates at ``t``.
    ratio : float
        Smallest ``sigma_rho / sigma_1`` of ``Phi_q`` seen (``rho``: the rank at the start).
    constraints : tuple of str
        The constraints whose rows become dependent there (the rows with a large entry in the
        left singular vector of ``Phi_q`` that belongs to ``sigma_rho``).
    """

    t: float
    t_enter: float
    t_exit: float
    q: np.ndarray
    ratio: float
    constraints: tuple[str, ...]

    def __str__(self) -> str:
        return (f"singular configuration at t = {self.t:.6g} (sigma ratio {self.ratio:.2g}; constraints "
                f"{', '.join(self.constraints)}), q = {np.array2string(self.q, precision=6)}")


class ColumnExport:
    """Export of a result to files: a subclass defines ``columns()`` (named arrays of shape (N,))
    and ``_metadata()`` (the run's message and counters)."""

    def to_csv(self, path: str | PathLike) -> None:
        """Write the columns to a comma-separated file with a one-line header of column names."""
        columns = self.columns()
        data = np.column_stack(list(columns.values())) if columns else np.zeros((0, 0))
        np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.17g")

    def to_npz(self, path: str | PathLike) -> None:
        """Write the columns and the run's metadata (``message``, ...) to a NumPy ``.npz`` archive."""
        np.savez(path, **self.columns(), **{key: np.asarray(value) for key, value in self._metadata().items()})

    def to_dataframe(self):
        """The columns as a :class:`pandas.DataFrame` (needs pandas)."""
        try:
            import pandas as pd
        except ImportError as error:
            raise ImportError(f"{type(self).__name__}.to_dataframe needs pandas: pip install pandas "
                              "(or kronlag[dataframe])") from error
        return pd.DataFrame(self.columns())


@dataclass(frozen=True, eq=False)
class Trajectory(ColumnExport):
    """Solution of the equations of motion at the output times (``N = len(t)``).

    Units are those of the model's parameters (SI if the user's are SI).

    Attributes
    ----------
    t : (N,)
        Output times.
    q, qd, qdd : (N, m)
        Coordinates, velocities and accelerations; ``qdd`` is recomputed at
        ``t`` by ``model.forward_dynamics(q, qd, t)`` (no Baumgarte terms).
    lam : (N, r)
        Holonomic multipliers ``lambda`` at ``t`` (same computation).
    mu : (N, s)
        Nonholonomic multipliers ``mu`` at ``t``.
    kinetic_energy, potential_energy : (N,)
        ``T = 1/2 qd^T M qd`` and ``Pi(q)``.
    position_residual : (N, r)
        ``Phi(q)``.
    velocity_residual : (N, r + s)
        ``[Phi_q qd; A qd + b]``.
    coordinate_names : tuple of str
        Names of ``q`` (length m).
    model : NumericModel
        The model that was integrated.
    method : str
        ``name`` of the :class:`~kronlag.simulation.Solver` that produced the trajectory.
    message : str
        Solver report.
    nfev, njev, steps : int
        Right-hand-side (or residual) evaluations, Jacobian evaluations and
        accepted steps.
    wall_time : float
        Seconds spent in :func:`kronlag.simulate`.
    events : tuple of SingularPassage
        Passages through or near singular configurations, in time order.
    result : Result
        How the integration ended; :attr:`status` (0 success, -1 failure: the arrays then hold
        the solution up to the failure) and :attr:`success` follow from it.
    inputs : dict of str to (N,)
        Under ``simulate(controller=...)``, the values the controller set, by parameter name, at
        the outputs (held values between samples of a ``Sampled`` one); else empty.

    Notes
    -----
    The export columns (:meth:`columns`, :meth:`to_csv`, :meth:`to_npz`,
    :meth:`to_dataframe`) are, in this order: ``t``; the coordinates by name
    (``q1, q2, ...``); their velocities (``q1d, ...``) and accelerations
    (``q1dd, ...``); ``lambda1 .. lambdar``; ``mu1 .. mus``;
    ``kinetic_energy``; ``potential_energy``; ``position_residual1 ..
    position_residualr``; ``velocity_residual1 .. velocity_residual(r+s)``; then, for
    every joint of the system (:meth:`kronlag.System.add_joint`), its reaction in world
    components (:meth:`reaction`): ``<joint>.Fx, <joint>.Fy[, <joint>.Fz]`` and
    ``<joint>.Mz`` (planar) or ``<joint>.Mx, .My, .Mz`` (spatial).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    kinetic_energy: np.ndarray
    potential_energy: np.ndarray
    position_residual: np.ndarray
    velocity_residual: np.ndarray
    coordinate_names: tuple[str, ...]
    model: NumericModel
    method: str
    message: str
    nfev: int
    njev: int
    steps: int
    wall_time: float
    events: tuple[SingularPassage, ...] = ()
    result: Result = Result.SUCCESS
    inputs: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def status(self) -> int:
        """0 on success, -1 if the integration failed (``result.status``)."""
        return self.result.status

    @property
    def success(self) -> bool:
        """The integration reached the end of the time span (``result`` is ``Result.SUCCESS``)."""
        return self.result is Result.SUCCESS

    @property
    def total_energy(self) -> np.ndarray:
        """``T + Pi``, shape (N,)."""
        return self.kinetic_energy + self.potential_energy

    @cached_property
    def nonconservative_work(self) -> np.ndarray:
        """``W(t) = integral qd^T (f_Q - Phi_q^T lambda - A^T mu) dt`` from ``t[0]``: the work of applied
        forces and torques, dampers, generalized forces and drives, shape (N,); see :mod:`kronlag.simulation.energy`."""
        return nonconservative_work(self.model, self.t, self.q, self.qd, self.qdd, inputs=self.inputs)

    @property
    def energy_balance(self) -> np.ndarray:
        """``E(t) - E(t0) - W(t)``, shape (N,): zero up to the integration error, also for driven and
        damped models (``E = T + Pi``)."""
        energy = self.total_energy
        return energy - energy[:1] - self.nonconservative_work

    def __len__(self) -> int:
        return len(self.t)

    def __repr__(self) -> str:
        span = f"t=[{self.t[0]:g}, {self.t[-1]:g}]" if len(self.t) else "t=[]"
        return (f"Trajectory(method={self.method!r}, status={self.status}, N={len(self.t)}, {span}, "
                f"steps={self.steps}, nfev={self.nfev}, wall_time={self.wall_time:.3g} s)")

    # -- export -----------------------------------------------------------------

    def columns(self) -> dict[str, np.ndarray]:
        """The export columns (see the class notes), each of shape (N,)."""
        names = self.coordinate_names
        blocks = [
            (["t"], self.t[:, None]),
            (list(names), self.q),
            ([f"{name}d" for name in names], self.qd),
            ([f"{name}dd" for name in names], self.qdd),
            ([f"lambda{j + 1}" for j in range(self.lam.shape[1])], self.lam),
            ([f"mu{k + 1}" for k in range(self.mu.shape[1])], self.mu),
            (["kinetic_energy"], self.kinetic_energy[:, None]),
            (["potential_energy"], self.potential_energy[:, None]),
            ([f"position_residual{j + 1}" for j in range(self.position_residual.shape[1])],
             self.position_residual),
            ([f"velocity_residual{j + 1}" for j in range(self.velocity_residual.shape[1])],
             self.velocity_residual),
        ]
        columns = {name: values[:, i] for labels, values in blocks for i, name in enumerate(labels)}
        columns.update(reaction_columns(self.model, self.t, self.q, self.lam))
        return columns

    def reaction(self, name: str, *, frame: str = "world") -> Reaction:
        """The reaction of joint ``name`` at every output time: the force (N, d) and couple
        (N, 1 planar or N, 3 spatial) that body A exerts on body B at B's joint point, in
        world or B's body components; see :mod:`kronlag.numeric.reactions`."""
        return joint_reaction(self.model, name, self.t, self.q, self.lam, frame=frame)

    def _metadata(self) -> dict[str, Any]:
        return {"method": self.method, "status": self.status, "message": self.message, "nfev": self.nfev,
                "njev": self.njev, "steps": self.steps, "wall_time": self.wall_time}

    # -- graphics -----------------------------------------------------------------

    # graphics live in the views layer, imported on use (a convenience listed in the layer contract)

    def plot(self, **kwargs):
        """Plot the trajectory; see :func:`kronlag.views.plotting.plot_trajectory`."""
        from ..views.plotting import plot_trajectory

        return plot_trajectory(self, **kwargs)

    def plot_reactions(self, joints=None, **kwargs):
        """Plot joint reactions over time; see :func:`kronlag.views.plotting.plot_joint_reactions`."""
        from ..views.plotting import plot_joint_reactions

        return plot_joint_reactions(self, joints, **kwargs)

    def animate(self, path=None, **kwargs):
        """Animate the mechanism; see :func:`kronlag.views.animation.animate`."""
        from ..views.animation import animate

        return animate(self, path, **kwargs)
