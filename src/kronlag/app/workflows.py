"""Whole tasks on a model file: check it, simulate it, analyse the kinematics and run inverse
dynamics along prescribed motions.  The command-line interface is a thin shell over these.

:func:`check_model` works on the symbolic equations (and the numeric model for the mobility); :func:`simulate_model`,
:func:`kinematics_along` and :func:`inverse_dynamics_along` use the numeric layer
(``Equations.numeric``, :func:`kronlag.simulate`, :mod:`kronlag.drives`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from ..core.errors import ModelError, NumericalError
from ..core.kernels import ExpressionFunction
from ..model.expressions import parse_expression
from ..model.modelfile import ModelFile, PrescribedMotion
from ..model.modelfile.units import si_unit
from ..model.symbols import t
from ..model.system import drive_name
from ..numeric.tolerances import matrix_rank
from ..simulation.controllers import file_controller
from ..simulation.simulate import simulate
from ..simulation.trajectory import LimitEvent, StictionEvent
from ..studies.constraint_groups import ConstraintGroup, constraint_ranks
from ..studies.drives import InverseDynamicsRun, Kinematics, inverse_dynamics, kinematic_analysis
from ..symbolic.derivation import derive
from ..symbolic.equations import Equations

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel
    from ..simulation.trajectory import Trajectory

__all__ = [
    "ModelCheck",
    "check_model",
    "numeric_model",
    "initial_state",
    "simulate_model",
    "model_units",
    "SimulationSummary",
    "summarize",
    "parse_drive",
    "driven_model",
    "kinematics_along",
    "inverse_dynamics_along",
]


# -- check ------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelCheck:
    """What :func:`check_model` found.

    Attributes
    ----------
    name : str
    m, r, s : int
        Coordinates, holonomic and nonholonomic constraints.
    degrees_of_freedom : int
        The mobility, ``m - rank [Phi_q; A]`` at the assembled initial state
        (:meth:`NumericModel.mobility`): redundant constraints count once.  ``m - r - s`` when
        values are missing or the state cannot be assembled (``mobility_at`` says which).
    mobility_at : str
        Where ``degrees_of_freedom`` was counted: ``"the assembled state"`` or ``"m - r - s"``.
    missing_values : tuple of str
        Parameters without a value (the numeric checks need them all).
    rank_Phi_q, rank_A : int or None
        Numeric ranks at the initial guess (``None`` when values are missing).
    constraint_residual : float or None
        ``max |Phi(q)|`` at the initial guess.
    assembly_correction : tuple of (float, float) or None
        ``max |q0 - q_guess|`` and ``max |qd0 - qd_guess|`` of the assembled initial state
        (:func:`initial_state`); ``None`` when it was not tried (values missing) or failed.
    assembly_error : str
        Why the initial state cannot be assembled (the unsatisfied constraint rows); empty if it can.
    constraint_groups : tuple of ConstraintGroup
        The holonomic rows by joint or loop and their ranks at the assembled state (with
        :attr:`dependent_rows`; empty when it was not assembled); reported when some group has
        several rows.
    dependent_rows : tuple of str
        The rows the rank policy counts dependent on the others there (as many as the solver drops,
        :func:`~kronlag.numeric.tolerances.rank_magnitudes`): those nearest to the span of the rows
        before them in the system's order.
    """

    name: str
    m: int
    r: int
    s: int
    degrees_of_freedom: int
    mobility_at: str
    missing_values: tuple[str, ...]
    rank_Phi_q: int | None
    rank_A: int | None
    constraint_residual: float | None
    assembly_correction: tuple[float, float] | None = None
    assembly_error: str = ""
    constraint_groups: tuple[ConstraintGroup, ...] = ()
    dependent_rows: tuple[str, ...] = ()

    def report(self) -> str:
        """A few lines of text for people."""
        lines = [f"model {self.name}: m = {self.m} coordinates, r = {self.r} holonomic and "
                 f"s = {self.s} nonholonomic constraints",
                 self._freedom_line()]
        if self.missing_values:
            lines.append("parameters without values: " + ", ".join(self.missing_values)
                         + " (numeric checks skipped)")
            return "\n".join(lines)
        for label, rank, rows in (("Phi_q", self.rank_Phi_q, self.r), ("A", self.rank_A, self.s)):
            if rows:
                verdict = "full" if rank == rows else f"DEFICIENT: {rows - rank} dependent rows"
                lines.append(f"rank of {label} at the initial guess: {rank} of {rows} ({verdict})")
        if self.r:
            lines.append(f"max |Phi(q)| at the initial guess: {self.constraint_residual:.3g}")
        if self.assembly_error:
            lines.append(f"initial state: NOT ASSEMBLED: {self.assembly_error}")
        elif self.assembly_correction is not None:
            lines.append("initial state assembled: max |q0 - guess| = {:.3g}, max |qd0 - guess| = {:.3g}"
                         .format(*self.assembly_correction))
        if len(self.constraint_groups) > 1 and any(len(group.rows) > 1 for group in self.constraint_groups):
            shown = [group for group in self.constraint_groups
                     if len(self.constraint_groups) <= _LISTED_GROUPS or group.rank < len(group.rows)]
            unlisted = len(self.constraint_groups) - len(shown)
            lines.append("rank of each joint's or loop's rows at the assembled state: " + "; ".join(
                f"{group.name} {group.rank} of {len(group.rows)}" for group in shown)
                + (f"{'; ' if shown else ''}{unlisted} more of full rank" if unlisted else ""))
        if self.dependent_rows:
            lines.append("rows dependent on the others at the assembled state (redundant): "
                         + ", ".join(self.dependent_rows))
        return "\n".join(lines)

    def _freedom_line(self) -> str:
        naive = self.m - self.r - self.s
        if self.mobility_at == _NAIVE:
            return f"degrees of freedom m - r - s = {naive}"
        note = "" if self.degrees_of_freedom == naive else f"; m - r - s = {naive}: dependent constraints"
        return f"degrees of freedom = {self.degrees_of_freedom} (m - rank [Phi_q; A] at {self.mobility_at}{note})"


#: :attr:`ModelCheck.mobility_at` when the mobility could not be counted at an assembled state.
_NAIVE = "m - r - s"


#: :meth:`ModelCheck.report` lists every group's rank up to this many groups, beyond it the deficient ones.
_LISTED_GROUPS = 20


def check_model(model: ModelFile, *, equations: Equations | None = None) -> ModelCheck:
    """Derive the equations and check the constraints at the initial guess (at ``t = 0``).

    Evaluates ``Phi``, ``Phi_q`` and ``A`` through a kernel of the symbolic matrices
    (:class:`kronlag.core.kernels.ExpressionFunction`, so a model with missing values is still
    checked as far as it can be), ranks by the rank policy
    (:func:`kronlag.numeric.tolerances.numerical_rank`).  With every value given and some
    constraint, the numeric model assembles the initial state and the degrees of freedom are its
    mobility there (:meth:`NumericModel.mobility`).
    """
    eom = equations if equations is not None else derive(model.system)
    m, r, s = eom.shape
    system = model.system
    missing = tuple(p.name for p in system.parameters if p.name not in model.values)
    rank_phi = rank_a = residual = None
    if not missing:
        values = model.numeric_values()
        q, qd = model.guess_vectors()
        evaluate = ExpressionFunction({"Phi": eom.Phi, "Phi_q": eom.Phi_q, "A": eom.A},
                                      [("t", eom.time), ("q", eom.coordinates), ("qd", eom.speeds),
                                       ("p", eom.parameters)], name="check")
        at_guess = evaluate(0.0, q, qd, [values[p.name] for p in eom.parameters])
        rank_phi, rank_a = (matrix_rank(at_guess[name]) for name in ("Phi_q", "A"))  # no model yet: default rtol
        residual = float(np.max(np.abs(at_guess["Phi"]), initial=0.0))
    freedom, at, correction, failure = m - r - s, _NAIVE, None, ""
    groups: tuple[ConstraintGroup, ...] = ()
    dependent: tuple[str, ...] = ()
    if not missing:
        numeric = numeric_model(model, equations=eom)
        q, qd = (np.asarray(x, dtype=float) for x in model.guess_vectors())
        try:
            q0, qd0 = initial_state(model, numeric)
        except NumericalError as error:  # not assembled: the rank at a state off the constraints means nothing
            failure = str(error)
        else:
            correction = (float(np.max(np.abs(q0 - q), initial=0.0)), float(np.max(np.abs(qd0 - qd), initial=0.0)))
            if r + s:
                freedom, at = numeric.mobility(q0), "the assembled state"
            if r:
                groups, dependent = constraint_ranks([c.name for c in system.constraints], numeric.Phi_q(q0),
                                                     numeric.rank_rtol)
    return ModelCheck(name=system.name, m=m, r=r, s=s, degrees_of_freedom=freedom, mobility_at=at,
                      missing_values=missing, rank_Phi_q=rank_phi, rank_A=rank_a, constraint_residual=residual,
                      assembly_correction=correction, assembly_error=failure, constraint_groups=groups,
                      dependent_rows=dependent)


# -- numeric set-up -------------------------------------------------------------------


def numeric_model(model: ModelFile, *, equations: Equations | None = None) -> NumericModel:
    """``derive(model.system).numeric(model.values)``: the file's parameter values, those written as
    expressions of others kept as definitions (computed again by ``with_parameters``)."""
    eom = equations if equations is not None else derive(model.system)
    return eom.numeric(model.values)


def initial_state(model: ModelFile, numeric: NumericModel) -> tuple[np.ndarray, np.ndarray]:
    """Assemble ``(q0, qd0)`` from the file's guesses, holding its fixed coordinates and speeds."""
    q, qd = model.guess_vectors()
    names = [symbol.name for symbol in model.system.coordinates]
    position = dict(zip(names, q))
    speed = dict(zip(names, qd))
    return numeric.assemble(q, fixed={name: position[name] for name in model.fixed} or None, qd_guess=qd,
                            qd_fixed={name: speed[name] for name in model.qd_fixed} or None)


