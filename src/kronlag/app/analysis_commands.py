"""The analysis commands of the ``kronlag`` command line (``equilibrium``, ``sweep``), registered
by :func:`kronlag.app.cli.build_parser`; thin shells over :mod:`kronlag.studies.equilibrium`,
:mod:`kronlag.studies.linearization` and :mod:`kronlag.studies.sweeps`."""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from ..core.errors import ModelError
from ..model.modelfile import ModelFile
from ..numeric.reactions import column_unit, multiplier_labels, reaction_columns
from ..numeric.tolerances import ZERO_EIGENVALUE_RTOL
from ..simulation.controllers import file_controller
from ..studies.linearization import LinearModel
from ..studies.sweeps import SweepInterrupted, SweepResult, sweep
from .commands import method_help, model_file, output_times
from .outputs import IncompleteRun, check_writable
from .workflows import model_units, numeric_model


def _assignment(text: str) -> tuple[str, float]:
    """``"q1=0.3"`` -> ``("q1", 0.3)``."""
    name, separator, value = text.partition("=")
    try:
        if not separator or not name.strip():
            raise ValueError
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=NUMBER, got {text!r}") from None


def _check_names(assignments: dict[str, float], names: tuple[str, ...], option: str) -> None:
    unknown = [name for name in assignments if name not in names]
    if unknown:
        raise ModelError(f"{option}: unknown coordinate(s) {', '.join(unknown)}; known: {', '.join(names)}")


def _equilibrium(arguments: argparse.Namespace) -> None:
    model = model_file(arguments)
    numeric = numeric_model(model)
    names = numeric.coordinate_names
    guess_values, _ = model.guess_vectors()
    guess = dict(zip(names, guess_values))
    given, fixed = dict(arguments.guess or ()), dict(arguments.fix or ())
    _check_names(given, names, "--guess")
    _check_names(fixed, names, "--fix")
    guess.update(given)
    guess.update(fixed)
    rest = numeric.equilibrium(np.array([guess[name] for name in names]), fixed=fixed or None)
    print(f"static equilibrium of {numeric.equations.system.name} (residual {rest.residual:.3g}, "
          f"{rest.iterations} Newton iterations)")
    for name, value in zip(names, rest.q):
        print(f"  {name:<12} = {value: .10g}{'  (held)' if name in fixed else ''}")
    system = numeric.equations.system
    joint_rows = {row for joint in system.joints for row in joint.constraint_names}
    for label, constraint, value in zip(multiplier_labels(system), system.constraints, rest.lam):
        if constraint.name not in joint_rows:
            print(f"  {label:<12} = {value: .10g}")
    for name, value in reaction_columns(numeric, [rest.t], rest.q[None, :], rest.lam[None, :]).items():
        print(f"  {name:<12} = {value[0]: .10g} {column_unit(name)}")
    for name, value in rest.holding_forces.items():
        print(f"  force holding {name} = {value: .10g}")
    if arguments.animate_mode and Path(arguments.animate_mode).suffix not in (".gif", ".mp4", ".html", ".htm"):
        raise ModelError(f"--animate-mode {arguments.animate_mode}: the file name must end in .gif, .mp4 or .html")
    if arguments.modes or arguments.animate_mode:
        linear = numeric.linearize(rest.q)
        print(modes_report(linear))
        if arguments.animate_mode:
            if not 0 <= arguments.mode < len(linear.coordinates):
                raise ModelError(f"--mode {arguments.mode}: the model has modes 0 to {len(linear.coordinates) - 1}")
            print(f"wrote {linear.animate_mode(arguments.mode, arguments.animate_mode)}")


def modes_report(linear: LinearModel) -> str:
    """The natural frequencies and mode shapes of ``linear``, a mode a line, its shape by coordinate
    name; a mode whose ``w^2`` is zero within rounding (:attr:`LinearModel.neutral`) prints as 0."""
    lines = [f"linearized in {', '.join(linear.coordinates)}: natural frequencies (rad/s; 0: neutral, "
             f"|w^2| <= {linear.neutral_threshold:.3g} rad^2/s^2 ({ZERO_EIGENVALUE_RTOL:g} of the scale), zero "
             "within rounding; nan: unstable, w^2 < 0)"]
    for k, (frequency, neutral) in enumerate(zip(linear.natural_frequencies, linear.neutral)):
        shape = ", ".join(f"{name} {value:.4g}" for name, value in linear.mode_shape(k).items())
        kind = "  (neutral)" if neutral else "  (unstable)" if np.isnan(frequency) else ""
        lines.append(f"  mode {k}: {frequency:.8g} rad/s = {frequency / (2 * np.pi):.6g} Hz{kind}   shape: {shape}")
    return "\n".join(lines)


