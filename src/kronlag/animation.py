"""Animations of a mechanism from the drawing hints of its model.

A :class:`~kronlag.system.System` carries drawing hints: polylines
(:meth:`~kronlag.system.System.add_drawing_line`) whose vertices are points
given as expressions of the coordinates and parameters, and traced points
(:meth:`~kronlag.system.System.add_trace`).  :func:`animate` evaluates them
along a :class:`~kronlag.trajectory.Trajectory` and writes a GIF, an MP4 or
a self-contained HTML page; :func:`render_frame` saves a single frame.

Links are drawn as lines and joints as dots at the polyline vertices; points
that do not depend on the coordinates (ground pivots) get a grey triangle,
and each traced point leaves its path behind it.  Planar models are drawn
with equal axis scales, spatial ones (3-vector points) in a 3-D view; the
axis limits are fixed, computed from all frames.
"""

from __future__ import annotations

import html
import itertools
import re
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

if TYPE_CHECKING:
    from matplotlib.animation import AbstractMovieWriter
    from matplotlib.figure import Figure

    from .numeric import NumericModel
    from .system import System
    from .trajectory import Trajectory

__all__ = ["animate", "render_frame", "SUPPORTED_FORMATS"]

#: File extensions :func:`animate` writes.
SUPPORTED_FORMATS = (".gif", ".mp4", ".html", ".htm")

#: Points of the traced paths per interval between frames: the paths stay smooth at low frame rates.
_PATH_SUBSTEPS = 8

ParameterValues = Mapping[str | sp.Symbol, float | Callable[[float], float]]

_HTML_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
</head>
<body>
{body}
</body>
</html>
"""


# -- evaluating the drawing hints ---------------------------------------------------


@dataclass(frozen=True)
class _Drawing:
    """The drawing hints evaluated at T times, of which F are frames (points of dimension 2 or 3)."""

    title: str
    times: np.ndarray  # (T,)
    frames: np.ndarray  # (F,): indices into times
    lines: dict[str, np.ndarray]  # name -> (T, vertices, dim)
    traces: dict[str, np.ndarray]  # name -> (T, dim)
    fixed_points: np.ndarray  # (K, dim): vertices that do not move

    @property
    def dimension(self) -> int:
        return self.fixed_points.shape[1]

    def all_points(self) -> np.ndarray:
        """Every drawn point at every time, shape (P, dim)."""
        blocks = [points.reshape(-1, self.dimension) for points in self.lines.values()]
        return np.concatenate(blocks + list(self.traces.values()) + [self.fixed_points])


def _model_parameters(model: NumericModel, times: np.ndarray) -> dict[str, float | np.ndarray]:
    """The model's parameter values by name: floats, or arrays over ``times`` if some parameter varies."""
    if model.time_varying:
        values = np.array([model.parameter_vector(time) for time in times]).T
    else:
        values = model.parameter_vector()
    return dict(zip(model.parameter_names, values))


def _parameter_values(traj: Trajectory, symbols: list[sp.Symbol], parameters: ParameterValues | None,
                      times: np.ndarray) -> list[float | np.ndarray]:
    """Values of ``symbols`` at ``times``: from ``parameters`` where given, else the trajectory's model."""
    given = {**_model_parameters(traj.model, times),
             **{getattr(key, "name", key): value for key, value in (parameters or {}).items()}}
    values = [given[symbol.name] for symbol in symbols]
    return [np.array([value(time) for time in times]) if callable(value) else value for value in values]


