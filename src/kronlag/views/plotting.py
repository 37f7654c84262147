"""Time-history plots of a :class:`~kronlag.trajectory.Trajectory`.

:func:`plot_trajectory` draws, in one figure, the coordinates ``q``, the
velocities ``qd``, the multipliers ``lambda`` / ``mu``, the energies, the
constraint drift and the named reactions of the joints
(:func:`plot_joint_reactions`: the reactions alone).  matplotlib is imported
only when a plot is made; figures that are not shown are plain
:class:`matplotlib.figure.Figure` objects that need no GUI backend, so
plotting works on machines without a display.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp
from sympy.printing.conventions import split_super_sub

from ..core.errors import InputError
from ..numeric.friction import friction_joints
from ..numeric.reactions import GENERALIZED_FORCE_UNITS, REACTION_UNITS, multiplier_labels
from ..simulation.labelled import rate_unit
from ..simulation.trajectory import LimitEvent

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from ..model.joints import Joint
    from ..simulation.trajectory import Trajectory
    from ..studies.drives import InverseDynamicsRun, Kinematics

__all__ = ["plot_trajectory", "plot_joint_reactions", "plot_reactions", "plot_kinematics", "plot_inverse_dynamics"]

_PANEL_HEIGHT = 2.8  # inches per row of panels
_FIGURE_WIDTH = 12.0


def _has_display() -> bool:
    """Whether a GUI backend could open a window (always on macOS and Windows)."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or
                                                         os.environ.get("WAYLAND_DISPLAY"))


def _pyplot():
    """``matplotlib.pyplot``, switched to the non-interactive Agg backend when there is no display.

    A backend chosen by the user (``MPLBACKEND``, e.g. by Jupyter, or an
    earlier import of pyplot) is left alone.
    """
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules and "MPLBACKEND" not in os.environ and not _has_display():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _new_figure(*, show: bool = False, **options) -> Figure:
    """A new figure: managed by pyplot if it is to be shown, otherwise a standalone one.

    Standalone figures need no backend and are not kept alive by pyplot, so
    making many of them in a loop does not leak memory.

    Parameters
    ----------
    show : bool
        Create the figure through pyplot so that ``pyplot.show()`` displays it.
    **options
        Passed to :class:`matplotlib.figure.Figure` (``figsize``, ``layout``, ...).
    """
    if show:
        return _pyplot().figure(**options)
    from matplotlib.figure import Figure

    return Figure(**options)


def _math_label(name: str, *, dots: int = 0) -> str:
    """Mathtext label of a symbol name, with ``dots`` accents for its time derivatives:
    ``"phi1"``, 1 -> ``$\\dot{\\phi}_{1}$``; 2 -> ``$\\ddot{\\phi}_{1}$``."""
    if dots:  # SymPy prints the modifier suffixes "dot", "ddot" of a base name as accents over it
        base, superscripts, subscripts = split_super_sub(name)
        name = (base + {1: "dot", 2: "ddot"}[dots] + "".join(f"_{s}" for s in subscripts)
                + "".join(f"^{s}" for s in superscripts))
    return f"${sp.latex(sp.Symbol(name))}$"


def _plot_series(axes: Axes, time: np.ndarray, values: np.ndarray, labels: Sequence[str], *,
                 title: str, ylabel: str, styles: Mapping[str, Mapping[str, str]] | None = None) -> None:
    """One line per column of ``values`` against ``time``, with a legend beside the axes;
    ``styles`` gives line options (``color``, ``linestyle``) by label."""
    for column, label in zip(values.T, labels):
        axes.plot(time, column, label=label, linewidth=1.3, **(styles or {}).get(label, {}))
    axes.set_title(title)
    axes.set_ylabel(ylabel)
    axes.grid(True, alpha=0.3)
    axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False,
                ncols=1 + (len(labels) - 1) // 8)


def _with_unit(label: str, unit: str | None) -> str:
    """``label (unit)``, or ``label`` when the unit is not known."""
    return f"{label} ({unit})" if unit else label


