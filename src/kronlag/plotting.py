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
from collections.abc import Callable, Sequence
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp
from sympy.printing.conventions import split_super_sub

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from .trajectory import Trajectory

__all__ = ["plot_trajectory"]

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


def _coordinates_panel(axes: Axes, traj: Trajectory) -> None:
    _plot_series(axes, traj.t, traj.q, [_math_label(name) for name in traj.coordinate_names],
                 title="Coordinates", ylabel="$q$")


def _velocities_panel(axes: Axes, traj: Trajectory) -> None:
    _plot_series(axes, traj.t, traj.qd, [_math_label(name, dotted=True) for name in traj.coordinate_names],
                 title="Velocities", ylabel=r"$\dot{q}$")


def _multipliers_panel(axes: Axes, traj: Trajectory) -> None:
    labels = ([_math_label(f"lambda{j + 1}") for j in range(traj.lam.shape[1])]
              + [_math_label(f"mu{k + 1}") for k in range(traj.mu.shape[1])])
    _plot_series(axes, traj.t, np.hstack([traj.lam, traj.mu]), labels,
                 title="Lagrange multipliers", ylabel=r"$\lambda,\ \mu$")


def _energy_panel(axes: Axes, traj: Trajectory) -> None:
    kinetic, potential = traj.kinetic_energy, traj.potential_energy
    _plot_series(axes, traj.t, np.column_stack([kinetic, potential, kinetic + potential]),
                 ["kinetic $T$", r"potential $\Pi$", r"total $E = T + \Pi$"], title="Energy", ylabel="energy")


def _energy_drift_panel(axes: Axes, traj: Trajectory) -> None:
    total = traj.kinetic_energy + traj.potential_energy
    _plot_series(axes, traj.t, (total - total[0])[:, None], ["$E(t) - E(t_0)$"],
                 title="Total-energy drift", ylabel=r"$\Delta E$")


def _constraint_drift_panel(axes: Axes, traj: Trajectory) -> None:
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


def _panels(traj: Trajectory) -> list[Callable[[Axes, Trajectory], None]]:
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


def plot_trajectory(traj: Trajectory, *, path: str | PathLike | None = None, show: bool = False) -> Figure:
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

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels = _panels(traj)
    rows = len(panels) // 2
    figure = _new_figure(show=show, figsize=(_FIGURE_WIDTH, 0.6 + _PANEL_HEIGHT * rows), layout="constrained")
    grid = figure.subplots(rows, 2, sharex=True, squeeze=False)
    for axes, panel in zip(grid.flat, panels):
        panel(axes, traj)
    for axes in grid[-1]:
        axes.set_xlabel("time $t$")
    figure.suptitle(_title(traj), color="black" if traj.status == 0 else "tab:red")
    if path is not None:
        figure.savefig(path)
    if show:
        _pyplot().show()
    return figure
