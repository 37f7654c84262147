"""The result of :func:`kronlag.simulate`: a sampled solution of the equations of motion.

A :class:`Trajectory` holds, at every output time ``t[k]``, the state of::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0

with time along the first axis of every array, and exports it as columns.
"""

from __future__ import annotations

import csv
import enum
import io
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from os import PathLike
from typing import TYPE_CHECKING, Any

import numpy as np

from ..numeric.friction import friction_columns, friction_joints
from ..numeric.reactions import Reaction, joint_reaction, reaction_columns
from .energy import Segment, event_energy, friction_work, nonconservative_work
from .labelled import LabelledArrays, multiplier_columns

if TYPE_CHECKING:
    import pandas
    import xarray

    from ..numeric.numeric_model import NumericModel

__all__ = ["Trajectory", "SingularPassage", "LimitEvent", "StictionEvent", "Result", "MethodInterval"]


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
    #: A segment that ends at a limit's event (a gap or a contact force through zero): the run goes
    #: on after the impact or the change of contact (:mod:`kronlag.simulation.impacts`); never a
    #: trajectory's result.
    LIMIT = -1020, "a limit's gap or contact force reached zero"

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


@dataclass(frozen=True)
class MethodInterval:
    """Which integrator ran over which interval of a run, and why (:attr:`Trajectory.intervals`).

    Attributes
    ----------
    method : str
        ``name`` of the :class:`~kronlag.simulation.Solver` that integrated ``[t_start, t_end]``: under
        the switching method ``"compiled"`` (CVODE) or ``"ali3p"``.
    t_start, t_end : float
    steps : int
        Its accepted steps.
    reason : str
        Why it ran there: the method asked for, the rank of ``Phi_q`` at the start (redundant
        constraints: the multipliers are then the minimum-norm ones), the approach to a singular
        configuration or the motion clear of one.
    """

    method: str
    t_start: float
    t_end: float
    steps: int
    reason: str

    def __str__(self) -> str:
        return f"{self.method} from t = {self.t_start:.6g} to {self.t_end:.6g} ({self.steps} steps): {self.reason}"


@dataclass(frozen=True)
class StictionEvent:
    """A transition of a joint with exact stiction (``Friction(law="exact")``, :mod:`kronlag.simulation.stiction`).

    Attributes
    ----------
    t : float
    joint : str
    kind : str
        ``"stick"`` (its rate reached zero and the holding force is within ``r mu_s N``: held from
        here), ``"slip"`` (the holding force reached ``r mu_s N``, or exceeded it at the start: it slides
        from here in that force's direction) or ``"reverse"`` (its rate reached zero and it slides on the
        other way).
    q : (m,)
    force : float
        The holding force (torque) at ``t`` (N or N*m; its sign is the direction it slides in after a
        slip).
    threshold : float
        ``r mu_s N`` at ``t``.
    """

    t: float
    joint: str
    kind: str
    q: np.ndarray
    force: float = 0.0
    threshold: float = 0.0

    def __str__(self) -> str:
        return (f"{self.kind} of joint {self.joint!r} at t = {self.t:.9g} (holding force {self.force:.6g}, "
                f"limit {self.threshold:.6g})")