def _evaluate_drawing(traj: Trajectory, frame_times: np.ndarray, parameters: ParameterValues | None) -> _Drawing:
    """Evaluate the drawing hints of the trajectory's system at ``frame_times`` and, for smooth traced
    paths, at :data:`_PATH_SUBSTEPS` times per interval between frames (``q`` resampled by :func:`_resample`).

    All points are compiled into one NumPy function of ``(q, parameters)``
    with :func:`sympy.lambdify` and evaluated for all times at once.
    """
    system: System = traj.model.equations.system
    if not system.drawing and not system.traces:
        raise ValueError(f"model {system.name!r} has no drawing hints; describe what to draw with "
                         "System.add_drawing_line and System.add_trace")
    points = [point for line in system.drawing for point in line.points] + [trace.points[0]
                                                                             for trace in system.traces]
    dimension = points[0].rows
    entries = [entry for point in points for entry in point]
    used = set().union(*(entry.free_symbols for entry in entries))
    symbols = [parameter for parameter in system.parameters if parameter in used]
    function = sp.lambdify([*system.coordinates, *symbols], entries, modules="numpy", cse=True)
    fractional_frames = np.arange((len(frame_times) - 1) * _PATH_SUBSTEPS + 1) / _PATH_SUBSTEPS
    times = np.interp(fractional_frames, np.arange(len(frame_times)), frame_times)
    raw = function(*_resample(traj, times).T, *_parameter_values(traj, symbols, parameters, times))
    values = np.stack([np.broadcast_to(np.asarray(value, dtype=float), times.shape) for value in raw], axis=-1)
    values = values.reshape(len(times), len(points), dimension)

    lines, start = {}, 0
    for line in system.drawing:
        lines[line.name] = values[:, start:start + len(line.points)]
        start += len(line.points)
    traces = {trace.name: values[:, start + k] for k, trace in enumerate(system.traces)}
    coordinates = set(system.coordinates)
    fixed = [values[0, k] for k, point in enumerate(points[:start]) if not point.free_symbols & coordinates]
    fixed_points = np.unique(np.array(fixed).reshape(-1, dimension), axis=0)
    frames = np.arange(len(frame_times)) * _PATH_SUBSTEPS
    return _Drawing(system.name, times, frames, lines, traces, fixed_points)


def _resample(traj: Trajectory, times: np.ndarray) -> np.ndarray:
    """Coordinates at ``times`` by cubic Hermite interpolation of ``q`` and ``qd``, shape (len(times), m)."""
    from scipy.interpolate import CubicHermiteSpline

    sample_times, first = np.unique(traj.t, return_index=True)
    if len(sample_times) == 1:
        return np.repeat(traj.q[first], len(times), axis=0)
    return CubicHermiteSpline(sample_times, traj.q[first], traj.qd[first], axis=0)(times)


# -- drawing ------------------------------------------------------------------------


def _set_points(artist, points: np.ndarray) -> None:
    """Move a line artist to ``points`` (n, 2) or (n, 3)."""
    if points.shape[1] == 3:
        artist.set_data_3d(*points.T)
    else:
        artist.set_data(*points.T)


