"""The model commands of the command line (``models``, ``derive``, ``export``, ``check``, ``simulate``,
``kinematics``, ``inverse``): thin shells over the Python API and :mod:`kronlag.app.workflows`."""

from __future__ import annotations

import argparse
import importlib.util
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..core.errors import InputError, ModelError
from ..core.limits import MAX_OUTPUT_POINTS
from ..model.builtin import BUILTIN_MODELS, example_names, example_path, resolve_model
from ..model.modelfile import ModelFile, SimulationSettings, load_model
from ..simulation import METHODS
from ..simulation.solvers import AUTO_PREFERENCE
from ..symbolic.derivation import derive
from ..symbolic.export import FORMATS, LANGUAGES, export_code, file_stem, format_equations
from ..views.animation import SUPPORTED_FORMATS, check_animation_target, playing_speed
from ..views.plotting import plot_inverse_dynamics, plot_kinematics
from .outputs import PLOT_SUFFIXES, OutputKind, emit, finish_run, no_check, requested_outputs
from .workflows import (
    check_model,
    initial_state,
    inverse_dynamics_along,
    kinematics_along,
    model_units,
    numeric_model,
    parse_drive,
    simulate_model,
    summarize,
)

__all__ = ["add_commands", "ProgressBar", "positive", "count", "method_help", "model_file"]


def model_file(arguments: argparse.Namespace) -> ModelFile:
    """The command's MODEL, a robot file read with ``--coordinates`` and ``--floating-base``."""
    return resolve_model(arguments.model, coordinates=arguments.coordinates, floating_base=arguments.floating_base)


#: Default output grid of ``simulate``: a point every _GRID_SPACING of simulated time, within
#: _GRID_POINTS points, so that a long run takes bounded memory.
_GRID_SPACING, _GRID_POINTS = 0.01, (1001, 100_001)


#: Advice appended to an integrator's failure message, by a pattern in that message.
_FAILURE_HINTS = {
    r"maximum number of steps|TOO_MUCH_WORK": "raise the step limit with --max-steps",
    r"RHSFUNC_FAIL|singular": "the equations could not be evaluated, usually a singular configuration "
                              "(a singular mass matrix or constraint Jacobian, e.g. Euler angles at gimbal lock)",
}


#: Largest turn of an angle coordinate between animation frames that the eye follows (radians); the CLI
#: suggests a slower --speed above it (a crank turning half a revolution per frame seems to stand still).
_SMOOTH_TURN = np.pi / 3


#: The modules an --output format needs beyond kronlag's own dependencies, and the extra that brings them.
_FORMAT_NEEDS = {".parquet": (("pandas", "pyarrow"), "parquet"), ".nc": (("xarray",), "xarray")}