@dataclass(frozen=True)
class LimitEvent:
    """An event of a limit side (:meth:`kronlag.System.add_limit`, :mod:`kronlag.simulation.impacts`).

    Attributes
    ----------
    t : float
    side : str
        The side: ``"<limit> lower"`` or ``"<limit> upper"``.
    kind : str
        ``"impact"`` (Newton's law applied: ``impulse``, gap speeds before and after), ``"contact"``
        (the side is held as a constraint from here: ``force`` its contact force; after an impact
        whose rebound fell below the Zeno threshold, or a start in contact) or ``"release"`` (its
        contact force fell through zero: the side is free again).
    q : (m,)
        Coordinates at ``t``.
    impulse : float
        Of an impact: the generalized impulse along the gap (positive: pushing it open).
    speed_before, speed_after : float
        Of an impact: the gap speed ``J qd`` before (negative: closing) and after.
    force : float
        Of a contact: its force along the gap at ``t`` (positive: pressing).
    reason : str
        Why a contact began (e.g. the Zeno rule with its threshold).
    """

    t: float
    side: str
    kind: str
    q: np.ndarray
    impulse: float = 0.0
    speed_before: float = 0.0
    speed_after: float = 0.0
    force: float = 0.0
    reason: str = ""

    def __str__(self) -> str:
        if self.kind == "impact":
            detail = (f"impulse {self.impulse:.6g}, gap speed {self.speed_before:.6g} -> "
                      f"{self.speed_after:.6g}")
        elif self.kind == "contact":
            detail = f"held, force {self.force:.6g}" + (f" ({self.reason})" if self.reason else "")
        else:
            detail = "released"
        return f"{self.kind} at {self.side} at t = {self.t:.9g}: {detail}"


