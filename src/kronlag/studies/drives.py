"""Drives: kinematic analysis and inverse dynamics along prescribed motions.

A drive is a rheonomic constraint ``target(q) - motion(t) = 0``
(:meth:`kronlag.System.add_drive`); at velocity and acceleration level::

    Phi_q qd + Phi_t = 0,    Phi_q qdd = gamma,    gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt

*Kinematic analysis* (:func:`kinematic_analysis`) of a fully driven mechanism
(``rank Phi_q = m``: as many independent drives as degrees of freedom) finds at
each time ``t_k`` the positions by Gauss-Newton on ``Phi(q, t_k) = 0`` from the
predictor ``q_{k-1} + h qd_{k-1} + h^2/2 qdd_{k-1}``, then ``qd`` and ``qdd`` from
the two linear systems above.  It never jumps silently to another assembly
branch: it stops, with a message naming ``t`` and ``q``, where ``Phi_q`` nears
a rank loss (the singular ratio of :mod:`kronlag.tolerances` below
``APPROACH_RTOL``, checked at every output time and sub-step).  Where the Newton
correction is not small against the step's displacement (a coarse time grid),
the step is halved into sub-steps until it is, up to 12 times; then it stops.

*Inverse dynamics* (:func:`inverse_dynamics`) adds the forces: either the
drives' own (``u = -lambda_drive``, the generalized force each drive applies
along its target), or those of actuated coordinates that replace the drives
(a five-bar robot driven at its end effector reports its motor torques), by
:meth:`kronlag.NumericModel.inverse_dynamics_trajectory`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.errors import AssemblyError, InputError, ModelError
from ..core.limits import MAX_OUTPUT_POINTS
from ..numeric.linalg import least_norm
from ..numeric.reactions import (
    GENERALIZED_FORCE_UNITS,
    Reaction,
    column_unit,
    joint_reaction,
    multiplier_labels,
    multiplier_units,
    reaction_columns,
)
from ..numeric.tolerances import APPROACH_RTOL, numerical_rank, rank_magnitudes, row_scales, singular_ratio
from ..simulation.labelled import LabelledArrays, multiplier_columns
from ..simulation.trajectory import ColumnExport

if TYPE_CHECKING:
    import xarray

    from ..numeric.numeric_model import NumericModel

__all__ = ["Kinematics", "InverseDynamicsRun", "kinematic_analysis", "inverse_dynamics", "BRANCH_RATIO"]

#: The Newton correction of the positions at a time step may be at most this fraction of the
#: step's predicted displacement; a larger one means the grid is too coarse to be sure of the branch.
BRANCH_RATIO = 0.25


@dataclass(eq=False)
class Kinematics(ColumnExport):
    """Positions, velocities and accelerations of a driven mechanism (:func:`kinematic_analysis`).

    Attributes
    ----------
    t : (N,)
    q, qd, qdd : (N, m)
        Rows up to where the analysis stopped (see ``message``).
    coordinate_names : tuple of str
    points : dict of str to dict
        For every named point: ``"position"``, ``"velocity"``, ``"acceleration"``, each (N, d).
    message : str
        Empty on success; otherwise where and why the analysis stopped.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    coordinate_names: tuple[str, ...]
    points: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    message: str = ""

    @property
    def success(self) -> bool:
        """The analysis covered every requested time."""
        return not self.message

    def columns(self) -> dict[str, np.ndarray]:
        """``t``, coordinates, ``<q>d``, ``<q>dd``, then ``<point>.x``, ``<point>.vx``, ``<point>.ax``, ..."""
        names = self.coordinate_names
        blocks = [(["t"], self.t[:, None]), (list(names), self.q), ([f"{n}d" for n in names], self.qd),
                  ([f"{n}dd" for n in names], self.qdd)]
        for point, state in self.points.items():
            axes = "xyz"[:state["position"].shape[1]]
            blocks += [([f"{point}.{prefix}{axis}" for axis in axes], state[quantity])
                       for prefix, quantity in (("", "position"), ("v", "velocity"), ("a", "acceleration"))]
        return {label: values[:, i] for labels, values in blocks for i, label in enumerate(labels)}

    def _metadata(self) -> dict[str, Any]:
        return {"message": self.message}

    def to_xarray(self, *, units: Mapping[str, str] | None = None) -> xarray.Dataset:
        """The analysis as an :class:`xarray.Dataset` (needs xarray): ``q``, ``qd``, ``qdd`` over
        ``time`` and ``coordinate``, the points' ``point_position``, ``point_velocity`` and
        ``point_acceleration``
        over ``time``, ``point`` and ``axis``; ``message`` and ``success`` as attributes.  ``units``
        as :meth:`kronlag.Trajectory.to_xarray` takes them."""
        return self._arrays(units).dataset({"message": self.message, "success": int(self.success)})

    def _arrays(self, units: Mapping[str, str] | None) -> LabelledArrays:
        arrays = LabelledArrays(self.t, units)
        arrays.coordinates(self.coordinate_names, self.q, self.qd, self.qdd)
        if self.points:
            states = list(self.points.values())
            arrays.dimension("point", list(self.points))
            arrays.dimension("axis", list("xyz"[:states[0]["position"].shape[1]]))
            for quantity in ("position", "velocity", "acceleration"):
                arrays.variable(f"point_{quantity}", ("time", "point", "axis"),
                                np.stack([state[quantity] for state in states], axis=1))
        return arrays

    def _reported(self) -> dict[str, np.ndarray]:
        """The columns of :meth:`report`: time and coordinates."""
        return {k: v for k, v in self.columns().items() if k == "t" or k in self.coordinate_names}

    def _summary(self) -> list[str]:
        return []

    def report(self, *, rows: int = 11) -> str:
        """A table of the main columns at up to ``rows`` evenly spaced times, and the message."""
        columns = self._reported()
        picks = np.unique(np.linspace(0, len(self.t) - 1, min(rows, len(self.t))).round().astype(int))
        widths = [max(12, len(name)) for name in columns]
        lines = ["  ".join(f"{name:>{width}}" for name, width in zip(columns, widths))]
        lines += ["  ".join(f"{values[i]:{width}.5g}" for values, width in zip(columns.values(), widths))
                  for i in picks]
        lines += self._summary()
        if self.message:
            lines.append(f"FAILED: {self.message}")
        return "\n".join(lines)