def _coordinates_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    _plot_series(axes, traj.t, traj.q,
                 [_with_unit(_math_label(name), units.get(name)) for name in traj.coordinate_names],
                 title="Coordinates", ylabel="$q$")


def _velocities_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    _plot_series(axes, traj.t, traj.qd,
                 [_with_unit(_math_label(name, dots=1), rate_unit(units.get(name), units))
                  for name in traj.coordinate_names],
                 title="Velocities", ylabel=r"$\dot{q}$")


def _multiplier_labels(run: Trajectory | InverseDynamicsRun, units: Mapping[str, str]) -> list[str]:
    """A legend label per multiplier, by constraint name, with its unit (``N``, ``N*m``:
    :func:`kronlag.numeric.reactions.multiplier_units`) when the model is in SI units; a run
    without its model has the multipliers' symbols ``lambda1``, ``mu1``, ..."""
    if run.model is None:
        return ([_math_label(f"lambda{j + 1}") for j in range(run.lam.shape[1])]
                + [_math_label(f"mu{k + 1}") for k in range(run.mu.shape[1])])
    system = run.model.equations.system
    return (multiplier_labels(system, dict(units), with_units=units.get("energy") == "J")
            + [f"mu[{item.name}]" for item in system.nonholonomic_constraints])


def _multipliers_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    _plot_series(axes, traj.t, np.hstack([traj.lam, traj.mu]), _multiplier_labels(traj, units),
                 title="Lagrange multipliers", ylabel=r"$\lambda,\ \mu$")


def _energy_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    kinetic, potential = traj.kinetic_energy, traj.potential_energy
    _plot_series(axes, traj.t, np.column_stack([kinetic, potential, kinetic + potential]),
                 ["kinetic $T$", r"potential $\Pi$", r"total $E = T + \Pi$"], title="Energy",
                 ylabel=_with_unit("energy", units.get("energy")))


def _energy_drift_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    """``E(t) - E(t0) - W(t)`` (:attr:`Trajectory.energy_balance`): the work ``W`` of the non-conservative
    forces (friction, dampers, applied forces, a controller's inputs) is energy exchanged, not drift."""
    _plot_series(axes, traj.t, traj.energy_balance[:, None], ["$E(t) - E(t_0) - W(t)$"],
                 title="Total-energy drift", ylabel=_with_unit(r"$\Delta E$", units.get("energy")))


def _friction_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    """Each joint's friction force or torque (against its rate)."""
    joints = friction_joints(traj.model.equations.system)
    columns = traj.friction_columns()
    _plot_series(axes, traj.t, np.column_stack([columns[f"{joint.name}.friction"] for joint in joints]),
                 [joint.name for joint in joints], title="joint friction (force or torque)",
                 ylabel="friction (N or N*m)" if units.get("energy") == "J" else "friction")


def _constraint_drift_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    series = {r"position $\|\Phi(q)\|$": traj.position_residual,
              r"velocity $\|\Phi_q \dot{q}\|$" if traj.mu.shape[1] == 0 else
              r"velocity $\|[\Phi_q \dot{q};\ A \dot{q} + b]\|$": traj.velocity_residual}
    drawn = []
    for label, residual in series.items():
        if residual.shape[1] == 0:
            continue
        norm = np.linalg.norm(residual, axis=1)
        # A log axis cannot show exact zeros; leave those samples out of the line.
        positive = np.where(norm > 0, norm, np.nan)
        if np.isfinite(positive).any():
            axes.semilogy(traj.t, positive, label=label, linewidth=1.3)
            drawn.append(label)
    axes.set_title("Constraint drift")
    axes.set_ylabel("residual norm")
    axes.grid(True, which="major", alpha=0.3)
    if drawn:
        axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    else:
        axes.text(0.5, 0.5, "constraints satisfied exactly", transform=axes.transAxes, ha="center",
                  va="center", color="0.4")


