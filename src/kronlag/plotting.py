"""Time-history plots of a :class:`~kronlag.trajectory.Trajectory`.

:func:`plot_trajectory` draws, in one figure, the coordinates ``q``, the
velocities ``qd``, the multipliers ``lambda`` / ``mu``, the energies and the
constraint drift.  matplotlib is imported only when a plot is made; figures
that are not shown are plain :class:`matplotlib.figure.Figure` objects that
need no GUI backend, so plotting works on machines without a display.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp
from sympy.printing.conventions import split_super_sub

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from .trajectory import Trajectory
    from .drives import InverseDynamicsRun, Kinematics

__all__ = ["plot_trajectory", "plot_kinematics", "plot_inverse_dynamics"]

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


def _math_label(name: str, *, dotted: bool = False) -> str:
    """Mathtext label of a symbol name, dotted for its velocity: ``"phi1"`` -> ``$\\dot{\\phi}_{1}$``."""
    if dotted:  # SymPy prints the modifier suffix "dot" of a base name as an accent over it
        base, superscripts, subscripts = split_super_sub(name)
        name = base + "dot" + "".join(f"_{s}" for s in subscripts) + "".join(f"^{s}" for s in superscripts)
    return f"${sp.latex(sp.Symbol(name))}$"


def _plot_series(axes: Axes, time: np.ndarray, values: np.ndarray, labels: Sequence[str], *,
                 title: str, ylabel: str) -> None:
    """One line per column of ``values`` against ``time``, with a legend beside the axes."""
    for column, label in zip(values.T, labels):
        axes.plot(time, column, label=label, linewidth=1.3)
    axes.set_title(title)
    axes.set_ylabel(ylabel)
    axes.grid(True, alpha=0.3)
    axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False,
                ncols=1 + (len(labels) - 1) // 8)


def _with_unit(label: str, unit: str | None) -> str:
    """``label (unit)``, or ``label`` when the unit is not known."""
    return f"{label} ({unit})" if unit else label


def _rate_unit(unit: str | None, units: Mapping[str, str]) -> str | None:
    """The unit of a time derivative, ``unit/s``, when both units are known."""
    return f"{unit}/{units['t']}" if unit and "t" in units else None


def _coordinates_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    _plot_series(axes, traj.t, traj.q,
                 [_with_unit(_math_label(name), units.get(name)) for name in traj.coordinate_names],
                 title="Coordinates", ylabel="$q$")


def _velocities_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    _plot_series(axes, traj.t, traj.qd,
                 [_with_unit(_math_label(name, dotted=True), _rate_unit(units.get(name), units))
                  for name in traj.coordinate_names],
                 title="Velocities", ylabel=r"$\dot{q}$")


def _multipliers_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    labels = ([_math_label(f"lambda{j + 1}") for j in range(traj.lam.shape[1])]
              + [_math_label(f"mu{k + 1}") for k in range(traj.mu.shape[1])])
    _plot_series(axes, traj.t, np.hstack([traj.lam, traj.mu]), labels,
                 title="Lagrange multipliers", ylabel=r"$\lambda,\ \mu$")


def _energy_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    kinetic, potential = traj.kinetic_energy, traj.potential_energy
    _plot_series(axes, traj.t, np.column_stack([kinetic, potential, kinetic + potential]),
                 ["kinetic $T$", r"potential $\Pi$", r"total $E = T + \Pi$"], title="Energy",
                 ylabel=_with_unit("energy", units.get("energy")))


def _energy_drift_panel(axes: Axes, traj: Trajectory, units: Mapping[str, str]) -> None:
    total = traj.kinetic_energy + traj.potential_energy
    _plot_series(axes, traj.t, (total - total[0])[:, None], ["$E(t) - E(t_0)$"],
                 title="Total-energy drift", ylabel=_with_unit(r"$\Delta E$", units.get("energy")))


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


def _panels(traj: Trajectory) -> list[Callable[[Axes, Trajectory, Mapping[str, str]], None]]:
    """The panels to draw: multipliers and constraint drift only for a constrained model."""
    constrained = traj.lam.shape[1] + traj.mu.shape[1] > 0
    panels = [_coordinates_panel, _velocities_panel]
    if constrained:
        panels += [_multipliers_panel, _constraint_drift_panel]
    return panels + [_energy_panel, _energy_drift_panel]


def _title(traj: Trajectory) -> str:
    name = traj.model.equations.system.name
    title = f"{name}: {traj.method}, t = [{traj.t[0]:g}, {traj.t[-1]:g}], {len(traj.t)} samples"
    if traj.status != 0:
        title += f"\nintegration FAILED: {traj.message}"
    return title


def plot_trajectory(traj: Trajectory, *, path: str | PathLike | None = None, show: bool = False,
                    units: Mapping[str, str] | None = None) -> Figure:
    """Plot the time histories of a trajectory in one figure.

    Panels (sharing the time axis): coordinates ``q``; velocities ``qd``;
    multipliers ``lambda1 ..`` and ``mu1 ..`` and the constraint drift
    ``||Phi(q)||``, ``||[Phi_q qd; A qd + b]||`` on a log scale (both only if
    the model has constraints); kinetic, potential and total energy; and the
    total-energy drift ``E(t) - E(t0)`` (a conservation check for models
    without driving or dissipative forces).  A failed integration is flagged
    in the title.

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
        quantities without a unit are labelled without one.

    Returns
    -------
    matplotlib.figure.Figure
    """
    units = dict(units or {})
    panels = _panels(traj)
    rows = len(panels) // 2
    figure = _new_figure(show=show, figsize=(_FIGURE_WIDTH, 0.6 + _PANEL_HEIGHT * rows), layout="constrained")
    grid = figure.subplots(rows, 2, sharex=True, squeeze=False)
    for axes, panel in zip(grid.flat, panels):
        panel(axes, traj, units)
    return _finish(figure, grid, title=_title(traj), failed=traj.status != 0, units=units, path=path, show=show)


def _finish(figure: Figure, grid: np.ndarray, *, title: str, failed: bool, units: Mapping[str, str],
            path: str | PathLike | None, show: bool) -> Figure:
    """Label the time axes and the figure (red if the run failed); save and show it as asked."""
    for axes in grid[-1]:
        axes.set_xlabel(_with_unit("time $t$", units.get("t")))
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
    return _finish(figure, grid, title=title, failed=not run.success, units=units, path=path, show=show)


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
                    [_with_unit(_math_label(name, dotted=True), _rate_unit(units.get(name), units)) for name in names]),
                   ("Accelerations", r"$\ddot{q}$", run.qdd, [_math_label(f"{name}dd") for name in names])]
    return _series_figure(run, series, f"kinematic analysis: {len(run.t)} samples", units=units, path=path,
                          show=show)


def plot_inverse_dynamics(run: InverseDynamicsRun, *, path: str | PathLike | None = None, show: bool = False,
                          units: Mapping[str, str] | None = None) -> Figure:
    """Plot the result of :func:`kronlag.inverse_dynamics`.

    Panels: the coordinates ``q`` (and the named points), the actuator forces
    ``u`` (on the actuated coordinates, or of the drives), and the multipliers
    ``lambda`` / ``mu`` (if the model has constraints).  Force units are ``N*m``
    on an angle and ``N`` on a length, when the energy is in ``J``.  Options as
    for :func:`plot_trajectory`.
    """
    units = dict(units or {})
    force_units = {"rad": "N*m", "m": "N"} if units.get("energy") == "J" else {}
    series = _kinematic_series(run, units)
    series.append(("Actuator forces", "generalized force", run.forces,
                   [_with_unit(f"on {_math_label(name)}" if name in run.coordinate_names else name,
                               force_units.get(units.get(name, ""))) for name in run.actuated]))
    if run.lam.shape[1] + run.mu.shape[1]:
        series.append(("Lagrange multipliers", r"$\lambda,\ \mu$", np.hstack([run.lam, run.mu]),
                       [_math_label(f"lambda{j + 1}") for j in range(run.lam.shape[1])]
                       + [_math_label(f"mu{k + 1}") for k in range(run.mu.shape[1])]))
    return _series_figure(run, series, f"inverse dynamics: forces on {', '.join(run.actuated)}, {len(run.t)} samples",
                          units=units, path=path, show=show)