@dataclass(eq=False)
class InverseDynamicsRun(Kinematics):
    """Actuator forces, multipliers and joint reactions along a driven motion (:func:`inverse_dynamics`).

    Attributes
    ----------
    actuated : tuple of str
        What the forces act on: the actuated coordinates, or the drives' names.
    forces : (N, n_a)
        ``forces[:, k]``: generalized force on ``actuated[k]`` (torque on an angle, force on a length).
    lam : (N, r), mu : (N, s)
        Multipliers with the sign of Eq. 23 (zero for drives replaced by actuators).
    reactions : dict of str to (N,) arrays
        The joints' reactions in world components (``main_bearing.Fx``, ...; see
        :func:`kronlag.reactions.reaction_columns`); :meth:`reaction` gives one joint's as a
        :class:`~kronlag.numeric.reactions.Reaction`.
    model : NumericModel
        The driven model.
    """

    actuated: tuple[str, ...] = ()
    forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    lam: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    mu: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    reactions: dict[str, np.ndarray] = field(default_factory=dict)
    model: NumericModel | None = field(default=None, repr=False)

    def reaction(self, name: str, *, frame: str = "world") -> Reaction:
        """The reaction of joint ``name`` at every time, as :meth:`kronlag.Trajectory.reaction` gives
        it; see :mod:`kronlag.numeric.reactions`."""
        return joint_reaction(self.model, name, self.t, self.q, self.lam, frame=frame)

    def columns(self) -> dict[str, np.ndarray]:
        """The :class:`Kinematics` columns, then ``force_<actuated>``, the multipliers by constraint name
        (``lambda[<constraint>]``, ``mu[<constraint>]``; ``lambda<j>``, ``mu<k>`` for a run without its
        model) and the joints' reactions."""
        multipliers = (multiplier_columns(self.model.equations.system) if self.model is not None else
                       [f"lambda{j + 1}" for j in range(self.lam.shape[1])]
                       + [f"mu{k + 1}" for k in range(self.mu.shape[1])])
        blocks = [([f"force_{n}" for n in self.actuated], self.forces),
                  (multipliers, np.hstack([self.lam, self.mu]))]
        columns = super().columns()
        columns.update({label: values[:, i] for labels, values in blocks for i, label in enumerate(labels)})
        return columns | self.reactions

    def to_xarray(self, *, units: Mapping[str, str] | None = None) -> xarray.Dataset:
        """The run as an :class:`xarray.Dataset` (needs xarray): the :class:`Kinematics` variables, the
        driving forces ``force`` over ``time`` and ``actuated`` (the actuated coordinates or the drives'
        names; ``N*m`` on an angle, ``N`` on a length, when the units tell), ``lambda`` and ``mu`` by
        constraint, and the joints' ``reaction_force`` and ``reaction_couple`` as
        :meth:`kronlag.Trajectory.to_xarray` has them.  ``units`` as that method takes them."""
        arrays = self._arrays(units)
        system = self.model.equations.system if self.model is not None else None
        force_units = multiplier_units(system, arrays.units) if system is not None and arrays.si else {}
        force_units |= {name: unit for name in self.actuated
                        if (unit := GENERALIZED_FORCE_UNITS.get(arrays.units.get(name, ""))) and arrays.si}
        arrays.dimension("actuated", list(self.actuated))
        arrays.variable("force", ("time", "actuated"), self.forces, [force_units.get(name) for name in self.actuated])
        arrays.multipliers(system, self.lam, self.mu)
        if self.model is not None:
            arrays.reactions(self.model, self.t, self.q, self.lam)
        return arrays.dataset({"message": self.message, "success": int(self.success)})

    def _reported(self) -> dict[str, np.ndarray]:
        """The columns of :meth:`report`: the forces, the multipliers of the constraints that are
        neither a joint's nor a drive's, by constraint name (the joints' reactions are in the
        summary)."""
        reported = {"t": self.t} | {f"force_{name}": self.forces[:, k] for k, name in enumerate(self.actuated)}
        if self.model is None:
            return reported
        system = self.model.equations.system
        joint_rows = {row for joint in system.joints for row in joint.constraint_names} | set(system.drives)
        reported |= {label: self.lam[:, j] for j, (label, constraint)
                     in enumerate(zip(multiplier_labels(system), system.constraints))
                     if constraint.name not in joint_rows}
        return reported | {f"mu[{c.name}]": self.mu[:, k] for k, c in enumerate(system.nonholonomic_constraints)}

    def _summary(self) -> list[str]:
        if not self.forces.size:
            return []
        peaks = ", ".join(f"{name} {np.max(np.abs(self.forces[:, k])):.5g}" for k, name in enumerate(self.actuated))
        lines = [f"max |force|: {peaks}"]
        by_joint: dict[str, list[str]] = {}
        for name, values in self.reactions.items():
            joint, _, component = name.rpartition(".")
            by_joint.setdefault(joint, []).append(f"{name} = {np.max(np.abs(values), initial=0.0):.5g} "
                                                  f"{column_unit(name)}")
        if by_joint:
            lines.append("max |joint reaction| (world components):")
            lines += ["  " + ", ".join(components) for components in by_joint.values()]
        return lines