def _reaction_unit(kind: str, units: Mapping[str, str]) -> str | None:
    """The unit of a reaction's ``"force"`` or ``"couple"`` in a model whose energy is in J."""
    return REACTION_UNITS[kind] if units.get("energy") == "J" else None


def _reaction_force_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str], *, joint: Joint,
                          frame: str = "world") -> None:
    force = traj.reaction(joint.name, frame=frame).force
    labels = [f"$F_{axis}$" for axis in "xyz"[:force.shape[1]]] + ["$|F|$"]
    where = "" if frame == "world" else f" ({joint.body_b} frame)"
    _plot_series(axes, traj.t, np.column_stack([force, np.linalg.norm(force, axis=1)]), labels,
                 title=f"{joint.name}: force of {joint.body_a} on {joint.body_b}{where}",
                 ylabel=_with_unit("force", _reaction_unit("force", units)),
                 styles={"$|F|$": {"color": "black", "linestyle": "--"}})


def _reaction_couple_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str], *,
                           joints: Sequence[Joint], frame: str = "world",
                           title: str = "Joint couples (on body B)") -> None:
    columns, labels = [], []
    for joint in joints:
        torque = traj.reaction(joint.name, frame=frame).torque
        columns.append(torque)
        labels += [f"{joint.name} $M_{axis}$" for axis in ("z" if torque.shape[1] == 1 else "xyz")]
    _plot_series(axes, traj.t, np.hstack(columns), labels, title=title,
                 ylabel=_with_unit("couple", _reaction_unit("couple", units)))


def _transmits_couple(joint: Joint) -> bool:
    """Whether the joint's reaction has a couple (``T`` rows of its wrench map not all zero)."""
    return any(entry != 0 for entry in joint.wrench[joint.dimension:, :])


def _selected_joints(traj: Trajectory, reactions: bool | Sequence[str] | None) -> list[Joint]:
    """The joints whose reactions ``reactions`` asks for (see :func:`plot_trajectory`)."""
    system = traj.model.equations.system
    joints = {joint.name: joint for joint in system.joints}
    if reactions is None or reactions is True:
        if reactions is True and not joints:
            raise InputError(f"reactions=True: {system.name} has no joints (System.add_joint) to plot the "
                             "reactions of")
        return list(joints.values())
    if reactions is False:
        return []
    if isinstance(reactions, str):
        raise TypeError(f"reactions must be a list of joint names, None, True or False, got the string "
                        f"{reactions!r} (write [{reactions!r}])")
    unknown = [name for name in reactions if name not in joints]
    if unknown:
        raise InputError(f"reactions: no joint named {', '.join(map(repr, unknown))} in {system.name} "
                         f"(joints: {', '.join(joints) or 'none'})")
    return [joints[name] for name in reactions]


def _panels(traj: Trajectory, reactions: bool | Sequence[str] | None
            ) -> list[Callable[[Axes, Trajectory, Mapping[str, str]], None]]:
    """The panels to draw: multipliers and constraint drift only for a constrained model, then a
    force panel per selected joint and one panel of the couples of those that transmit one."""
    constrained = traj.lam.shape[1] + traj.mu.shape[1] > 0
    panels = [_coordinates_panel, _velocities_panel]
    if constrained:
        panels += [_multipliers_panel, _constraint_drift_panel]
    panels += [_energy_panel, _energy_drift_panel]
    if traj.limit_forces is not None:
        panels.append(_limit_forces_panel)
    if friction_joints(traj.model.equations.system):
        panels.append(_friction_panel)
    joints = _selected_joints(traj, reactions)
    panels += [functools.partial(_reaction_force_panel, joint=joint) for joint in joints]
    couples = [joint for joint in joints if _transmits_couple(joint)]
    if couples:
        panels.append(functools.partial(_reaction_couple_panel, joints=couples))
    return panels


def _limit_sides(traj: Trajectory) -> list[str]:
    return [side.name for limit in traj.model.equations.system.limits for side in limit.sides]