class _Scene:
    """A figure showing the mechanism at one frame at a time, with axis limits that fit all frames."""

    _FIGURE_WIDTH = 6.0  # inches
    _RATIOS = (0.5, 1.5)  # smallest and largest height/width of a planar view

    def __init__(self, drawing: _Drawing, *, trace: bool, dpi: float):
        from matplotlib.figure import Figure

        self.drawing = drawing
        lower, upper = self._limits(drawing)
        planar = drawing.dimension == 2
        height = self._FIGURE_WIDTH
        if planar:
            height *= (upper[1] - lower[1]) / (upper[0] - lower[0])
        self.figure = Figure(figsize=(self._FIGURE_WIDTH, height + 0.8), dpi=dpi, layout="constrained")
        axes = self.figure.add_subplot(projection=None if planar else "3d")
        for axis, low, high in zip("xyz", lower, upper):
            getattr(axes, f"set_{axis}lim")(low, high)
            getattr(axes, f"set_{axis}label")(axis)
        if planar:
            axes.set_aspect("equal")
            axes.grid(True, alpha=0.25)
        else:
            axes.set_box_aspect((1, 1, 1), zoom=0.9)  # room for the z label
        self.title = axes.set_title("")  # the model's name and the time, set by show()

        if len(drawing.fixed_points):
            axes.plot(*drawing.fixed_points.T, linestyle="none", marker="^", markersize=14, color="0.6",
                      zorder=1)
        colors = (f"C{k}" for k in itertools.count())
        self.lines = {name: axes.plot(*points[0].T, color=next(colors), linewidth=3, marker="o", markersize=7,
                                      markerfacecolor="white", markeredgewidth=2, solid_capstyle="round",
                                      label=name, zorder=3)[0]
                      for name, points in drawing.lines.items()}
        self.paths, self.tracers = {}, {}
        if trace:
            for name, path in drawing.traces.items():
                color = next(colors)
                self.paths[name] = axes.plot(*path[:1].T, color=color, linewidth=1.2, alpha=0.8, label=name,
                                             zorder=2)[0]
                self.tracers[name] = axes.plot(*path[:1].T, color=color, marker="o", markersize=4, zorder=4)[0]
        if self.lines or self.paths:  # below the view, where it cannot hide the mechanism
            self.figure.legend(loc="outside lower center", ncols=min(len(self.lines) + len(self.paths), 4),
                               fontsize="small", frameon=False)
        # Lay out once: frames only move artists inside the axes and change the title's digits; a layout
        # engine would redo the layout for every frame.
        self.show(0)
        self.figure.draw_without_rendering()
        self.figure.set_layout_engine("none")

    @classmethod
    def _limits(cls, drawing: _Drawing) -> tuple[np.ndarray, np.ndarray]:
        """Axis limits: the padded box around all points; a cube in 3-D, in the plane widened or
        heightened to a height/width ratio within ``_RATIOS`` so that the view fills the figure."""
        points = drawing.all_points()
        low, high = points.min(axis=0), points.max(axis=0)
        size = (high - low).max() or 1.0
        span = 1.1 * (high - low) + 0.1 * size
        if drawing.dimension == 3:
            span[:] = span.max()
        else:
            smallest, largest = cls._RATIOS
            span = np.array([max(span[0], span[1] / largest), max(span[1], span[0] * smallest)])
        middle = (low + high) / 2
        return middle - span / 2, middle + span / 2

    def show(self, frame: int) -> None:
        """Put the mechanism in its position at ``frame``."""
        drawing = self.drawing
        index = drawing.frames[frame]
        for name, line in self.lines.items():
            _set_points(line, drawing.lines[name][index])
        for name, path in self.paths.items():
            _set_points(path, drawing.traces[name][:index + 1])
            _set_points(self.tracers[name], drawing.traces[name][index:index + 1])
        self.title.set_text(f"{drawing.title}    t = {drawing.times[index]:.3f}")

    def record(self, writer: AbstractMovieWriter, path: Path, dpi: float) -> None:
        """Write every frame with a matplotlib movie writer."""
        with writer.saving(self.figure, path, dpi):
            for frame in range(len(self.drawing.frames)):
                self.show(frame)
                writer.grab_frame()


# -- output -------------------------------------------------------------------------


#: Text for the player's buttons, whose icons matplotlib takes from a web font on a CDN.
_BUTTON_TEXT = {"fa-minus": "\u2212", "fa-fast-backward": "|\u25c0\u25c0", "fa-step-backward": "|\u25c0",
                "fa-play fa-flip-horizontal": "\u25c0", "fa-pause": "\u275a\u275a", "fa-play": "\u25b6",
                "fa-step-forward": "\u25b6|", "fa-fast-forward": "\u25b6\u25b6|", "fa-plus": "+"}


def _self_contained(fragment: str) -> str:
    """matplotlib's HTML player without its external stylesheet: icon elements become text."""
    fragment = re.sub(r"<link\b[^>]*>", "", fragment)
    return re.sub(r'<i class="fa ([^"]*)"></i>',
                  lambda icon: _BUTTON_TEXT.get(icon[1], icon[1].replace("fa-", "")), fragment)


def _html_page(scene: _Scene, *, fps: float, dpi: float) -> str:
    """A self-contained HTML page (frames embedded as base64 PNG) that plays the animation."""
    from matplotlib.animation import HTMLWriter

    with tempfile.TemporaryDirectory() as folder:
        fragment = Path(folder) / "animation.html"
        scene.record(HTMLWriter(fps=fps, embed_frames=True), fragment, dpi)
        body = _self_contained(fragment.read_text(encoding="utf-8"))
    return _HTML_PAGE.format(title=html.escape(scene.drawing.title), body=body)


def _movie_writer(suffix: str, fps: float) -> AbstractMovieWriter:
    from matplotlib.animation import FFMpegWriter, PillowWriter

    if suffix == ".gif":
        return PillowWriter(fps=fps)
    if not FFMpegWriter.isAvailable():
        raise RuntimeError("writing .mp4 needs ffmpeg, which was not found (install it, or set the matplotlib "
                           "rcParam animation.ffmpeg_path); .gif and .html work without it")
    return FFMpegWriter(fps=fps)


