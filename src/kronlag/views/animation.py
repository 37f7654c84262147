"""Animations of a mechanism from the drawing hints of its model.

A :class:`~kronlag.system.System` carries drawing hints: polylines
(:meth:`~kronlag.system.System.add_drawing_line`) whose vertices are points
given as expressions of the coordinates and parameters, and traced points
(:meth:`~kronlag.system.System.add_trace`).  :func:`animate` evaluates them
along a :class:`~kronlag.trajectory.Trajectory` and writes a GIF, an MP4 or
a self-contained HTML page; :func:`render_frame` saves a single frame.

Links are drawn as lines and joints as dots at the polyline vertices; points
that do not depend on the coordinates (ground pivots) get a grey triangle,
and each traced point leaves its path behind it.  Spatial models (3-vector
points) are drawn in a fixed oblique view with the x, y, z axes at the origin.
The view is fitted once around all frames.

Frames are drawn directly with Pillow (GIF, MP4 through ffmpeg) or, in the
HTML page, by a small script on a canvas from the pixel coordinates of the
frames: the page holds numbers, not images, and starts playing when loaded.
Frame ``k`` shows simulated time ``t0 + k * speed / fps`` and is shown at
``k / fps`` seconds of playing time: real time for ``speed = 1``.
"""

from __future__ import annotations

import html
import itertools
import json
import shutil
import subprocess
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from ..core.errors import InputError
from ..core.kernels import ExpressionFunction
from .solids import body_frames, hull, place

if TYPE_CHECKING:
    from PIL.Image import Image

    from ..model.system import System
    from ..numeric.numeric_model import NumericModel
    from ..simulation.trajectory import Trajectory

__all__ = ["animate", "render_frame", "check_animation_target", "playing_speed", "SUPPORTED_FORMATS"]

#: File extensions :func:`animate` writes.
SUPPORTED_FORMATS = (".gif", ".mp4", ".html", ".htm")

#: Points of the traced paths per interval between frames: the paths stay smooth at low frame rates.
_PATH_SUBSTEPS = 8

#: GIF frame delays are whole hundredths of a second, and browsers slow down delays below 2/100 s.
_GIF_MAX_FPS = 50

