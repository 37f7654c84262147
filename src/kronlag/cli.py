"""Command-line interface: a thin shell over the Python API.

MODEL is the name of a built-in model or shipped example (``kronlag models``
lists them) or the path of a TOML model file (format: :mod:`kronlag.modelfile`).

Exit status: 0 success; 2 bad input (a message on stderr, no traceback);
1 numerical failure (what was computed is saved first).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from .derivation import derive
from .export import FORMATS, LANGUAGES, export_code, format_equations
from .modelfile import example_names, example_path, load_model, resolve_model
from .models import BUILTIN_MODELS
from .system import ModelError
from .workflows import check_model, inverse_dynamics_along, parse_drive, simulate_model, summarize

EXIT_OK, EXIT_NUMERICAL, EXIT_BAD_INPUT = 0, 1, 2
_TRAJECTORY_SUFFIXES = (".csv", ".npz", ".parquet")
_PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg")
_ANIMATION_SUFFIXES = (".gif", ".mp4", ".html", ".htm")
_INVERSE_SUFFIXES = (".csv", ".npz")


class NumericalFailure(Exception):
    """A computation failed; the message says what was saved."""


def _output_path(value: str | None, suffixes: Sequence[str], option: str) -> Path | None:
    if value is None:
        return None
    path = Path(value)
    if path.suffix not in suffixes:
        raise ModelError(f"{option} {value}: the file name must end in {', '.join(suffixes)}")
    return path


def _emit(text: str, output: str | None) -> None:
    if output is None:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    else:
        Path(output).write_text(text, encoding="utf-8")
        print(f"wrote {output}", file=sys.stderr)


# -- commands -------------------------------------------------------------------------


def _models(arguments: argparse.Namespace) -> None:
    for name in example_names():
        kind = "built-in" if name in BUILTIN_MODELS else "example"
        print(f"{name:<18} {kind:<9} {load_model(example_path(name)).description}")
    folder = example_path(example_names()[0]).parent
    print(f"\nmodel files: {folder}  (copy one to start a model of your own)")


def _derive(arguments: argparse.Namespace) -> None:
    equations = derive(resolve_model(arguments.model).system, simplify=arguments.simplify)
    _emit(format_equations(equations, arguments.format), arguments.output)


def _export(arguments: argparse.Namespace) -> None:
    equations = derive(resolve_model(arguments.model).system, simplify=arguments.simplify)
    _emit(export_code(equations, arguments.lang), arguments.output)


def _check(arguments: argparse.Namespace) -> None:
    model = resolve_model(arguments.model)
    print(f"{model.source}: valid model file")
    print(check_model(model).report())


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


def _simulate(arguments: argparse.Namespace) -> None:
    model = resolve_model(arguments.model)
    output = _output_path(arguments.output, _TRAJECTORY_SUFFIXES, "--output")
    figure = _output_path(arguments.plot, _PLOT_SUFFIXES, "--plot")
    movie = _output_path(arguments.animate, _ANIMATION_SUFFIXES, "--animate")
    t_end = arguments.t_end if arguments.t_end is not None else model.simulation.t_end
    bar = ProgressBar(t_end, sys.stderr)
    trajectory = simulate_model(model, t_end=t_end, method=arguments.method, rtol=arguments.rtol,
                                atol=arguments.atol, progress=bar)
    bar.close()
    print(summarize(trajectory).report())
    if not trajectory.success:
        saved = output or Path(f"{model.system.name}-partial.npz")
        _save_trajectory(trajectory, saved)
        reached = trajectory.t[-1] if len(trajectory.t) else 0.0
        raise NumericalFailure(f"simulation failed ({trajectory.message.rstrip('.')}); "
                               f"the trajectory up to t = {reached:g} is saved in {saved}")
    if output:
        _save_trajectory(trajectory, output)
    if figure:
        trajectory.plot(path=figure)
        print(f"wrote {figure}")
    if movie:
        trajectory.animate(movie)
        print(f"wrote {movie}")


def _save_trajectory(trajectory, path: Path) -> None:
    if path.suffix == ".parquet":
        try:
            trajectory.to_dataframe().to_parquet(path)
        except ImportError as error:
            raise ModelError(f"--output {path}: {error}") from None
    elif path.suffix == ".csv":
        trajectory.to_csv(path)
    else:
        trajectory.to_npz(path)
    print(f"wrote {path}")


def _inverse(arguments: argparse.Namespace) -> None:
    model = resolve_model(arguments.model)
    output = _output_path(arguments.output, _INVERSE_SUFFIXES, "--output")
    drives = dict(parse_drive(text, model) for text in arguments.drive) if arguments.drive else model.drives
    if not drives:
        raise ModelError("no drives: give --drive COORDINATE=EXPRESSION or [[drives]] in the model file")
    t_end = model.simulation.t_end if arguments.t_end is None else arguments.t_end
    run = inverse_dynamics_along(model, drives, np.linspace(0.0, t_end, arguments.points))
    print(run.report())
    if not run.success:
        saved = output or Path(f"{model.system.name}-inverse-partial.csv")
        run.save(saved)
        raise NumericalFailure(f"inverse dynamics failed {run.message}; the results before are saved in {saved}")
    if output:
        run.save(output)
        print(f"wrote {output}")


# -- parser ---------------------------------------------------------------------------


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _count(text: str) -> int:
    if not text.isdigit() or int(text) < 2:
        raise argparse.ArgumentTypeError(f"expected an integer of at least 2, got {text!r}")
    return int(text)


def build_parser() -> argparse.ArgumentParser:
    """The ``kronlag`` argument parser."""
    parser = argparse.ArgumentParser(prog="kronlag", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, handler: Callable[[argparse.Namespace], None], summary: str,
                *, model: bool = True) -> argparse.ArgumentParser:
        sub = commands.add_parser(name, help=summary, description=summary)
        sub.set_defaults(handler=handler)
        if model:
            sub.add_argument("model", metavar="MODEL", help="built-in model name or path of a TOML model file")
        return sub

    command("models", _models, "list the built-in models and shipped example files", model=False)

    sub = command("derive", _derive, "derive and print the equations of motion (Eq. 23)")
    sub.add_argument("--format", choices=FORMATS, default="text", help="output format (default: text)")
    sub.add_argument("--simplify", action="store_true", help="apply trigsimp to every entry")
    sub.add_argument("--output", metavar="FILE", help="write to FILE instead of standard output")

    sub = command("export", _export, "write standalone code for M, C, g, Phi, Phi_q, gamma, A, b, f_Q")
    sub.add_argument("--lang", choices=LANGUAGES, required=True, help="target language")
    sub.add_argument("--simplify", action="store_true", help="apply trigsimp to every entry first")
    sub.add_argument("--output", metavar="FILE", help="write to FILE instead of standard output")

    command("check", _check, "validate a model; report degrees of freedom and constraint ranks at the guess")

    sub = command("simulate", _simulate, "assemble the initial state and integrate the equations of motion")
    sub.add_argument("--t-end", type=_positive, help="final time (default: the model's [simulation] t_end)")
    sub.add_argument("--method", help="integration method: auto, baumgarte, projection, ggl, compiled")
    sub.add_argument("--rtol", type=_positive, help="relative tolerance")
    sub.add_argument("--atol", type=_positive, help="absolute tolerance")
    sub.add_argument("--output", metavar="FILE", help="save the trajectory (.csv, .npz or .parquet)")
    sub.add_argument("--plot", metavar="FILE", help="save a figure of the time histories (.png, .pdf, .svg)")
    sub.add_argument("--animate", metavar="FILE", help="save an animation (.gif, .mp4 or .html)")

    sub = command("inverse", _inverse, "actuator forces and multipliers along a prescribed motion")
    sub.add_argument("--drive", action="append", metavar="Q=EXPR",
                     help="prescribed motion of a coordinate as an expression of t, e.g. 'q1=2*pi*t' "
                          "(repeat for several; default: the model's [[drives]])")
    sub.add_argument("--t-end", type=_positive, help="final time (default: the model's [simulation] t_end)")
    sub.add_argument("--points", type=_count, default=101, help="number of evenly spaced times (default: 101)")
    sub.add_argument("--output", metavar="FILE", help="save the results (.csv or .npz)")

    from .cli_analysis import add_commands as add_analysis_commands

    add_analysis_commands(command)
    return parser


def _numerical_errors() -> tuple[type[Exception], ...]:
    """The numeric layer's failure exceptions (none if it is not installed)."""
    try:
        from .analysis import EquilibriumError
        from .numeric import AssemblyError, SingularConfigurationError
    except ImportError:
        return ()
    return AssemblyError, SingularConfigurationError, EquilibriumError


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    try:
        arguments = build_parser().parse_args(argv)
    except SystemExit as exit_request:  # --help, or a usage error (argparse printed it)
        return int(exit_request.code or 0)
    try:
        arguments.handler(arguments)
    except NumericalFailure as error:
        print(f"kronlag: {error}", file=sys.stderr)
        return EXIT_NUMERICAL
    except _numerical_errors() as error:
        print(f"kronlag: numerical failure: {error}", file=sys.stderr)
        return EXIT_NUMERICAL
    except BrokenPipeError:  # the reader of standard output quit early (| head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except (ModelError, ValueError, OSError) as error:
        print(f"kronlag: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