def _check_format(path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    needs, extra = _FORMAT_NEEDS.get(path.suffix, ((), ""))
    if not all(importlib.util.find_spec(name) for name in needs):
        raise ModelError(f"--output {path}: writing {path.suffix} needs {' and '.join(needs)} (pip install "
                         f"{' '.join(needs)}, or kronlag[{extra}]); .csv and .npz need nothing more")


def _check_animation(path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    try:
        check_animation_target(path, fps=arguments.fps)
    except (ValueError, RuntimeError) as error:
        raise ModelError(f"--animate {path}: {error}") from None
    system = model.system
    if not system.drawing and not system.traces:
        raise ModelError(f"--animate {path}: model {system.name!r} has no [[drawing]] or [[traces]] to draw")


def _save_trajectory(trajectory, path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    {".parquet": lambda: trajectory.to_dataframe().to_parquet(path), ".csv": lambda: trajectory.to_csv(path),
     ".npz": lambda: trajectory.to_npz(path),
     ".nc": lambda: trajectory.to_xarray(units=model_units(model)).to_netcdf(path)}[path.suffix]()


def _save_columns(run, path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    {".csv": lambda: run.to_csv(path), ".npz": lambda: run.to_npz(path),
     ".nc": lambda: run.to_xarray(units=model_units(model)).to_netcdf(path)}[path.suffix]()


#: The words ``--reactions`` takes besides joint names, as ``plot_trajectory(reactions=...)`` values.
_REACTION_WORDS = {"all": True, "none": False}


def _reaction_selection(arguments: argparse.Namespace) -> bool | list[str] | None:
    """``--reactions`` as :func:`kronlag.plotting.plot_trajectory` takes it: every joint (not given, or
    ``all``), none, or the joints named (separated by commas)."""
    text = arguments.reactions
    if text is None or text in _REACTION_WORDS:
        return _REACTION_WORDS.get(text)
    return [name.strip() for name in text.split(",")]


def _check_reactions(path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    joints = [joint.name for joint in model.system.joints]
    selection = _reaction_selection(arguments)
    if selection is True and not joints:
        raise ModelError(f"--reactions all: model {model.system.name!r} has no [[joints]]")
    unknown = [name for name in selection if name not in joints] if isinstance(selection, list) else []
    if unknown:
        raise ModelError(f"--reactions: no joint named {', '.join(map(repr, unknown))} in model "
                         f"{model.system.name!r} (joints: {', '.join(joints) or 'none'})")


def _plot_trajectory(trajectory, path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    trajectory.plot(path=path, units=model_units(model), reactions=_reaction_selection(arguments))


def _animate(trajectory, path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    trajectory.animate(path, fps=arguments.fps, speed=arguments.speed, duration=arguments.duration)
    angles = [k for k, name in enumerate(trajectory.coordinate_names) if model_units(model).get(name) == "rad"]
    speed = playing_speed(trajectory.t[-1] - trajectory.t[0], fps=arguments.fps, speed=arguments.speed,
                          duration=arguments.duration)
    turn = float(np.max(np.abs(trajectory.qd[:, angles]), initial=0.0)) * speed / arguments.fps
    if turn > _SMOOTH_TURN:
        slower = float(f"{speed * _SMOOTH_TURN / turn:.1g}")
        print(f"note: an angle turns by up to {np.degrees(turn):.0f} degrees between frames of {path}, too fast to "
              f"follow; --speed {slower:g} (or a higher --fps) shows the motion smoothly", file=sys.stderr)


def _plot_inverse(run, path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    plot_inverse_dynamics(run, path=path, units=model_units(model))


def _plot_kinematics(run, path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    plot_kinematics(run, path=path, units=model_units(model))


_SIMULATION_OUTPUTS = (OutputKind("--output", (".csv", ".npz", ".parquet", ".nc"), _check_format, _save_trajectory),
                       OutputKind("--plot", PLOT_SUFFIXES, _check_reactions, _plot_trajectory),
                       OutputKind("--animate", SUPPORTED_FORMATS, _check_animation, _animate))


_INVERSE_OUTPUTS = (OutputKind("--output", (".csv", ".npz", ".nc"), _check_format, _save_columns),
                    OutputKind("--plot", PLOT_SUFFIXES, no_check, _plot_inverse))


_KINEMATICS_OUTPUTS = (OutputKind("--output", (".csv", ".npz", ".nc"), _check_format, _save_columns),
                       OutputKind("--plot", PLOT_SUFFIXES, no_check, _plot_kinematics))


def _models(arguments: argparse.Namespace) -> None:
    for name in example_names():
        kind = "built-in" if name in BUILTIN_MODELS else "example"
        print(f"{name:<18} {kind:<9} {load_model(example_path(name), apply_drives=False).description}")
    folder = example_path(example_names()[0]).parent
    print(f"\nmodel files: {folder}  (copy one to start a model of your own)")


def _derive(arguments: argparse.Namespace) -> None:
    equations = derive(model_file(arguments).system, simplify=arguments.simplify)
    emit(format_equations(equations, arguments.format), arguments.output)


def _export(arguments: argparse.Namespace) -> None:
    if (arguments.lang is None) == (arguments.fmu is None):
        raise InputError("export: give either --lang LANGUAGE (code) or --fmu FILE (an FMU)")
    if arguments.fmu is not None:
        _export_fmu(arguments)
        return
    equations = derive(model_file(arguments).system, simplify=arguments.simplify)
    emit(export_code(equations, arguments.lang), arguments.output)


def _export_fmu(arguments: argparse.Namespace) -> None:
    """``export --fmu FILE``: :func:`kronlag.export_fmu` of the model with its file's parameter values,
    assembled initial state, ``t_end`` and ``rtol``."""
    from ..views.fmu import export_fmu

    model = model_file(arguments)
    numeric = numeric_model(model)
    q0, qd0 = initial_state(model, numeric)
    path = export_fmu(numeric, arguments.fmu, q0=q0, qd0=qd0, stop_time=model.simulation.t_end,
                      tolerance=model.simulation.rtol, units={**model.units, **model_units(model)},
                      fmi_version=arguments.fmi_version)
    print(f"{path}: FMI {arguments.fmi_version} FMU (model exchange and co-simulation) of {model.system.name!r}")


def _check(arguments: argparse.Namespace) -> None:
    model = model_file(arguments)
    check = check_model(model)
    if check.assembly_error:  # bad input: the file's [initial] state is not a state of the mechanism
        print(check.report())
        raise ModelError(f"{model.source}: [initial]: the initial state cannot be assembled: {check.assembly_error}")
    print(f"{model.source}: valid model file")
    if getattr(model.system, "robot", None) is not None:  # a robot file: its structure first
        print(model.system.describe())
    print(check.report())


class ProgressBar:
    """Draws the simulated time on a terminal, once a run has lasted ``delay`` seconds.

    Called with the time after every integration step; redraws at most ten
    times a second, and draws nothing on a stream that is not a terminal.
    """

    def __init__(self, t_end: float, stream, *, delay: float = 0.5, width: int = 30):
        self.t_end, self.stream, self.delay, self.width = t_end, stream, delay, width
        self.started = time.monotonic()
        self.drawn_at: float | None = None
        self.enabled = hasattr(stream, "isatty") and stream.isatty()

    def __call__(self, t: float) -> None:
        now = time.monotonic()
        if not self.enabled or now - self.started < self.delay or (
                self.drawn_at is not None and now - self.drawn_at < 0.1):
            return
        self.drawn_at = now
        filled = int(self.width * min(max(t / self.t_end, 0.0), 1.0))
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] t = {t:.4g} / {self.t_end:.4g}")
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line, if one was drawn."""
        if self.drawn_at is not None:
            self.stream.write("\n")
            self.stream.flush()


def output_times(t_end: float, *, points: int | None = None, dt: float | None = None,
                 default_points: int = 101) -> np.ndarray:
    """Output times 0 .. t_end: every ``dt`` (``--dt``), or ``points`` (``--points``) evenly spaced, or
    ``default_points``; InputError for a step or count that is not positive, or more than
    :data:`~kronlag.core.limits.MAX_OUTPUT_POINTS` times (checked before allocating them)."""
    if dt is not None:
        if not dt > 0:
            raise InputError(f"--dt {dt:g}: the output step must be positive")
        if t_end / dt + 1 > MAX_OUTPUT_POINTS:
            raise InputError(f"--dt {dt:g} gives {t_end / dt + 1:.3g} output times up to "
                             f"t = {t_end:g}, more than the limit of {MAX_OUTPUT_POINTS}: give a larger --dt")
        return np.append(np.arange(0.0, t_end * (1 - 1e-12), dt), t_end)
    if points is not None and points > MAX_OUTPUT_POINTS:
        raise InputError(f"--points {points}: more than the limit of {MAX_OUTPUT_POINTS} output times")
    if points is not None and points < 2:
        raise InputError(f"--points {points}: give at least 2 output times (t = 0 and t_end)")
    return np.linspace(0.0, t_end, points or default_points)


def _default_points(t_end: float) -> int:
    """A point every _GRID_SPACING, within the _GRID_POINTS bounds."""
    return int(np.clip(round(t_end / _GRID_SPACING) + 1, *_GRID_POINTS))


def _failure_hint(message: str) -> str:
    hints = [hint for pattern, hint in _FAILURE_HINTS.items() if re.search(pattern, message, re.IGNORECASE)]
    return "; ".join([message.rstrip("."), *hints])


def _simulate(arguments: argparse.Namespace) -> None:
    model = model_file(arguments)
    if arguments.reactions is not None and arguments.plot is None:
        raise ModelError("--reactions selects what --plot draws: give --plot FILE too")
    outputs = requested_outputs(_SIMULATION_OUTPUTS, arguments, model)
    t_end = arguments.t_end if arguments.t_end is not None else model.simulation.t_end
    bar = ProgressBar(t_end, sys.stderr)
    interrupted = False
    t_eval = output_times(t_end, points=arguments.points, dt=arguments.dt, default_points=_default_points(t_end))
    try:
        trajectory = simulate_model(model, t_end=t_end, method=arguments.method, rtol=arguments.rtol,
                                    atol=arguments.atol, t_eval=t_eval,
                                    max_steps=arguments.max_steps, progress=bar)
    except KeyboardInterrupt as interrupt:  # Ctrl-C: the partial run is written as a failed one is
        if not hasattr(interrupt, "trajectory"):
            raise
        trajectory, interrupted = interrupt.trajectory, True
    bar.close()
    print(summarize(trajectory).report())
    reached = trajectory.t[-1] if len(trajectory.t) else 0.0
    failure = f"{trajectory.message.rstrip('.')}; the trajectory reaches t = {reached:g}" if interrupted else (
        "" if trajectory.success else (f"simulation failed: {_failure_hint(trajectory.message)}; "
                                       f"the trajectory reaches t = {reached:g}"))
    finish_run(trajectory, outputs, arguments, model, failure=failure, save=trajectory.to_npz,
                rescue_name=f"{file_stem(model.system.name)}-trajectory.npz", interrupted=interrupted)


def _drives(arguments: argparse.Namespace, model: ModelFile) -> dict:
    """The drives of ``--drive`` options, or else the model file's ``[[drives]]``."""
    drives = dict(parse_drive(text, model) for text in arguments.drive) if arguments.drive else model.drives
    if not drives:
        raise ModelError("no drives: give --drive COORDINATE=EXPRESSION or [[drives]] in the model file")
    return drives


def _driven_run(arguments: argparse.Namespace, outputs_table, run_along, what: str, suffix: str, **options) -> None:
    """Run ``run_along(model, drives, times, **options)``, report it and write the outputs."""
    model = model_file(arguments)
    outputs = requested_outputs(outputs_table, arguments, model)
    drives = _drives(arguments, model)
    t_end = model.simulation.t_end if arguments.t_end is None else arguments.t_end
    run = run_along(model, drives, output_times(t_end, points=arguments.points, dt=arguments.dt), **options)
    print(run.report())
    failure = "" if run.success else f"{what} failed {run.message}"
    finish_run(run, outputs, arguments, model, failure=failure, save=run.to_csv,
                rescue_name=f"{file_stem(model.system.name)}-{suffix}.csv")


def _inverse(arguments: argparse.Namespace) -> None:
    actuated = [name.strip() for name in arguments.actuated.split(",")] if arguments.actuated else None
    _driven_run(arguments, _INVERSE_OUTPUTS, inverse_dynamics_along, "inverse dynamics", "inverse",
                actuated=actuated)


def _kinematics(arguments: argparse.Namespace) -> None:
    _driven_run(arguments, _KINEMATICS_OUTPUTS, kinematics_along, "kinematic analysis", "kinematics")


def positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def count(text: str) -> int:
    if not text.isdigit() or int(text) < 2:
        raise argparse.ArgumentTypeError(f"expected an integer of at least 2, got {text!r}")
    return int(text)


def method_help() -> str:
    """Help of ``--method``: every method of the solver registry, and the default marked."""
    default = SimulationSettings().method
    listed = ", ".join(f"{name} (the default)" if name == default else name for name in ("auto", *METHODS))
    return (f"integration method: {listed}; the default is the model file's [simulation] method when it gives "
            f"one; auto picks the first of {', '.join(AUTO_PREFERENCE)} that supports the model")


def _add_grid_options(sub: argparse.ArgumentParser, default: str) -> None:
    """``--dt`` or ``--points``: the output times."""
    grid = sub.add_mutually_exclusive_group()
    grid.add_argument("--dt", type=positive, metavar="STEP", help="output every STEP of time")
    grid.add_argument("--points", type=count, metavar="N", help=f"N evenly spaced output times (default: {default})")


def add_commands(command: Callable[..., argparse.ArgumentParser]) -> None:
    """Register the model commands with ``command(name, handler, summary, *, model=True)`` of the main parser."""
    command("models", _models, "list the built-in models and shipped example files", model=False)

    sub = command("derive", _derive, "derive and print the equations of motion (Eq. 23)")
    sub.add_argument("--format", choices=FORMATS, default="text", help="output format (default: text)")
    sub.add_argument("--simplify", action="store_true", help="apply trigsimp to every entry")
    sub.add_argument("--output", metavar="FILE", help="write to FILE instead of standard output")

    sub = command("export", _export, "write standalone code for M, C, g, Phi, Phi_q, Phi_t, gamma, A, b, f_Q, "
                  "or an FMU (--fmu)")
    sub.add_argument("--lang", choices=LANGUAGES, help="target language")
    sub.add_argument("--fmu", metavar="FILE", help="write an FMU (model exchange and co-simulation, "
                     "compiled for this platform) instead of code; needs FMPy's FMI headers (pip install kronlag[fmu])")
    sub.add_argument("--fmi-version", choices=("2.0", "3.0"), default="2.0", help="FMI version of --fmu "
                     "(default: 2.0)")
    sub.add_argument("--simplify", action="store_true", help="apply trigsimp to every entry first")
    sub.add_argument("--output", metavar="FILE", help="write to FILE instead of standard output")

    command("check", _check, "validate a model; report degrees of freedom and constraint ranks at the guess")

    sub = command("simulate", _simulate, "assemble the initial state and integrate the equations of motion")
    sub.add_argument("--t-end", type=positive, help="final time (default: the model's [simulation] t_end)")
    sub.add_argument("--method", help=method_help())
    sub.add_argument("--rtol", type=positive, help="relative tolerance")
    sub.add_argument("--atol", type=positive, help="absolute tolerance")
    sub.add_argument("--max-steps", type=count, metavar="N", help="stop after N integrator steps "
                     "(default: kronlag.simulate's, which grows with the time span)")
    _add_grid_options(sub, f"a point every {_GRID_SPACING:g} of time, at least {_GRID_POINTS[0]} and at most "
                           f"{_GRID_POINTS[1]} points")
    sub.add_argument("--output", metavar="FILE", help="save the trajectory (.csv, .npz, .parquet or .nc: "
                     "netCDF, labelled arrays with the model file's units)")
    sub.add_argument("--plot", metavar="FILE", help="save a figure of the time histories (.png, .pdf, .svg, .jpg), "
                     "with the reaction forces of the joints")
    sub.add_argument("--reactions", metavar="JOINTS", help="joints whose reactions --plot draws: all (default), "
                     "none, or names separated by commas (--output always has every joint's columns)")
    sub.add_argument("--animate", metavar="FILE", help="save an animation (.gif, .mp4 or .html)")
    sub.add_argument("--fps", type=positive, default=25.0,
                     help="animation frames per second (default: 25; a GIF plays at most 50)")
    pace = sub.add_mutually_exclusive_group()
    pace.add_argument("--speed", type=positive, help="simulated seconds per second of animation (default: 1, real "
                                                      "time; 0.1 shows a fast mechanism ten times slower)")
    pace.add_argument("--duration", type=positive, metavar="SECONDS", help="playing time of the animation")

    for name, handler, summary, outputs in (
            ("kinematics", _kinematics, "positions, speeds and accelerations along prescribed motions",
             "coordinates, speeds, accelerations and points"),
            ("inverse", _inverse, "actuator forces, multipliers and reactions along prescribed motions",
             "forces and multipliers")):
        sub = command(name, handler, summary)
        sub.add_argument("--drive", action="append", metavar="Q=EXPR",
                         help="prescribed motion of a coordinate as an expression of t, e.g. 'q1=2*pi*t' "
                              "(repeat for several, one per degree of freedom; default: the model's [[drives]])")
        sub.add_argument("--t-end", type=positive, help="final time (default: the model's [simulation] t_end)")
        _add_grid_options(sub, "101")
        sub.add_argument("--output", metavar="FILE", help="save the results (.csv, .npz or .nc: netCDF with units)")
        sub.add_argument("--plot", metavar="FILE", help=f"save a figure of the {outputs} (.png, .pdf, .svg, .jpg)")
    sub.add_argument("--actuated", metavar="Q1,Q2", help="the coordinates that carry the actuators, comma "
                     "separated (default: the driven coordinates); the drives then only prescribe the motion")