ParameterValues = Mapping[str | sp.Symbol, float | Callable[[float], float]]


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
    solids: dict[str, np.ndarray]  # a robot file's visuals: name -> (T, points, 3) (kronlag.views.solids)

    @property
    def dimension(self) -> int:
        return self.fixed_points.shape[1]

    def all_points(self) -> np.ndarray:
        """Every drawn point at every time, shape (P, dim)."""
        blocks = [points.reshape(-1, self.dimension) for points in self.lines.values()]
        solids = [points.reshape(-1, self.dimension) for points in self.solids.values()]
        return np.concatenate(blocks + solids + list(self.traces.values()) + [self.fixed_points])


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

    All points are compiled into one kernel of ``(q, parameters)``
    (:class:`kronlag.core.kernels.ExpressionFunction`) and evaluated for all times at once.
    """
    system: System = traj.model.equations.system
    if not system.drawing and not system.traces:
        raise InputError(f"model {system.name!r} has no drawing hints; describe what to draw with "
                         "System.add_drawing_line and System.add_trace")
    points = [point for line in system.drawing for point in line.points] + [trace.points[0]
                                                                             for trace in system.traces]
    dimension = points[0].rows
    frames_of_solids = body_frames(system) if dimension == 3 else {}
    entries = [entry for point in points for entry in point] + [entry for frame in frames_of_solids.values()
                                                                 for entry in frame]
    used = set().union(*(entry.free_symbols for entry in entries))
    symbols = [parameter for parameter in system.parameters if parameter in used]
    function = ExpressionFunction({"points": sp.Matrix(entries)}, [("q", system.coordinates), ("p", symbols)],
                                  name="drawing")
    fractional_frames = np.arange((len(frame_times) - 1) * _PATH_SUBSTEPS + 1) / _PATH_SUBSTEPS
    times = np.interp(fractional_frames, np.arange(len(frame_times)), frame_times)
    parameter_rows = np.column_stack([np.broadcast_to(np.asarray(value, dtype=float), times.shape) for value in
                                      _parameter_values(traj, symbols, parameters, times)] or
                                     [np.zeros((len(times), 0))])
    values = function.batch(_resample(traj, times), parameter_rows)["points"]
    values = values.reshape(len(times), -1)
    solid_values = values[:, len(points) * dimension:]
    values = values[:, :len(points) * dimension].reshape(len(times), len(points), dimension)
    solids = place(system, {body: solid_values[:, 12 * k:12 * k + 12]
                            for k, body in enumerate(frames_of_solids)}) if frames_of_solids else {}

    lines, start = {}, 0
    for line in system.drawing:
        lines[line.name] = values[:, start:start + len(line.points)]
        start += len(line.points)
    traces = {trace.name: values[:, start + k] for k, trace in enumerate(system.traces)}
    coordinates = set(system.coordinates)
    fixed = [values[0, k] for k, point in enumerate(points[:start]) if not point.free_symbols & coordinates]
    fixed_points = np.unique(np.array(fixed).reshape(-1, dimension), axis=0)
    frames = np.arange(len(frame_times)) * _PATH_SUBSTEPS
    return _Drawing(system.name, times, frames, lines, traces, fixed_points, solids)


def _resample(traj: Trajectory, times: np.ndarray) -> np.ndarray:
    """Coordinates at ``times`` by cubic Hermite interpolation of ``q`` and ``qd``, shape (len(times), m)."""
    from scipy.interpolate import CubicHermiteSpline

    sample_times, first = np.unique(traj.t, return_index=True)
    if len(sample_times) == 1:
        return np.repeat(traj.q[first], len(times), axis=0)
    return CubicHermiteSpline(sample_times, traj.q[first], traj.qd[first], axis=0)(times)


# -- timing -------------------------------------------------------------------------


def playing_speed(span: float, *, fps: float, speed: float | None, duration: float | None) -> float:
    """Simulated seconds per second of playing time: ``speed``, or ``span / duration``, or 1 (real time).

    Raises
    ------
    ValueError
        A non-positive ``fps``, ``speed`` or ``duration``, or both of the latter.
    """
    if duration is not None and speed is not None:
        raise InputError("give the playing speed or the duration of an animation, not both")
    for name, value in (("fps", fps), ("speed", speed), ("duration", duration)):
        if value is not None and not (value > 0 and np.isfinite(value)):
            raise InputError(f"{name} must be positive, got {value}")
    if duration is not None and span > 0:
        return span / duration
    return speed or 1.0


def _frame_times(t0: float, t1: float, *, fps: float, speed: float) -> np.ndarray:
    """Simulated times of the frames, ``t0 + k * speed / fps`` up to ``t1``."""
    interval = speed / fps
    count = int(np.floor((t1 - t0) / interval * (1 + 1e-12))) + 1 if t1 > t0 else 1
    return t0 + interval * np.arange(count)


def _gif_delays(count: int, fps: float) -> list[int]:
    """Delays of ``count`` GIF frames in milliseconds, whole hundredths of a second whose running
    sums stay within 5 ms of ``k / fps``: exact timing for 25 or 50 fps, rounding spread out otherwise."""
    ticks = np.round(np.arange(count + 1) * 100.0 / fps).astype(int)
    return [10 * int(delay) for delay in np.diff(ticks)]


# -- drawing ------------------------------------------------------------------------

#: matplotlib's default colour cycle (tab10), for the lines and then the traced points.
_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf")
_WHITE, _BLACK, _GROUND, _AXES = "#ffffff", "#000000", "#999999", "#c8c8c8"

#: View direction of spatial models (matplotlib's default 3-D view): azimuth and elevation.
_AZIMUTH, _ELEVATION = np.radians(-60.0), np.radians(30.0)


def _screen_axes() -> np.ndarray:
    """Rows: the unit vectors pointing right and up on the screen, for the view (_AZIMUTH, _ELEVATION)."""
    ca, sa, ce, se = np.cos(_AZIMUTH), np.sin(_AZIMUTH), np.cos(_ELEVATION), np.sin(_ELEVATION)
    return np.array([[-sa, ca, 0.0], [-se * ca, -se * sa, ce]])


def _pale(color: str) -> str:
    """``color`` mixed half and half with white: the colour of a traced path."""
    rgb = np.array([int(color[k:k + 2], 16) for k in (1, 3, 5)])
    return "#" + "".join(f"{value:02x}" for value in (rgb + 255) // 2)


class _Picture:
    """The mechanism in pixels: a view fitted around all frames, ``width`` pixels wide.

    Points are mapped to pixel coordinates (origin top left, y down) once;
    :meth:`images` draws the frames with Pillow and :meth:`html` hands the
    same coordinates to a canvas script, so both show the same picture.
    """

    _TITLE_HEIGHT = 28  # pixels above the view
    _RATIOS = (0.5, 1.5)  # smallest and largest height/width of the view

    def __init__(self, drawing: _Drawing, *, width: int, trace: bool):
        self.drawing = drawing
        project = (lambda points: points) if drawing.dimension == 2 else (lambda points: points @ _screen_axes().T)
        lines = {name: project(points) for name, points in drawing.lines.items()}
        traces = {name: project(path) for name, path in drawing.traces.items()} if trace else {}
        fixed = project(drawing.fixed_points)
        axes = self._axis_segments(drawing)
        solids = {name: project(points) for name, points in drawing.solids.items()}
        everything = np.concatenate([points.reshape(-1, 2) for points in [*lines.values(), *solids.values()]]
                                    + list(traces.values()) + [fixed, project(axes).reshape(-1, 2)])
        low, high = everything.min(axis=0), everything.max(axis=0)
        size = (high - low).max() or 1.0
        span = 1.1 * (high - low) + 0.1 * size
        smallest, largest = self._RATIOS
        span = np.array([max(span[0], span[1] / largest), max(span[1], span[0] * smallest)])
        middle = (low + high) / 2
        self.scale = (width - 1) / span[0]  # pixels per model length
        self.corner = np.array([middle[0] - span[0] / 2, middle[1] + span[1] / 2])  # top left, model units
        self.legend = [(name, _COLORS[k % len(_COLORS)]) for k, name in enumerate([*lines, *traces])]
        legend_height = 22 if self.legend else 0
        view_height = int(np.ceil(span[1] * self.scale))
        height = self._TITLE_HEIGHT + view_height + legend_height
        self.size = (width + width % 2, height + height % 2)  # even sizes, as video encoders want
        self.lines = {name: self._pixels(points) for name, points in lines.items()}
        self.traces = {name: self._pixels(path) for name, path in traces.items()}
        self.fixed = self._pixels(fixed)
        self.solids = {name: self._pixels(points) for name, points in solids.items()}
        # far to near: the depth of a solid is its mean along the view direction (towards the viewer)
        toward = np.cross(*_screen_axes()) if drawing.dimension == 3 else np.zeros(2)
        self.depths = {name: (points @ toward).mean(axis=1) for name, points in drawing.solids.items()}
        self.axes = self._pixels(project(axes))
        self.line_width = max(2, round(width / 160))

    @staticmethod
    def _axis_segments(drawing: _Drawing) -> np.ndarray:
        """The x, y and z axes from the origin, a fifth of the drawing's size long (spatial models), (k, 2, 3)."""
        if drawing.dimension == 2:
            return np.zeros((0, 2, 2))
        points = drawing.all_points()
        length = 0.2 * ((points.max(axis=0) - points.min(axis=0)).max() or 1.0)
        return np.stack([np.zeros((3, 3)), length * np.eye(3)], axis=1)

    def _pixels(self, points: np.ndarray) -> np.ndarray:
        """Integer pixel coordinates (..., 2) of model points (..., 2)."""
        offset = (points - self.corner) * self.scale * np.array([1.0, -1.0])
        return np.rint(offset + [0.0, self._TITLE_HEIGHT]).astype(int)

    def title(self, frame: int) -> str:
        return f"{self.drawing.title}    t = {self.drawing.times[self.drawing.frames[frame]]:.3f}"

    def images(self) -> Iterator[Image]:
        """The frames as palette images (palette: white, then the colours used)."""
        from PIL import Image, ImageDraw, ImageFont

        colors = [_WHITE, _BLACK, _GROUND, _AXES, *(color for _, color in self.legend),
                  *(_pale(color) for _, color in self.legend), *_COLORS, *map(_pale, _COLORS)]
        index = {color: k for k, color in reversed(list(enumerate(colors)))}
        palette = [int(color[k:k + 2], 16) for color in colors for k in (1, 3, 5)]
        font = ImageFont.load_default(size=14)
        width, radius = self.line_width, self.line_width + 1
        background = Image.new("P", self.size, 0)
        background.putpalette(palette)
        draw = ImageDraw.Draw(background)
        for (start, end), label in zip(self.axes, "xyz"):
            draw.line([tuple(start), tuple(end)], fill=index[_AXES], width=1)
            draw.text(tuple(end + 3), label, fill=index[_GROUND], font=font)
        for x, y in self.fixed:
            side = 3 * width
            draw.polygon([(x, y), (x - side, y + 2 * side), (x + side, y + 2 * side)], fill=index[_GROUND])
        x = 8
        for name, color in self.legend:
            y = self.size[1] - 12
            draw.line([(x, y), (x + 20, y)], fill=index[color], width=width)
            draw.text((x + 26, y - 8), name, fill=index[_BLACK], font=font)
            x += 40 + round(draw.textlength(name, font=font))
        colors_of = dict(self.legend)
        drawn_to = 0  # the traced paths are drawn on the background up to this time index
        for frame, time_index in enumerate(self.drawing.frames):
            background_draw = ImageDraw.Draw(background)
            for name, path in self.traces.items():
                segment = [tuple(point) for point in path[max(drawn_to - 1, 0):time_index + 1]]
                if len(segment) > 1:
                    background_draw.line(segment, fill=index[_pale(colors_of[name])], width=max(1, width // 2))
            drawn_to = time_index + 1
            image = background.copy()
            draw = ImageDraw.Draw(image)
            draw.text((8, 6), self.title(frame), fill=index[_BLACK], font=font)
            self._draw_solids(draw, index, time_index)
            for name, points in self.lines.items():
                vertices = [tuple(point) for point in points[time_index]]
                draw.line(vertices, fill=index[colors_of[name]], width=width, joint="curve")
                for x, y in vertices:
                    draw.ellipse([x - radius, y - radius, x + radius, y + radius], fill=index[_WHITE],
                                 outline=index[colors_of[name]], width=max(1, width - 1))
            for name, path in self.traces.items():
                x, y = path[time_index]
                draw.ellipse([x - radius, y - radius, x + radius, y + radius], fill=index[colors_of[name]])
            yield image

    def _draw_solids(self, draw, index: dict[str, int], time_index: int) -> None:
        """The robot's visuals at one time: convex silhouettes, far to near, one colour per solid."""
        names = list(self.solids)
        for k in sorted(range(len(names)), key=lambda k: self.depths[names[k]][time_index]):
            color = _COLORS[k % len(_COLORS)]
            outline = hull(self.solids[names[k]][time_index])
            if len(outline) >= 3:
                draw.polygon([tuple(point) for point in outline], fill=index[_pale(color)], outline=index[color])

    def html(self, *, fps: float, speed: float) -> str:
        """A page whose script draws the frames on a canvas, in a loop from when it is loaded
        (a click pauses and resumes); frame coordinates are inlined as JSON integers."""
        frames = self.drawing.frames
        data = {
            "fps": fps, "count": len(frames), "substeps": _PATH_SUBSTEPS, "title": self.drawing.title,
            "t0": float(self.drawing.times[0]), "step": speed / fps, "width": self.line_width,
            "lines": [{"color": dict(self.legend)[name], "xy": points[frames].ravel().tolist()}
                      for name, points in self.lines.items()],
            "traces": [{"color": dict(self.legend)[name], "pale": _pale(dict(self.legend)[name]),
                        "xy": path.ravel().tolist()} for name, path in self.traces.items()],
            "fixed": self.fixed.ravel().tolist(), "axes": self.axes.reshape(-1, 4).tolist(),
            "legend": self.legend, "colors": {"ground": _GROUND, "axes": _AXES},
        }
        return _HTML_PAGE.format(title=html.escape(self.drawing.title), width=self.size[0], height=self.size[1],
                                 data=json.dumps(data, separators=(",", ":")).replace("</", "<\\/"),
                                 script=_CANVAS_SCRIPT)


_HTML_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>body {{ margin: 0; background: #fff; }} canvas {{ display: block; cursor: pointer; }}</style>
</head>
<body>
<canvas id="animation" width="{width}" height="{height}" title="click to pause or resume"></canvas>
<script>
const D = {data};
{script}
</script>
</body>
</html>
"""

#: Draws frame k of D (the data of _Picture.html) on the canvas, as _Picture.images does with Pillow.
_CANVAS_SCRIPT = r"""
const canvas = document.getElementById("animation"), g = canvas.getContext("2d");
const w = D.width, r = D.width + 1;
g.font = "14px sans-serif";
function polyline(xy, from, to, color, width) {
  g.beginPath(); g.strokeStyle = color; g.lineWidth = width; g.lineJoin = g.lineCap = "round";
  for (let i = from; i < to; i += 2) { if (i === from) g.moveTo(xy[i], xy[i + 1]); else g.lineTo(xy[i], xy[i + 1]); }
  g.stroke();
}
function dot(x, y, fill, stroke) {
  g.beginPath(); g.arc(x, y, r, 0, 2 * Math.PI); g.fillStyle = fill; g.fill();
  if (stroke) { g.strokeStyle = stroke; g.lineWidth = Math.max(1, w - 1); g.stroke(); }
}
function draw(k) {
  g.fillStyle = "#fff"; g.fillRect(0, 0, canvas.width, canvas.height);
  g.fillStyle = D.colors.ground; g.textBaseline = "top";
  for (const [x0, y0, x1, y1] of D.axes) { polyline([x0, y0, x1, y1], 0, 4, D.colors.axes, 1); }
  D.axes.forEach(([x0, y0, x1, y1], i) => g.fillText("xyz"[i], x1 + 3, y1 + 3));
  for (let i = 0; i < D.fixed.length; i += 2) {
    const x = D.fixed[i], y = D.fixed[i + 1], s = 3 * w;
    g.beginPath(); g.moveTo(x, y); g.lineTo(x - s, y + 2 * s); g.lineTo(x + s, y + 2 * s); g.closePath(); g.fill();
  }
  const last = k * D.substeps;
  for (const t of D.traces) { polyline(t.xy, 0, 2 * last + 2, t.pale, Math.max(1, Math.floor(w / 2))); }
  for (const line of D.lines) {
    const n = line.xy.length / D.count, xy = line.xy.slice(k * n, (k + 1) * n);
    polyline(xy, 0, n, line.color, w);
    for (let i = 0; i < n; i += 2) dot(xy[i], xy[i + 1], "#fff", line.color);
  }
  for (const t of D.traces) dot(t.xy[2 * last], t.xy[2 * last + 1], t.color);
  g.fillStyle = "#000";
  g.fillText(D.title + "    t = " + (D.t0 + k * D.step).toFixed(3), 8, 6);
  let x = 8; const y = canvas.height - 12;
  for (const [name, color] of D.legend) {
    polyline([x, y, x + 20, y], 0, 4, color, w);
    g.fillStyle = "#000"; g.fillText(name, x + 26, y - 8);
    x += 40 + g.measureText(name).width;
  }
}
// Each frame is drawn at its playing time, k / fps seconds after the start, by a timer set to the next
// frame's time (timers also follow the virtual clock of a headless browser, where animation frames stop).
let origin = performance.now(), pausedAt = null;
function tick() {
  if (pausedAt !== null) return;
  const elapsed = (performance.now() - origin) * D.fps / 1000, k = Math.floor(elapsed);
  draw(k % D.count);
  setTimeout(tick, (k + 1 - elapsed) * 1000 / D.fps);
}
canvas.addEventListener("click", () => {
  if (pausedAt === null) { pausedAt = performance.now(); return; }
  origin += performance.now() - pausedAt; pausedAt = null; tick();
});
tick();
""".strip()


# -- output -------------------------------------------------------------------------


def _ffmpeg() -> str:
    """The path of the ffmpeg program."""
    program = shutil.which("ffmpeg")
    if program is None:
        raise RuntimeError("writing .mp4 needs ffmpeg, which was not found on the PATH (install it); "
                           ".gif and .html work without it")
    return program


def check_animation_target(path: str | PathLike, *, fps: float = 25.0) -> str:
    """Check, before any work, that :func:`animate` can write ``path`` at ``fps``; return its suffix.

    Raises
    ------
    ValueError
        Unsupported extension, or a GIF faster than 50 frames per second.
    RuntimeError
        ``.mp4`` without ffmpeg.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in SUPPORTED_FORMATS:
        raise InputError(f"cannot write an animation to {str(path)!r}: "
                         f"the file extension must be one of {', '.join(SUPPORTED_FORMATS)}")
    if suffix == ".gif" and fps > _GIF_MAX_FPS:
        raise InputError(f"a GIF plays at most {_GIF_MAX_FPS} frames per second (delays are whole hundredths of "
                         f"a second), got fps = {fps:g}; use a lower --fps or .html/.mp4")
    if suffix == ".mp4":
        _ffmpeg()
    return suffix


def _write_gif(picture: _Picture, path: Path, fps: float) -> None:
    first, *rest = picture.images()
    first.save(path, save_all=True, append_images=rest, duration=_gif_delays(1 + len(rest), fps), loop=0)


def _write_mp4(picture: _Picture, path: Path, fps: float) -> None:
    width, height = picture.size
    command = [_ffmpeg(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
               "-s", f"{width}x{height}", "-r", repr(float(fps)), "-i", "-", "-an", "-pix_fmt", "yuv420p",
               str(path)]
    with subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE) as process:
        try:
            for image in picture.images():
                process.stdin.write(image.convert("RGB").tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped; its message follows
        process.stdin.close()
        message = process.stderr.read().decode(errors="replace").strip()
    if process.returncode:
        raise RuntimeError(f"ffmpeg could not write {path}: {message}")


def animate(traj: Trajectory, path: str | PathLike | None = None, *, fps: float = 25.0,
            speed: float | None = None, duration: float | None = None, trace: bool = True, width: int = 480,
            parameters: ParameterValues | None = None) -> Path | str:
    """Animate the mechanism along a trajectory, from its model's drawing hints.

    Frame ``k`` shows the mechanism at ``t[0] + k * speed / fps`` (coordinates
    by cubic Hermite interpolation of ``q`` with ``qd``) and is shown ``k / fps``
    seconds after the start: by default (``speed = 1``) the animation plays in
    real time.  The traced paths are drawn with more points than frames, so
    that they stay smooth.

    Parameters
    ----------
    traj : Trajectory
        The motion.  Its model provides the drawing hints
        (``model.equations.system``) and the parameter values
        (``model.parameter_vector(t)``, in the order of ``model.parameter_names``).
    path : str or path-like, optional
        Output file: ``.gif`` (at most 50 fps; 25 or 50 fps give exact frame
        delays, other rates spread the rounding to 1/100 s), ``.mp4`` (needs
        ffmpeg) or ``.html``/``.htm`` (a self-contained page whose script draws
        the frames on a canvas and starts when loaded; a click pauses).
        Without a path the HTML page is returned as a string (for a notebook:
        ``IPython.display.HTML(traj.animate())``).
    fps : float
        Frames per second of playing time.
    speed : float, optional
        Simulated seconds per second of playing time (default 1: real time;
        0.1 shows a fast mechanism ten times slower).
    duration : float, optional
        Playing time in seconds, instead of ``speed``.
    trace : bool
        Draw the paths of the model's traced points.
    width : int
        Width of a frame in pixels; the height follows the drawing.
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
        Unsupported file extension, non-positive ``fps``/``speed``/``duration``
        or both of the latter, a GIF above 50 fps, or a model without drawing hints.
    RuntimeError
        ``.mp4`` requested but ffmpeg is not installed.
    """
    target = None if path is None else Path(path)
    suffix = ".html" if target is None else check_animation_target(target, fps=fps)
    t0, t1 = float(traj.t[0]), float(traj.t[-1])
    speed = playing_speed(t1 - t0, fps=fps, speed=speed, duration=duration)
    times = _frame_times(t0, t1, fps=fps, speed=speed)
    picture = _Picture(_evaluate_drawing(traj, times, parameters), width=width, trace=trace)
    if suffix in (".html", ".htm"):
        page = picture.html(fps=fps, speed=speed)
        if target is None:
            return page
        target.write_text(page, encoding="utf-8")
    else:
        {".gif": _write_gif, ".mp4": _write_mp4}[suffix](picture, target, fps)
    return target


def render_frame(traj: Trajectory, index: int, path: str | PathLike, *, trace: bool = True, width: int = 480,
                 parameters: ParameterValues | None = None) -> Image:
    """Save the mechanism at sample ``traj.t[index]`` as an image (PNG, or the format of the extension).

    The picture is the one :func:`animate` draws when its frames are the
    samples (same view); the traced paths run up to ``index``.  Options are
    those of :func:`animate`.

    Returns
    -------
    PIL.Image.Image
        The frame.
    """
    count = len(traj.t)
    if not -count <= index < count:
        raise IndexError(f"frame index {index} is out of range for a trajectory of {count} samples")
    picture = _Picture(_evaluate_drawing(traj, np.asarray(traj.t), parameters), width=width, trace=trace)
    image = next(itertools.islice(picture.images(), index % count, None))
    image.save(path)
    return image