def _limit_forces_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    """The contact forces of the limit sides (0 while free)."""
    # a generalized force: its unit is the energy's over the gap's (a force for a length, a torque for an angle)
    _plot_series(axes, traj.t, traj.limit_forces, _limit_sides(traj), title="limit contact forces",
                 ylabel="force along the gap")


#: Most impacts labelled with their limit's name (a Zeno sequence has many; all are marked).
_MAX_EVENT_LABELS = 12


def _mark_limit_events(panels: list[Axes], traj: Trajectory) -> None:
    """A vertical line at every limit event in every panel (impacts dashed, contacts and releases
    dotted), the first impacts labelled with the side's name in the first panel."""
    events = [event for event in traj.events if isinstance(event, LimitEvent)]
    for k, event in enumerate(events):
        style = "--" if event.kind == "impact" else ":"
        for axes in panels:
            axes.axvline(event.t, color="tab:gray", linestyle=style, linewidth=0.8, alpha=0.7)
        if k < _MAX_EVENT_LABELS and panels:
            panels[0].annotate(f"{event.kind}: {event.side}", (event.t, 1.0), xycoords=("data", "axes fraction"),
                               rotation=90, fontsize=6, va="top", ha="right", color="tab:gray")


def _title(traj: Trajectory) -> str:
    name = traj.model.equations.system.name
    title = f"{name}: {traj.method}, t = [{traj.t[0]:g}, {traj.t[-1]:g}], {len(traj.t)} samples"
    if traj.status != 0:
        title += f"\nintegration FAILED: {traj.message}"
    return title