def _axis(text: str) -> tuple[str, tuple[str, str, int] | list[str]]:
    """``"m2=1:3:5"`` -> ``("m2", ("1", "3", 5))``; ``"m2=1,2.5"`` -> ``("m2", ["1", "2.5"])``: the values
    as text, read in the model file's units (:meth:`ModelFile.parameter_value`) once the model is known."""
    name, separator, values = text.partition("=")
    try:
        if not separator or not name.strip():
            raise ValueError
        if ":" in values:
            start, stop, count = values.split(":")
            if int(count) < 1:
                raise ValueError
            return name.strip(), (start, stop, int(count))
        return name.strip(), values.split(",")
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=START:STOP:COUNT or NAME=V1,V2,..., got {text!r}") from None


def _setting(text: str) -> tuple[str, str]:
    """``"L=0.3m"`` -> ``("L", "0.3m")`` (read in the model file's units once the model is known)."""
    name, separator, value = text.partition("=")
    if not separator or not name.strip() or not value.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE (VALUE a number, optionally with a unit), got {text!r}")
    return name.strip(), value


def _axis_values(model: ModelFile, name: str, values: tuple[str, str, int] | list[str]) -> np.ndarray:
    """The SI values of a ``--grid`` axis (each text in the file's unit of ``name`` or its own unit)."""
    if isinstance(values, tuple):
        start, stop, count = values
        return np.linspace(model.parameter_value(name, start), model.parameter_value(name, stop), count)
    return np.array([model.parameter_value(name, value) for value in values])


def _column_labels(model: ModelFile, names: list[str]) -> dict[str, str]:
    """``name -> "name [unit]"`` for the swept names whose unit the file determines (parameters with a
    unit, coordinates by :func:`model_units`, their speeds per second); the others keep their name.  The
    values are SI: a parameter's label is the file's unit when it is an SI one (``N*m``), else the SI unit."""
    units = model_units(model, parameters=True)
    coordinates = {q.name for q in model.system.coordinates}
    speeds = {f"{q}d": f"{units[q]}/{units['t']}" for q in coordinates if q in units and "t" in units}
    units |= speeds
    return {name: f"{name} [{units[name]}]" for name in names if units.get(name)}


class _RowFile:
    """The rows of a sweep appended to a CSV file as the cases finish (the file rewritten when a row brings
    new columns, e.g. the outcomes after failed cases), so that a stopped sweep keeps them."""

    def __init__(self, path: Path, labels: Mapping[str, str]):
        self.path, self.labels, self.rows, self.columns = path, labels, [], []

    def __call__(self, row: dict) -> None:
        self.rows.append(row)
        new = [column for column in row if column not in self.columns]
        self.columns += new
        self._write(self.rows if new else [row], "w" if new else "a")

    def _write(self, rows: list[dict], mode: str) -> None:
        with open(self.path, mode, newline="", encoding="utf-8") as file:
            writer = csv.DictWriter(file, self.columns)
            if mode == "w":
                writer.writerow({column: self.labels.get(column, column) for column in self.columns})
            writer.writerows(rows)


def _save_table(result: SweepResult, path: Path, labels: Mapping[str, str]) -> None:
    """The table in the order of the cases, its swept columns labelled with their units."""
    table = result.table.rename(columns=labels)
    if path.suffix == ".csv":
        table.to_csv(path, index=False)
    else:
        table.to_parquet(path)
    print(f"wrote {path}")