# -- simulation -------------------------------------------------------------------------


def simulate_model(model: ModelFile, *, t_end: float | None = None, method: str | None = None,
                   rtol: float | None = None, atol: float | None = None, t_eval: np.ndarray | None = None,
                   max_steps: int | None = None, progress: Callable[[float], object] | None = None) -> Trajectory:
    """Assemble the initial state and simulate from 0 to ``t_end``.

    Options left at ``None`` come from the file's ``[simulation]`` table
    (``max_steps``: :func:`kronlag.simulate`'s default); ``t_eval`` are the
    output times (default: every step); ``progress`` is called with the time
    after every step.
    """
    numeric = numeric_model(model)
    q0, qd0 = initial_state(model, numeric)
    settings = model.simulation
    limits = {} if max_steps is None else {"max_steps": max_steps}
    controller = None if model.controller is None else file_controller(model.controller, numeric)
    return simulate(numeric, (0.0, settings.t_end if t_end is None else t_end), q0, qd0,
                    method=method or settings.method, rtol=rtol or settings.rtol, atol=atol or settings.atol,
                    t_eval=t_eval, progress=progress, controller=controller, **limits)


_TRIGONOMETRIC = (sp.sin, sp.cos, sp.tan)


def model_units(model: ModelFile, *, parameters: bool = False) -> dict[str, str]:
    """Units the model file determines, by name: coordinates, ``"t"`` (time) and ``"energy"``, and
    with ``parameters`` every parameter with a unit (the file's unit when it is an SI one, ``N*m``,
    else the SI unit its value is in: ``m`` for a length the file gives in ``mm``).

    Only what follows from the file is given; a quantity whose unit cannot be
    told is left out.  Coordinates: ``rad`` for one that is the argument of
    a sine, cosine or tangent, or a planar body's angle; the length unit for
    one that enters a position (of a body, drawing or traced point) with a
    constant nonzero factor, where the length unit is the one unit of the
    parameters appearing in those positions.  Time: ``s`` when some
    parameter's unit is written with ``s``.  Energy: ``J`` when mass, length
    and time are ``kg``, ``m`` and ``s``.
    """
    system = model.system
    coordinates = set(system.coordinates)
    positions = [entry for body in system.bodies for entry in body.position]
    positions += [entry for line in system.drawing + system.traces for point in line.points for entry in point]
    angle_expressions = positions + [getattr(body, "angle", sp.S.Zero) for body in system.bodies]
    angle_expressions += [entry for body in system.bodies for entry in getattr(body, "rotation", ())]
    angles = {body.angle for body in system.bodies if getattr(body, "angle", None) in coordinates}
    angles |= {symbol for expression in angle_expressions for function in expression.atoms(*_TRIGONOMETRIC)
               for symbol in function.args[0].free_symbols & coordinates}

    def units_of(expressions: list[sp.Expr]) -> set[str | None]:
        return {model.units.get(p.name) for e in expressions for p in e.free_symbols - coordinates}

    length_units = units_of(positions)
    length = length_units.pop() if len(length_units) == 1 else None
    lengths = {q for q in coordinates for entry in positions if (factor := sp.diff(entry, q)).is_number
               and factor != 0}
    units = {q.name: "rad" for q in angles - lengths}
    if length:
        units |= {q.name: length for q in lengths - angles}
    if any(re.search(r"(?<![A-Za-z])s(?![A-Za-z])", unit) for unit in model.units.values()):
        units["t"] = "s"
    masses = units_of([body.mass for body in system.bodies])
    if masses == {"kg"} and length == "m" and units.get("t") == "s":
        units["energy"] = "J"
    if parameters:
        units |= model.units
        units |= {name: text for name, text in model.file_units.items() if si_unit(text)[0].magnitude == 1}
    return units