def plot_trajectory(traj: Trajectory, *, path: str | PathLike | None = None, show: bool = False,
                    units: Mapping[str, str] | None = None,
                    reactions: bool | Sequence[str] | None = None) -> Figure:
    """Plot the time histories of a trajectory in one figure.

    Panels (sharing the time axis): coordinates ``q``; velocities ``qd``;
    multipliers ``lambda1 ..`` and ``mu1 ..`` and the constraint drift
    ``||Phi(q)||``, ``||[Phi_q qd; A qd + b]||`` on a log scale (both only if
    the model has constraints); kinetic, potential and total energy; the
    total-energy drift ``E(t) - E(t0)`` (a conservation check for models
    without driving or dissipative forces); then the named reactions of the
    joints (:meth:`kronlag.System.add_joint`, :mod:`kronlag.reactions`): a
    panel per joint with the force ``F = (Fx, Fy[, Fz])`` that body A exerts
    on body B at B's joint point and ``|F|``, in world components, and one
    panel with the couples ``T`` of the joints that transmit one.  A failed
    integration is flagged in the title.

    Parameters
    ----------
    traj : Trajectory
        The result of :func:`kronlag.simulate`.
    path : str or path-like, optional
        Save the figure there; the format (PNG, PDF, SVG, ...) follows the
        file extension.
    show : bool
        Display the figure with ``matplotlib.pyplot.show()`` (on a machine
        without a display the Agg backend is used and nothing opens).
    units : mapping of str to str, optional
        Units by coordinate name, ``"t"`` (time) and ``"energy"``, as
        :func:`kronlag.workflows.model_units` finds them in a model file;
        quantities without a unit are labelled without one (reactions are in
        ``N`` and ``N*m`` when the energy is in ``J``).
    reactions : None, bool or sequence of str
        The joints whose reactions are drawn: ``None`` (default) every joint of
        the system, if it has any; ``True`` every joint (an error if there is
        none); ``False`` none; a list of joint names, those.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        ``reactions`` names a joint the system does not have.
    """
    units = dict(units or {})
    panels = _panels(traj, reactions)
    rows = -(-len(panels) // 2)
    figure = _new_figure(show=show, figsize=(_FIGURE_WIDTH, 0.6 + _PANEL_HEIGHT * rows), layout="constrained")
    grid = figure.subplots(rows, 2, sharex=True, squeeze=False)
    for axes, panel in zip(grid.flat, panels):
        panel(axes, traj, units)
    _mark_limit_events(list(grid.flat[:len(panels)]), traj)
    return _finish(figure, grid, used=len(panels), title=_title(traj), failed=traj.status != 0, units=units,
                   path=path, show=show)


def _finish(figure: Figure, grid: np.ndarray, *, used: int, title: str, failed: bool, units: Mapping[str, str],
            path: str | PathLike | None, show: bool) -> Figure:
    """Remove the grid's cells after the first ``used``, label the lowest time axis of each column
    (with its tick labels) and the figure (red if the run failed); save and show it as asked."""
    for axes in grid.flat[used:]:
        axes.remove()
    columns = grid.shape[1]
    for column in range(min(columns, used)):
        lowest = grid[(used - column + columns - 1) // columns - 1, column]  # panels fill the grid row by row
        lowest.xaxis.set_tick_params(labelbottom=True)
        lowest.set_xlabel(_with_unit("time $t$", units.get("t")))
    figure.suptitle(title, color="tab:red" if failed else "black")
    if path is not None:
        figure.savefig(path)
    if show:
        _pyplot().show()
    return figure


def _series_figure(run: Kinematics, series: list[tuple[str, str, np.ndarray, list[str]]], title: str, *,
                   units: Mapping[str, str], path: str | PathLike | None, show: bool) -> Figure:
    """One panel per ``(title, ylabel, values (N, k), labels)`` of ``series`` against ``run.t``."""
    figure = _new_figure(show=show, figsize=(_FIGURE_WIDTH / 2 + 1.5, 0.6 + _PANEL_HEIGHT * len(series)),
                         layout="constrained")
    grid = figure.subplots(len(series), 1, sharex=True, squeeze=False)
    for axes, (panel, ylabel, values, labels) in zip(grid.flat, series):
        _plot_series(axes, run.t, values, labels, title=panel, ylabel=ylabel)
    if not run.success:
        title += f"\nFAILED {run.message}"
    return _finish(figure, grid, used=len(series), title=title, failed=not run.success, units=units, path=path,
                   show=show)


def _kinematic_series(run: Kinematics, units: Mapping[str, str]) -> list[tuple[str, str, np.ndarray, list[str]]]:
    """Panels of the coordinates, and of the named points' positions."""
    series = [("Coordinates", "$q$", run.q,
               [_with_unit(_math_label(name), units.get(name)) for name in run.coordinate_names])]
    if run.points:
        positions = np.hstack([state["position"] for state in run.points.values()])
        labels = [f"{point} {axis}" for point, state in run.points.items()
                  for axis in "xyz"[:state["position"].shape[1]]]
        series.append(("Points", "position", positions, labels))
    return series


def plot_kinematics(run: Kinematics, *, path: str | PathLike | None = None, show: bool = False,
                    units: Mapping[str, str] | None = None) -> Figure:
    """Plot the result of :func:`kronlag.kinematic_analysis`: the coordinates ``q``, their speeds
    ``qd`` and accelerations ``qdd``, and the named points' positions.  Options as for
    :func:`plot_trajectory`."""
    units = dict(units or {})
    names = run.coordinate_names
    series = _kinematic_series(run, units)
    series[1:1] = [("Speeds", r"$\dot{q}$", run.qd,
                    [_with_unit(_math_label(name, dots=1), rate_unit(units.get(name), units)) for name in names]),
                   ("Accelerations", r"$\ddot{q}$", run.qdd, [_with_unit(_math_label(name, dots=2),
                                                                              rate_unit(units.get(name), units, 2))
                                                                   for name in names])]
    return _series_figure(run, series, f"kinematic analysis: {len(run.t)} samples", units=units, path=path,
                          show=show)


def plot_joint_reactions(traj: Trajectory, joints: Sequence[str] | None = None, *, frame: str = "world",
                         path: str | PathLike | None = None, show: bool = False,
                         units: Mapping[str, str] | None = None) -> Figure:
    """Plot the reactions of ``joints`` (default: every joint) over time, a row per joint: the force
    ``F`` that body A exerts on body B at B's joint point and ``|F|`` on the left, the couple ``T``
    on B on the right (:mod:`kronlag.reactions`), in world or B's body components (``frame``).

    Options as for :func:`plot_trajectory`; returns the figure.

    Raises
    ------
    ValueError
        The system has no joints, or ``joints`` names one it does not have; ``frame`` is not
        ``"world"`` or ``"body"``.
    """
    units = dict(units or {})
    selected = _selected_joints(traj, True if joints is None else joints)
    if not selected:
        raise InputError("joints: give at least one joint name (or None for every joint)")
    figure = _new_figure(show=show, figsize=(_FIGURE_WIDTH, 0.6 + _PANEL_HEIGHT * len(selected)),
                         layout="constrained")
    grid = figure.subplots(len(selected), 2, sharex=True, squeeze=False)
    for (forces, couples), joint in zip(grid, selected):
        _reaction_force_panel(forces, traj, units, joint=joint, frame=frame)
        _reaction_couple_panel(couples, traj, units, joints=[joint], frame=frame,
                               title=f"{joint.name}: couple on {joint.body_b}")
    title = f"{traj.model.equations.system.name}: joint reactions ({frame} components)"
    return _finish(figure, grid, used=grid.size, title=title, failed=traj.status != 0, units=units, path=path,
                   show=show)


#: The name of :func:`plot_joint_reactions` in ``kronlag.reactions`` of earlier versions.
plot_reactions = plot_joint_reactions


def _joint_force_magnitudes(columns: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``|F|`` by joint name from reaction columns ``<joint>.Fx, <joint>.Fy[, <joint>.Fz]``."""
    components: dict[str, list[np.ndarray]] = {}
    for label, values in columns.items():
        joint, _, component = label.rpartition(".")
        if component in ("Fx", "Fy", "Fz"):
            components.setdefault(joint, []).append(values)
    return {joint: np.linalg.norm(np.column_stack(values), axis=1) for joint, values in components.items()}


def plot_inverse_dynamics(run: InverseDynamicsRun, *, path: str | PathLike | None = None, show: bool = False,
                          units: Mapping[str, str] | None = None) -> Figure:
    """Plot the result of :func:`kronlag.inverse_dynamics`.

    Panels: the coordinates ``q`` (and the named points), the actuator forces
    ``u`` (on the actuated coordinates, or of the drives), the multipliers
    ``lambda`` / ``mu`` (if the model has constraints) and, if the model has
    joints, the magnitude ``|F|`` of every joint's reaction force
    (``run.reactions``, :mod:`kronlag.reactions`).  Force units are ``N*m`` on
    an angle and ``N`` on a length, when the energy is in ``J``.  Options as for
    :func:`plot_trajectory`.
    """
    units = dict(units or {})
    force_units = GENERALIZED_FORCE_UNITS if units.get("energy") == "J" else {}
    series = _kinematic_series(run, units)
    series.append(("Actuator forces", "generalized force", run.forces,
                   [_with_unit(f"on {_math_label(name)}" if name in run.coordinate_names else name,
                               force_units.get(units.get(name, ""))) for name in run.actuated]))
    if run.lam.shape[1] + run.mu.shape[1]:
        series.append(("Lagrange multipliers", r"$\lambda,\ \mu$", np.hstack([run.lam, run.mu]),
                       _multiplier_labels(run, units)))
    joint_forces = _joint_force_magnitudes(run.reactions)
    if joint_forces:
        series.append(("Joint reaction forces", _with_unit("$|F|$", _reaction_unit("force", units)),
                       np.column_stack(list(joint_forces.values())), list(joint_forces)))
    return _series_figure(run, series, f"inverse dynamics: forces on {', '.join(run.actuated)}, {len(run.t)} samples",
                          units=units, path=path, show=show)