def _times(t) -> np.ndarray:
    times = np.asarray(t, dtype=float)
    if times.ndim != 1 or len(times) == 0:
        raise InputError(f"t must be a non-empty 1-d sequence of times, got shape {times.shape}")
    if len(times) > MAX_OUTPUT_POINTS:
        raise InputError(f"t has {len(times)} times, more than the limit of {MAX_OUTPUT_POINTS}")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise InputError("t must be finite and strictly increasing")
    return times


def _point_names(model: NumericModel, points: Sequence[str] | None) -> list[str]:
    available = list(model.equations.system.points)
    names = available if points is None else list(points)
    unknown = [name for name in names if name not in available]
    if unknown:
        raise ModelError(f"unknown point(s) {unknown}; points are {available}")
    return names


class _Stop(Exception):
    """Ends a kinematic analysis early; the text is the result's message."""


#: Halvings of a time step at most, when the predictor is too far from the solution.
_MAX_HALVINGS = 12


def _accelerations(model: NumericModel, q: np.ndarray, qd: np.ndarray, time: float) -> np.ndarray:
    """``qdd`` from ``Phi_q qdd = gamma`` (minimum-norm least squares over the independent rows:
    redundant rows are consistent)."""
    return least_norm(model.Phi_q(q, time), model.gamma(q, qd, time), rank_rtol=model.rank_rtol)