@dataclass(frozen=True)
class SimulationSummary:
    """The figures of merit of a simulation run.

    Attributes
    ----------
    success : bool
    message, method : str
    steps, points : int
        Accepted integrator steps and stored output times.
    t_final : float
        The last time reached.
    position_drift, velocity_drift : float
        ``max |Phi(q)|`` and ``max |[Phi_q qd; A qd + b]|`` over the run.
    energy_drift : float
        ``max |E(t) - E(0) - W(t) - E_events(t)|``: the total energy ``E = T + Pi`` against the work
        ``W`` of the non-conservative forces and what the events changed (:attr:`Trajectory.energy_drift`),
        zero up to the integration error for driven and damped models, and with impacts, too.
    relative_energy_drift : float
        ``energy_drift`` over ``max(|E|, |W|)`` (0 if both are 0 throughout).
    work : float
        ``W`` at the last time: the work of applied forces, torques and dampers.
    event_energy : float
        The change of ``E`` at the events (:attr:`Trajectory.event_energy`: the impacts' losses) by the
        last time.
    wall_time : float
        Seconds.
    largest_reactions : tuple of (str, float)
        Every joint's name and its largest reaction force ``max |F|`` over the run
        (:meth:`Trajectory.reaction`).
    limit_events : tuple of (str, int)
        The number of limit events by kind (``"impact"``, ``"contact"``, ``"release"``), for a model
        with limits.
    stiction_events : tuple of (str, int)
        The number of stiction events by kind (``"stick"``, ``"slip"``, ``"reverse"``), for a model
        with exact joint friction.
    intervals : tuple of str
        Which integrator ran where and why (:attr:`Trajectory.intervals`), when that says more than
        the method's name (the switching method; redundant constraints).
    """

    success: bool
    message: str
    method: str
    steps: int
    points: int
    t_final: float
    position_drift: float
    velocity_drift: float
    energy_drift: float
    relative_energy_drift: float
    wall_time: float
    work: float = 0.0
    event_energy: float = 0.0
    largest_reactions: tuple[tuple[str, float], ...] = ()
    limit_events: tuple[tuple[str, int], ...] = ()
    stiction_events: tuple[tuple[str, int], ...] = ()
    intervals: tuple[str, ...] = ()

    def report(self) -> str:
        """A few lines of text for people."""
        status = "ok" if self.success else f"FAILED: {self.message}"
        lines = [
            f"status: {status}",
            f"method {self.method}: {self.steps} steps, {self.points} output points, t = 0 .. {self.t_final:g}",
            f"max constraint drift: position {self.position_drift:.3g}, velocity {self.velocity_drift:.3g}",
            f"energy drift: {self.energy_drift:.3g} (relative {self.relative_energy_drift:.3g}; "
            f"E(t) - E(0) - W(t) with the work of non-conservative forces W = {self.work:.6g})",
        ]
        if self.work and self.points < self.steps:  # W's quadrature error is in the drift, not the motion's
            lines.append(f"  (W integrated over the {self.points} output points, not the {self.steps} steps: "
                         "more points (--points, --dt) tighten the balance)")
        if self.limit_events:  # impacts lose energy: not the integration's drift
            lines.append("limit events: " + ", ".join(f"{count} {kind}" for kind, count in self.limit_events)
                         + f" (they changed the energy by {self.event_energy:.6g}, apart from the drift)")
        if self.stiction_events:
            lines.append("stiction events: " + ", ".join(f"{count} {kind}" for kind, count in self.stiction_events))
        lines += [f"  {interval}" for interval in self.intervals]
        if self.largest_reactions:
            lines.append("max joint force |F|: " + ", ".join(f"{name} {force:.5g}"
                                                             for name, force in self.largest_reactions))
        return "\n".join([*lines, f"wall time: {self.wall_time:.3g} s"])