class ColumnExport:
    """Export of a result to files: a subclass defines ``columns()`` (named arrays of shape (N,))
    and ``_metadata()`` (the run's message and counters)."""

    if TYPE_CHECKING:  # the subclass's
        def columns(self) -> dict[str, np.ndarray]: ...
        def _metadata(self) -> dict[str, Any]: ...

    def to_csv(self, path: str | PathLike) -> None:
        """Write the columns to a comma-separated file with a one-line header of column names (a name
        with a comma in it, as a constraint's may have, quoted)."""
        columns = self.columns()
        data = np.column_stack(list(columns.values())) if columns else np.zeros((0, 0))
        header = io.StringIO()
        csv.writer(header, lineterminator="").writerow(columns)
        np.savetxt(path, data, delimiter=",", header=header.getvalue(), comments="", fmt="%.17g")

    def to_npz(self, path: str | PathLike) -> None:
        """Write the columns and the run's metadata (``message``, ...) to a NumPy ``.npz`` archive."""
        arrays = {**self.columns(), **{key: np.asarray(value) for key, value in self._metadata().items()}}
        np.savez(path, allow_pickle=False, **arrays)

    def to_dataframe(self) -> pandas.DataFrame:
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
    events : tuple of SingularPassage and LimitEvent
        Passages through or near singular configurations and the limits' impacts and contacts,
        in time order.
    limit_forces : (N, n) or None
        For a model with limits: the force of each limit side's contact along its gap (0 when
        not in contact), columns in the order of the sides (every bound of every limit, lower first).
    friction_held : (N, n) or None
        For a model with exact stiction: the holding force of each joint with friction while it
        sticks (NaN while it slides), in the order of the joints; the ``<joint>.friction`` column
        shows it there.
    result : Result
        How the integration ended; :attr:`status` (0 success, -1 failure: the arrays then hold
        the solution up to the failure) and :attr:`success` follow from it.
    inputs : dict of str to (N,)
        Under ``simulate(controller=...)``, the values the controller set, by parameter name, at
        the outputs (held values between samples of a ``Sampled`` one); else empty.
    intervals : tuple of MethodInterval
        Which integrator ran over which interval and why, in time order (one interval unless the
        switching method changed integrators, e.g. ALI3-P near a singular configuration).
    segments : tuple of Segment
        For a run with limits or exact stiction: its pieces between events, in order, each with the
        model integrated there (contacts and sticking joints held, sliding directions) and its number
        of outputs, so that :attr:`nonconservative_work` uses the friction that acted
        (:class:`~kronlag.simulation.energy.Segment`); empty when ``model`` ran throughout.
    sample_times : (S,) or None
        Under a :class:`~kronlag.simulation.controllers.Sampled` controller, the instants it took its
        samples (its inputs held from each to the next, as :attr:`nonconservative_work` integrates them);
        else None.

    Notes
    -----
    The export columns (:meth:`columns`, :meth:`to_csv`, :meth:`to_npz`,
    :meth:`to_dataframe`) are, in this order: ``t``; the coordinates by name
    (``q1, q2, ...``); their velocities (``q1d, ...``) and accelerations
    (``q1dd, ...``); the multipliers by constraint name, ``lambda[<constraint>]`` (e.g.
    ``lambda[loop x]``) and ``mu[<constraint>]``, as the plots label them; ``kinetic_energy``;
    ``potential_energy``; ``position_residual1 .. position_residualr``; ``velocity_residual1 ..
    velocity_residual(r+s)``; then, for
    every joint of the system (:meth:`kronlag.System.add_joint`), its reaction in world
    components (:meth:`reaction`): ``<joint>.Fx, <joint>.Fy[, <joint>.Fz]`` and
    ``<joint>.Mz`` (planar) or ``<joint>.Mx, .My, .Mz`` (spatial); for a model with limits, the contact
    force of every limit side (:attr:`limit_forces`): ``<limit> lower.force``, ``<limit> upper.force``.
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
    events: tuple[SingularPassage | LimitEvent | StictionEvent, ...] = ()
    result: Result = Result.SUCCESS
    limit_forces: np.ndarray | None = None
    friction_held: np.ndarray | None = None
    inputs: dict[str, np.ndarray] = field(default_factory=dict)
    intervals: tuple[MethodInterval, ...] = ()
    segments: tuple[Segment, ...] = ()
    sample_times: np.ndarray | None = None

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
        forces and torques, dampers, generalized forces, joint friction and drives, shape (N,); see
        :mod:`kronlag.simulation.energy`."""
        return nonconservative_work(self.model, self.t, self.q, self.qd, self.qdd, inputs=self.inputs,
                                    segments=self.segments, sample_times=self.sample_times)

    @cached_property
    def friction_work(self) -> np.ndarray:
        """``integral Q_f . qd dt`` from ``t[0]``: the work of the joints' friction (negative: energy lost),
        shape (N,), part of :attr:`nonconservative_work`; zeros without friction (:mod:`kronlag.model.friction`)."""
        return friction_work(self.model, self.t, self.q, self.qd, self.qdd, segments=self.segments)

    @property
    def energy_balance(self) -> np.ndarray:
        """``E(t) - E(t0) - W(t)``, shape (N,): zero up to the integration error, also for driven and
        damped models (``E = T + Pi``), but for what the events changed (:attr:`event_energy`: the
        impacts' losses)."""
        energy = self.total_energy
        return energy - energy[:1] - self.nonconservative_work

    @cached_property
    def event_energy(self) -> np.ndarray:
        """The change of ``E = T + Pi`` at the run's events up to each output (the impacts' losses,
        <= 0), shape (N,); zeros without limits or exact stiction.  ``energy_balance - event_energy`` is
        the integration's drift; see :func:`kronlag.simulation.energy.event_energy`."""
        return event_energy(self.model, self.t, self.segments)

    @property
    def energy_drift(self) -> np.ndarray:
        """``E(t) - E(t0) - W(t)`` less :attr:`event_energy`, shape (N,): the integration's energy error,
        zero up to it with impacts too."""
        return self.energy_balance - self.event_energy

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
            (multiplier_columns(self.model.equations.system), np.hstack([self.lam, self.mu])),
            (["kinetic_energy"], self.kinetic_energy[:, None]),
            (["potential_energy"], self.potential_energy[:, None]),
            ([f"position_residual{j + 1}" for j in range(self.position_residual.shape[1])],
             self.position_residual),
            ([f"velocity_residual{j + 1}" for j in range(self.velocity_residual.shape[1])],
             self.velocity_residual),
        ]
        columns = {name: values[:, i] for labels, values in blocks for i, name in enumerate(labels)}
        columns.update(reaction_columns(self.model, self.t, self.q, self.lam))
        if self.limit_forces is not None:  # limits: each side's contact force
            sides = [side.name for limit in self.model.equations.system.limits for side in limit.sides]
            columns.update({f"{side}.force": self.limit_forces[:, i] for i, side in enumerate(sides)})
        if friction_joints(self.model.equations.system):  # joint friction: force, normal load and rate by joint
            columns.update(self.friction_columns())
        return columns

    def friction_columns(self) -> dict[str, np.ndarray]:
        """Per joint with friction, ``<joint>.friction``, ``<joint>.normal_load`` and ``<joint>.rate``, and
        ``friction_power``, each (N,) (:func:`kronlag.numeric.friction.friction_columns`): the friction that
        acted, segment by segment with each one's model (a joint that slips at an output where its rate is
        still zero slides in its segment's direction; a held one's is its holding force)."""
        pieces = [piece for piece in self.segments if piece.outputs] or [Segment(self.model, len(self.t))]
        parts, first = [], 0
        for piece in pieces:
            rows = slice(first, first + piece.outputs)
            held = None if self.friction_held is None else self.friction_held[rows]
            parts.append(friction_columns(piece.model, self.t[rows], self.q[rows], self.qd[rows], self.lam[rows], held))
            first = rows.stop
        return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}

    def reaction(self, name: str, *, frame: str = "world") -> Reaction:
        """The reaction of joint ``name`` at every output time: the force (N, d) and couple
        (N, 1 planar or N, 3 spatial) that body A exerts on body B at B's joint point, in
        world or B's body components; see :mod:`kronlag.numeric.reactions`."""
        return joint_reaction(self.model, name, self.t, self.q, self.lam, frame=frame)

    def to_xarray(self, *, units: Mapping[str, str] | None = None) -> xarray.Dataset:
        """The trajectory as an :class:`xarray.Dataset` over ``time`` (needs xarray).

        Dimensions ``time``, ``coordinate`` (the coordinate names), ``constraint`` and
        ``nonholonomic`` (the constraint names), and, for a system with joints, ``joint``,
        ``axis`` and ``couple_axis``.  Variables ``q``, ``qd``, ``qdd`` (time, coordinate);
        ``lambda`` and ``position_residual`` (time, constraint); ``velocity_residual``
        (time, constraint: ``Phi_q qd``); ``mu`` and ``nonholonomic_residual`` (time,
        nonholonomic: ``A qd + b``); ``kinetic_energy``, ``potential_energy`` (time); the
        joints' reactions ``reaction_force`` and ``reaction_couple`` in world components
        (:mod:`kronlag.simulation.labelled`).  The run's ``method``, ``status``, ``result``,
        ``message``, counters and ``system`` are attributes of the dataset.

        Parameters
        ----------
        units : mapping of str to str, optional
            Units by name, as :meth:`plot` takes them (``kronlag.app.workflows.model_units(model_file)``
            gives a model file's); they become the variables' ``units`` attributes.
        """
        arrays = LabelledArrays(self.t, units)
        system = self.model.equations.system
        r = self.lam.shape[1]
        arrays.coordinates(self.coordinate_names, self.q, self.qd, self.qdd)
        arrays.multipliers(system, self.lam, self.mu)
        energy = arrays.units.get("energy")
        arrays.variable("kinetic_energy", ("time",), self.kinetic_energy, energy)
        arrays.variable("potential_energy", ("time",), self.potential_energy, energy)
        arrays.variable("position_residual", ("time", "constraint"), self.position_residual)
        arrays.variable("velocity_residual", ("time", "constraint"), self.velocity_residual[:, :r])
        arrays.variable("nonholonomic_residual", ("time", "nonholonomic"), self.velocity_residual[:, r:])
        arrays.reactions(self.model, self.t, self.q, self.lam)
        return arrays.dataset({**self._metadata(), "result": self.result.name, "system": system.name})

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
