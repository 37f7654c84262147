"""The analysis commands of the ``kronlag`` command line (``equilibrium``, ``sweep``), registered
by :func:`kronlag.app.cli.build_parser`; thin shells over :mod:`kronlag.studies.equilibrium`,
:mod:`kronlag.studies.linearization` and :mod:`kronlag.studies.sweeps`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..core.errors import ModelError
from ..model.builtin import resolve_model
from ..numeric.reactions import column_unit, multiplier_labels, reaction_columns
from ..numeric.tolerances import ZERO_EIGENVALUE_RTOL
from ..studies.linearization import LinearModel
from ..studies.sweeps import sweep
from .commands import method_help
from .outputs import IncompleteRun
from .workflows import numeric_model


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
    model = resolve_model(arguments.model)
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


def _axis(text: str) -> tuple[str, np.ndarray]:
    """``"m2=1:3:5"`` -> ``("m2", linspace(1, 3, 5))``; ``"m2=1,2.5"`` -> the listed values."""
    name, separator, values = text.partition("=")
    try:
        if not separator or not name.strip():
            raise ValueError
        if ":" in values:
            start, stop, count = values.split(":")
            if int(count) < 1:
                raise ValueError
            return name.strip(), np.linspace(float(start), float(stop), int(count))
        return name.strip(), np.array([float(value) for value in values.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=START:STOP:COUNT or NAME=V1,V2,..., got {text!r}") from None


def _sweep(arguments: argparse.Namespace) -> None:

    if arguments.output and Path(arguments.output).suffix not in (".csv", ".parquet"):
        raise ModelError(f"--output {arguments.output}: the file name must end in .csv or .parquet")
    model = resolve_model(arguments.model)
    numeric = numeric_model(model)
    t_end = arguments.t_end if arguments.t_end is not None else model.simulation.t_end
    options = {"method": arguments.method or model.simulation.method, "rtol": model.simulation.rtol,
               "atol": model.simulation.atol, "t_eval": np.linspace(0.0, t_end, arguments.points)}
    result = sweep(numeric, parameters=dict(arguments.grid), initial_states=model.guess_vectors(),
                   fixed=model.fixed, qd_fixed=model.qd_fixed, t_span=(0.0, t_end), workers=arguments.workers,
                   progress=True, **options)
    table = result.table
    print(f"{len(table)} cases, {int((table['status'] == 'ok').sum())} ok, "
          f"{len(result.failed)} not; median wall time per case {table['wall_time'].median():.3g} s")
    print(table.drop(columns=["message"]).to_string(max_rows=20, float_format=lambda x: f"{x:.6g}"))
    if arguments.output:
        path = Path(arguments.output)
        if path.suffix == ".csv":
            table.to_csv(path, index=False)
        else:
            table.to_parquet(path)
        print(f"wrote {path}")
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

    sub = command("sweep", _sweep, "simulate a grid of parameter values and initial coordinates/speeds (Dask)")
    sub.add_argument("--grid", action="append", type=_axis, required=True, metavar="NAME=START:STOP:COUNT",
                     help="values of a parameter, coordinate (q1) or speed (q1d): evenly spaced, or "
                          "NAME=V1,V2,...; repeat for a grid of all combinations")
    sub.add_argument("--t-end", type=float, help="final time (default: the model's [simulation] t_end)")
    sub.add_argument("--method", help=method_help())
    sub.add_argument("--points", type=int, default=101, help="output times per case (default: 101)")
    sub.add_argument("--workers", type=int, default=2,
                     help="processes of the local Dask cluster; 0: run in this process (default: 2)")
    sub.add_argument("--output", metavar="FILE", help="save the table of outcomes (.csv or .parquet)")