def _advance(model: NumericModel, state: tuple, time: float, tol: float, *, depth: int, scales: np.ndarray) -> tuple:
    """The state ``(t, q, qd, qdd)`` at ``time`` from ``state``: Newton from the Taylor predictor,
    the step halved (sub-steps, not outputs) while the Newton correction is not small against
    the step's displacement (:data:`BRANCH_RATIO`)."""
    start, previous, speed, acceleration = state
    h = time - start
    predictor = previous + h * speed + h * h / 2 * acceleration
    failure: AssemblyError | None = None
    try:
        q, qd = model.assemble(predictor, t=time, tol=tol)  # qd unique: solved afresh, no cancellation
        correction = np.max(np.abs(q - predictor))
        displacement = np.max(np.abs(predictor - previous))
        close = correction <= BRANCH_RATIO * displacement + 1e3 * tol * (1 + np.max(np.abs(q)))
    except AssemblyError as error:
        close, failure = False, error
    if close:
        return time, q, qd, _accelerations(model, q, qd, time)
    if depth == _MAX_HALVINGS:
        where = f"between t = {start:g} and {time:g}, from q = {np.array2string(previous, precision=6)}"
        raise _Stop(f"{where}: {failure}" if failure is not None else
                    f"{where}: the positions cannot be followed on their assembly branch (the Newton "
                    f"correction stays large against the step after {_MAX_HALVINGS} halvings)")
    middle = _advance(model, state, start + h / 2, tol, depth=depth + 1, scales=scales)
    _check_regular(model, middle[0], middle[1], scales)
    return _advance(model, middle, time, tol, depth=depth + 1, scales=scales)


def _check_regular(model: NumericModel, time: float, q: np.ndarray, scales: np.ndarray) -> None:
    """:class:`_Stop` where ``Phi_q`` nears a rank loss (the singular ratio below ``APPROACH_RTOL``, the
    rows in the units ``scales``: :func:`~kronlag.numeric.tolerances.row_scales` at the first time)."""
    ratio, row = singular_ratio(model.Phi_q(q, time), model.m, scales)
    if ratio < APPROACH_RTOL:
        raise _Stop(f"at t = {time:g}, q = {np.array2string(q, precision=6)}: Phi_q is nearly singular "
                    f"(ratio {ratio:.3g} < {APPROACH_RTOL:g}, constraint "
                    f"{model.equations.system.constraints[row].name!r}): a singular configuration, past which "
                    "the positions may switch assembly branch; the analysis stops here")


def _mechanism_rows(model: NumericModel) -> list[int]:
    """The holonomic constraint rows that are not drives."""
    system = model.equations.system
    return [j for j, item in enumerate(system.constraints) if item.name not in system.drives]


def _freedom_without_drives(model: NumericModel, q, time: float) -> int:
    """Degrees of freedom at ``q`` of the mechanism without its drives: ``m - rank Phi_q`` of the other rows."""
    jacobian = model.Phi_q(np.asarray(q, dtype=float), time)[_mechanism_rows(model)]
    return model.m - numerical_rank(rank_magnitudes(jacobian)[0], model.rank_rtol)


def _diagnose_overdriven(model: NumericModel, q_guess, time: float) -> None:
    """ModelError when there are more drives than the mechanism without them has degrees of freedom."""
    drives = model.equations.system.drives
    freedom = _freedom_without_drives(model, q_guess, time)
    if len(drives) > freedom:
        raise ModelError(f"{model.equations.system.name} is over-driven: {len(drives)} drives "
                         f"({', '.join(drives)}) for {freedom} degree(s) of freedom")


def kinematic_analysis(model: NumericModel, t, q_guess, *, points: Sequence[str] | None = None,
                       tol: float = 1e-12) -> Kinematics:
    """Positions, velocities and accelerations of a fully driven mechanism at the times ``t``.

    At each time (see the module docstring)::

        Phi(q, t) = 0,    Phi_q qd = -Phi_t,    Phi_q qdd = gamma

    Parameters
    ----------
    model : NumericModel
        With holonomic constraints only, drives included, and ``rank Phi_q = m``.
    t : (N,)
        Strictly increasing output times (sub-steps are added between them where
        the motion needs them to stay on its branch).
    q_guess : (m,)
        Near the assembly wanted at ``t[0]`` (it selects the branch).
    points : sequence of str, optional
        Named points (:meth:`kronlag.System.add_point`) whose position, velocity and
        acceleration to compute (default: all).
    tol : float
        ``max |Phi|`` at which the positions are accepted.

    Returns
    -------
    Kinematics
        Stops early, with ``message`` naming t and q, at a singular configuration
        or where the positions cannot be followed on their branch.

    Raises
    ------
    ModelError
        The model has nonholonomic constraints, or is not fully driven at ``t[0]``
        (the message gives the number of degrees of freedom left), or has more
        drives than degrees of freedom (over-driven).
    AssemblyError
        No assembly near ``q_guess`` at ``t[0]``.
    """
    times = _times(t)
    names = _point_names(model, points)
    system = model.equations.system
    if model.s:
        raise ModelError(f"kinematic analysis of {system.name}: it has {model.s} nonholonomic constraint(s), "
                         "whose positions follow only by integration (use kronlag.simulate)")
    try:
        q, qd = model.assemble(q_guess, t=float(times[0]), tol=tol)
    except AssemblyError:
        _diagnose_overdriven(model, q_guess, times[0])
        raise
    magnitudes, _ = rank_magnitudes(model.Phi_q(q, times[0]))
    rank = numerical_rank(magnitudes, model.rank_rtol)
    scales = row_scales(model.Phi_q(q, times[0]), model.rank_rtol)
    if rank < model.m:
        raise ModelError(f"{system.name} is not fully driven at t = {times[0]:g}: rank Phi_q = {rank} < m = "
                         f"{model.m}, {model.m - rank} degree(s) of freedom left; add drives "
                         f"(System.add_drive) for them (drives now: {system.drives or 'none'})")
    rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    message = ""
    state = (float(times[0]), q, qd, _accelerations(model, q, qd, times[0]))
    for k, time in enumerate(times):
        try:
            if k:
                state = _advance(model, state, float(time), tol, depth=0, scales=scales)
            _check_regular(model, *state[:2], scales)
        except _Stop as stop:
            message = str(stop)
            break
        rows.append(state[1:])
    count = len(rows)
    q_rows, qd_rows, qdd_rows = (np.array([row[i] for row in rows]).reshape(count, model.m) for i in range(3))
    states = [[model.point_state(name, *state, t=time) for time, state in zip(times, rows)] for name in names]
    point_values = {name: {quantity: np.array([state[quantity] for state in series]).reshape(count, -1)
                           for quantity in ("position", "velocity", "acceleration")}
                    for name, series in zip(names, states)}
    return Kinematics(times[:count], q_rows, qd_rows, qdd_rows, model.coordinate_names, point_values, message)