def animate(traj: Trajectory, path: str | PathLike | None = None, *, fps: float = 30,
            duration: float | None = None, trace: bool = True, dpi: float = 100,
            parameters: ParameterValues | None = None) -> Path | str:
    """Animate the mechanism along a trajectory, from its model's drawing hints.

    The coordinates are resampled to ``round(duration * fps) + 1`` frames
    evenly spaced from the first to the last time of the trajectory (cubic
    Hermite interpolation of ``q`` with ``qd``); the traced paths are drawn
    with more points than frames, so that they stay smooth.

    Parameters
    ----------
    traj : Trajectory
        The motion.  Its model provides the drawing hints
        (``model.equations.system``) and the parameter values
        (``model.parameter_vector(t)``, in the order of ``model.parameter_names``).
    path : str or path-like, optional
        Output file: ``.gif`` (Pillow), ``.mp4`` (needs ffmpeg) or
        ``.html``/``.htm`` (a self-contained page that plays the frames,
        embedded as base64 PNG images, with player controls).  Without a path
        the HTML page is returned as a string (for a notebook:
        ``IPython.display.HTML(traj.animate())``).
    fps : float
        Frames per second of the output.
    duration : float, optional
        Playing time in seconds; by default the simulated time span (real time).
    trace : bool
        Draw the paths of the model's traced points.
    dpi : float
        Resolution; a frame is about ``6 * dpi`` pixels wide.
    parameters : mapping, optional
        Parameter values (by name or symbol; floats or callables of time) to
        draw with instead of the model's, e.g. to exaggerate a small part.

    Returns
    -------
    pathlib.Path or str
        The path written, or the HTML page when ``path`` is None.

    Raises
    ------
    ValueError
        Unsupported file extension, non-positive ``fps``/``duration``, or a
        model without drawing hints.
    RuntimeError
        ``.mp4`` requested but ffmpeg is not installed.
    """
    target = None if path is None else Path(path)
    suffix = ".html" if target is None else target.suffix.lower()
    if suffix not in SUPPORTED_FORMATS:
        raise ValueError(f"cannot write an animation to {str(path)!r}: "
                         f"the file extension must be one of {', '.join(SUPPORTED_FORMATS)}")
    if fps <= 0 or (duration is not None and duration <= 0):
        raise ValueError(f"fps and duration must be positive, got fps={fps}, duration={duration}")
    writer = None if suffix in (".html", ".htm") else _movie_writer(suffix, fps)
    if duration is None:
        duration = abs(traj.t[-1] - traj.t[0])
    times = np.linspace(traj.t[0], traj.t[-1], round(duration * fps) + 1)
    scene = _Scene(_evaluate_drawing(traj, times, parameters), trace=trace, dpi=dpi)
    if writer is not None:
        scene.record(writer, target, dpi)
        return target
    page = _html_page(scene, fps=fps, dpi=dpi)
    if target is None:
        return page
    target.write_text(page, encoding="utf-8")
    return target


def render_frame(traj: Trajectory, index: int, path: str | PathLike, *, trace: bool = True, dpi: float = 100,
                 parameters: ParameterValues | None = None) -> Figure:
    """Save the mechanism at sample ``traj.t[index]`` as an image (PNG, or the format of the extension).

    The figure is the one :func:`animate` draws when its frames are the
    samples (same axis limits); the traced paths run up to ``index``.
    Options are those of :func:`animate`.

    Returns
    -------
    matplotlib.figure.Figure
        The figure, for further changes (its axes' ``transData`` maps model
        coordinates to pixels of the saved image, origin at the bottom left).
    """
    count = len(traj.t)
    if not -count <= index < count:
        raise IndexError(f"frame index {index} is out of range for a trajectory of {count} samples")
    scene = _Scene(_evaluate_drawing(traj, np.asarray(traj.t), parameters), trace=trace, dpi=dpi)
    scene.show(index % count)
    scene.figure.savefig(path, dpi=dpi)
    return scene.figure
