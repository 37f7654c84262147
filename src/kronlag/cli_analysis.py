"""The analysis commands of the ``kronlag`` command line (``equilibrium``), registered by
:func:`kronlag.cli.build_parser`; thin shells over :mod:`kronlag.analysis`."""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np

from .modelfile import resolve_model
from .system import ModelError
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
    for j, value in enumerate(rest.lam):
        print(f"  lambda{j + 1:<6} = {value: .10g}")
    for name, value in rest.holding_forces.items():
        print(f"  force holding {name} = {value: .10g}")
    if arguments.modes:
        linear = numeric.linearize(rest.q)
        print(f"linearized in {', '.join(linear.coordinates)}: natural frequencies (rad/s, nan: unstable)")
        for k, frequency in enumerate(linear.natural_frequencies):
            shape = ", ".join(f"{value:.4g}" for value in linear.mode_shapes[:, k])
            print(f"  mode {k}: {frequency:.8g} rad/s = {frequency / (2 * np.pi):.6g} Hz   shape ({shape})")


def add_commands(command: Callable[..., argparse.ArgumentParser]) -> None:
    """Register the analysis commands with ``command(name, handler, summary)`` of the main parser."""
    sub = command("equilibrium", _equilibrium, "static equilibrium: g - f_Q + Phi_q^T lambda = 0, Phi = 0")
    sub.add_argument("--guess", action="append", type=_assignment, metavar="Q=VALUE",
                     help="start value of a coordinate (default: the model's initial guess); repeatable")
    sub.add_argument("--fix", action="append", type=_assignment, metavar="Q=VALUE",
                     help="hold a coordinate at a value (a drive held); repeatable")
    sub.add_argument("--modes", action="store_true",
                     help="also linearize there and print the natural frequencies and mode shapes")