def inverse_dynamics(model: NumericModel, t, q_guess, *, actuated: Sequence[str] | None = None,
                     points: Sequence[str] | None = None, tol: float = 1e-12) -> InverseDynamicsRun:
    """Forces along the motion that the drives prescribe, with multipliers and joint reactions.

    The motion is :func:`kinematic_analysis`; at each time the forces solve Eq. 23 with
    actuators ``B u`` added to ``f_Q``::

        M qdd + C qd + g - f_Q + Phi_q^T lambda = B u

    * ``actuated=None``: the drives are the actuators.  ``u_k = -lambda_k`` of drive
      ``k`` (:attr:`kronlag.System.drives`), the generalized force it applies along
      its target: a torque for a driven angle, a force for a driven length or point
      coordinate.
    * ``actuated=("theta1", "theta2")``: these coordinates carry the actuators and the
      drives only prescribe the motion (they are left out of ``Phi``, their ``lambda``
      is 0).  Fewer actuators than the degrees of freedom of the mechanism without
      its drives is a :class:`~kronlag.ModelError` (under-actuated); more gives the
      minimum-norm split with an :class:`~kronlag.ActuationWarning` (over-actuated);
      see :meth:`kronlag.NumericModel.inverse_dynamics`.

    Parameters
    ----------
    model, t, q_guess, points, tol
        As for :func:`kinematic_analysis`.
    actuated : sequence of coordinate names, optional

    Returns
    -------
    InverseDynamicsRun
        ``forces`` (N, n_a), ``lam`` (N, r), ``mu`` (N, 0), ``reactions``; rows up to where
        the kinematic analysis stopped (``message``).
    """
    system = model.equations.system
    if not system.drives:
        raise ModelError(f"{system.name} has no drives: prescribe the motion with System.add_drive")
    names = [item.name for item in system.constraints]
    drive_rows = [names.index(name) for name in system.drives]
    if actuated is None:
        labels, constraints, columns = tuple(system.drives), None, tuple[str, ...]()
    else:
        labels, columns = tuple(str(name) for name in actuated), tuple(actuated)
        constraints = _mechanism_rows(model)
    motion = kinematic_analysis(model, t, q_guess, points=points, tol=tol)
    if actuated is not None and len(motion.t):
        freedom = _freedom_without_drives(model, motion.q[0], motion.t[0])
        if len(columns) < freedom:
            raise ModelError(f"under-actuated: {len(columns)} actuator(s) {list(columns)} for the {freedom} degrees "
                             f"of freedom of {system.name} without its drives")
    result = model.inverse_dynamics_trajectory(motion.t, motion.q, motion.qd, motion.qdd, actuated=columns,
                                               constraints=constraints)
    forces = -result.lam[:, drive_rows] if actuated is None else result.forces
    return InverseDynamicsRun(motion.t, motion.q, motion.qd, motion.qdd, motion.coordinate_names, motion.points,
                              motion.message, labels, forces, result.lam, result.mu,
                              reaction_columns(model, motion.t, motion.q, result.lam), model)