def _largest(values: np.ndarray) -> float:
    return float(np.max(np.abs(values), initial=0.0)) if values.size else 0.0


def summarize(trajectory: Trajectory) -> SimulationSummary:
    """Steps, constraint and energy drift and wall time of a trajectory."""
    energy = trajectory.total_energy
    work = trajectory.nonconservative_work if energy.size else energy
    drift = _largest(trajectory.energy_drift) if energy.size else 0.0
    scale = max(_largest(energy), _largest(work))
    return SimulationSummary(
        success=trajectory.success, message=trajectory.message, method=trajectory.method,
        steps=trajectory.steps, points=len(trajectory.t),
        t_final=float(trajectory.t[-1]) if len(trajectory.t) else 0.0,
        position_drift=_largest(trajectory.position_residual), velocity_drift=_largest(trajectory.velocity_residual),
        energy_drift=drift, relative_energy_drift=drift / scale if scale else 0.0, wall_time=trajectory.wall_time,
        work=float(work[-1]) if work.size else 0.0,
        event_energy=float(trajectory.event_energy[-1]) if energy.size else 0.0,
        largest_reactions=tuple((joint.name, _largest(np.linalg.norm(trajectory.reaction(joint.name).force, axis=1)))
                                for joint in trajectory.model.equations.system.joints) if len(trajectory.t) else (),
        limit_events=_limit_events(trajectory), stiction_events=_stiction_events(trajectory),
        intervals=_intervals(trajectory))