def _sweep(arguments: argparse.Namespace) -> None:
    output = Path(arguments.output) if arguments.output else None
    if output:  # before any work: a sweep must not end with nowhere to put its table
        if output.suffix not in (".csv", ".parquet"):
            raise ModelError(f"--output {output}: the file name must end in .csv or .parquet")
        check_writable(output, "--output")
    model = model_file(arguments)
    grid = {name: _axis_values(model, name, values) for name, values in arguments.grid}
    settings = {name: model.parameter_value(name, value) for name, value in arguments.set or ()}
    both = sorted(settings.keys() & grid.keys())
    if both:
        raise ModelError(f"--set and --grid both give {', '.join(both)}")
    numeric = numeric_model(model).with_parameters(settings)
    t_end = arguments.t_end if arguments.t_end is not None else model.simulation.t_end
    options = {"method": arguments.method or model.simulation.method, "rtol": model.simulation.rtol,
               "atol": model.simulation.atol, "t_eval": output_times(t_end, points=arguments.points),
               "controller": None if model.controller is None else file_controller(model.controller, numeric)}
    labels = _column_labels(model, list(grid))
    # the rows as they finish: in the output itself (CSV), else next to it until the table is written
    rows = output if output is None or output.suffix == ".csv" else output.with_name(output.name + ".partial.csv")
    try:
        result = sweep(numeric, parameters=grid, initial_states=model.guess_vectors(), fixed=model.fixed,
                       qd_fixed=model.qd_fixed, t_span=(0.0, t_end), workers=arguments.workers,
                       scheduler=arguments.scheduler, progress=not arguments.no_progress,
                       on_row=_RowFile(rows, labels) if rows else None, **options)
    except SweepInterrupted as stop:
        if output:
            _save_table(stop.partial, output, labels)
        if rows and rows != output:
            rows.unlink(missing_ok=True)
        raise KeyboardInterrupt(f"{stop}" + (f"; the finished cases are saved in {output}" if output else "")
                                ) from None
    table = result.table
    print(f"{len(table)} cases, {int((table['status'] == 'ok').sum())} ok, "
          f"{len(result.failed)} not; median wall time per case {table['wall_time'].median():.3g} s")
    print(table.rename(columns=labels).drop(columns=["message"]).to_string(
        max_rows=20, float_format=lambda x: f"{x:.6g}"))
    if output:
        _save_table(result, output, labels)
        if rows != output:
            rows.unlink(missing_ok=True)
    if len(result.failed):
        for row in result.failed.itertuples():
            print(f"case {row.case}: {row.status}: {row.message}", file=sys.stderr)
        raise IncompleteRun(f"{len(result.failed)} of {len(table)} cases did not succeed"
                               + (f"; all results are saved in {arguments.output}" if arguments.output else ""))


def add_commands(command: Callable[..., argparse.ArgumentParser]) -> None:
    """Register the analysis commands with ``command(name, handler, summary)`` of the main parser."""
    sub = command("equilibrium", _equilibrium, "static equilibrium: g - f_Q + Phi_q^T lambda = 0, Phi = 0")
    sub.add_argument("--guess", action="append", type=_assignment, metavar="Q=VALUE",
                     help="start value of a coordinate (default: the model's initial guess); repeatable")
    sub.add_argument("--fix", action="append", type=_assignment, metavar="Q=VALUE",
                     help="hold a coordinate at a value (a drive held); repeatable")
    sub.add_argument("--modes", action="store_true",
                     help="also linearize there and print the natural frequencies and mode shapes")
    sub.add_argument("--animate-mode", metavar="FILE", help="animate a mode shape (.gif, .mp4 or .html)")
    sub.add_argument("--mode", type=int, default=0, help="the mode to animate, 0 = lowest (default: 0)")

    sub = command("sweep", _sweep,
                  "simulate a grid of parameter values and initial coordinates/speeds (local processes or Dask)")
    sub.add_argument("--grid", action="append", type=_axis, required=True, metavar="NAME=START:STOP:COUNT",
                     help="values of a parameter, coordinate (q1) or speed (q1d): evenly spaced, or "
                          "NAME=V1,V2,...; in the model file's unit of NAME or with a unit of the same "
                          "dimension (l1=100mm:300mm:5); repeat for a grid of all combinations")
    sub.add_argument("--set", action="append", type=_setting, metavar="NAME=VALUE",
                     help="a parameter's value in every case, in the file's unit or with a unit (L=0.3m); "
                          "parameters the file defines from it are computed again; repeatable")
    sub.add_argument("--t-end", type=float, help="final time (default: the model's [simulation] t_end)")
    sub.add_argument("--method", help=method_help())
    sub.add_argument("--points", type=int, default=101, help="output times per case (default: 101)")
    sub.add_argument("--workers", type=int,
                     help="local worker processes; 0: run in this process (default: one per CPU; a sweep "
                          "too short to gain from them runs in this process)")
    sub.add_argument("--scheduler", metavar="ADDRESS",
                     help="run on an existing Dask cluster: its scheduler's address, e.g. tcp://host:8786")
    sub.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    sub.add_argument("--output", metavar="FILE",
                     help="save the table of outcomes (.csv or .parquet; checked before the first case, rows "
                          "appended as cases finish, kept on Ctrl-C); swept columns are labelled 'NAME [unit]'")