def _limit_events(trajectory: Trajectory) -> tuple[tuple[str, int], ...]:
    """The number of limit events by kind, for a model with limits (else empty)."""
    if trajectory.limit_forces is None:
        return ()
    kinds = [event.kind for event in trajectory.events if isinstance(event, LimitEvent)]
    return tuple((kind, kinds.count(kind)) for kind in ("impact", "contact", "release"))


def _stiction_events(trajectory: Trajectory) -> tuple[tuple[str, int], ...]:
    """The number of stiction events by kind, if there were any (else empty)."""
    kinds = [event.kind for event in trajectory.events if isinstance(event, StictionEvent)]
    return tuple((kind, kinds.count(kind)) for kind in ("stick", "slip", "reverse")) if kinds else ()


def _intervals(trajectory: Trajectory) -> tuple[str, ...]:
    """The method intervals as text, unless the run is one interval of the method asked for."""
    intervals = trajectory.intervals
    if len(intervals) == 1 and intervals[0].method == trajectory.method:
        return ()
    return tuple(str(interval) for interval in intervals)


# -- inverse dynamics -----------------------------------------------------------------


def parse_drive(text: str, model: ModelFile) -> tuple[str, PrescribedMotion]:
    """Read ``"q1=<expression of t>"`` (as on the command line) into ``(drive name, motion)``."""
    name, separator, expression = text.partition("=")
    name = name.strip()
    coordinates = {q.name: q for q in model.system.coordinates}
    if not separator or name not in coordinates:
        raise ModelError(f"drive {text!r}: expected COORDINATE=EXPRESSION with a coordinate of "
                         f"{', '.join(coordinates)}")
    symbols = {p.name: p for p in model.system.parameters} | {"t": t}
    motion = parse_expression(expression, symbols, what=f"drive {name}")
    return drive_name(coordinates[name]), PrescribedMotion(coordinates[name], motion)


def driven_model(model: ModelFile, drives: Mapping[str, PrescribedMotion]) -> NumericModel:
    """The numeric model of ``model`` with ``drives`` (by name) added as rheonomic constraints
    (:meth:`kronlag.System.add_drive`)."""
    return derive(dataclasses.replace(model, drives=dict(drives)).driven().system).numeric(model.values)


def kinematics_along(model: ModelFile, drives: Mapping[str, PrescribedMotion],
                     times: Sequence[float] | np.ndarray) -> Kinematics:
    """:func:`kronlag.kinematic_analysis` of ``model`` driven by ``drives`` (one per degree of
    freedom), from the file's assembly guesses."""
    return kinematic_analysis(driven_model(model, drives), times, model.guess_vectors()[0])


def inverse_dynamics_along(model: ModelFile, drives: Mapping[str, PrescribedMotion],
                           times: Sequence[float] | np.ndarray, *,
                           actuated: Sequence[str] | None = None) -> InverseDynamicsRun:
    """:func:`kronlag.inverse_dynamics` of ``model`` driven by ``drives``, with the actuators on the
    coordinates ``actuated``; by default on the driven coordinates when every drive drives a
    coordinate, else the drives' own forces."""
    coordinates = model.system.coordinates
    if actuated is None and all(drive.target in coordinates for drive in drives.values()):
        actuated = [drive.target.name for drive in drives.values()]
    return inverse_dynamics(driven_model(model, drives), times, model.guess_vectors()[0],
                            actuated=None if actuated is None else tuple(actuated))
