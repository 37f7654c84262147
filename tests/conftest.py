"""Shared test helpers: the built-in models (derived once per session) and
comparison of symbolic matrices, exactly or at random numeric points.

Test modules import these helpers with ``from conftest import ...``.
"""

from __future__ import annotations

import functools
import random

import sympy as sp

import kronlag
from kronlag import models

#: Every built-in model, by the name the tests use.
MODEL_BUILDERS = {
    "four_bar": models.four_bar,
    "quick_return": models.quick_return,
    "double_pendulum": models.double_pendulum,
    "slider_crank": models.slider_crank,
    "slider_crank_engine": models.slider_crank_engine,
    "five_bar": models.five_bar,
    "heavy_top": models.heavy_top,
    "chaplygin_sleigh": models.chaplygin_sleigh,
    "closed_chain_4_absolute": functools.partial(models.closed_chain, 4, "absolute"),
    "closed_chain_4_relative": functools.partial(models.closed_chain, 4, "relative"),
    "pendulum_cartesian": models.pendulum_cartesian,
    "n_four_bar": models.n_four_bar,
    "andrews_squeezer": models.andrews_squeezer,
    "flyball_governor": models.flyball_governor,
    # Not models.bricard: its symbolic C (2 MB of text) is too large for the 30-digit
    # comparisons of the identity tests; tests/test_iftomm.py checks it numerically.
}

#: Digits of the numeric evaluations and the relative tolerance of comparisons.
DIGITS = 30
RELATIVE_TOLERANCE = 1e-12


@functools.cache
def derived(name: str) -> kronlag.Equations:
    """``kronlag.derive`` of the built-in model ``name`` (cached: Equations are immutable)."""
    return kronlag.derive(MODEL_BUILDERS[name]())


def state_symbols(equations: kronlag.Equations) -> set[sp.Symbol]:
    """Coordinates, speeds, accelerations and multipliers: the symbols that take signed values."""
    return {*equations.coordinates, *equations.speeds, *equations.accelerations,
            *equations.lambdas, *equations.mus}


def is_zero(expr) -> bool:
    """Symbolic test ``expr == 0`` (entry-wise for a matrix) via trig expansion and simplification."""
    entries = expr if isinstance(expr, sp.MatrixBase) else [expr]
    return all(sp.simplify(sp.expand_trig(sp.sympify(entry))) == 0 for entry in entries)


def random_values(symbols, rng: random.Random, signed=frozenset()) -> dict:
    """Random values: uniform in (-3, 3) for the ``signed`` symbols (angles, speeds,
    multipliers), in (0.5, 2) for the others (masses, lengths, inertias...)."""
    return {symbol: rng.uniform(-3, 3) if symbol in signed else rng.uniform(0.5, 2)
            for symbol in symbols}


def evaluate(matrix, values: dict) -> list[sp.Float]:
    """The entries of ``matrix`` (row by row) at ``values``, with :data:`DIGITS` digits."""
    floats = {symbol: sp.Float(value, DIGITS) for symbol, value in values.items()}
    entries = [sp.sympify(entry).xreplace(floats).evalf(DIGITS) for entry in sp.Matrix(matrix)]
    assert all(entry.is_number for entry in entries), "a symbol was left without a value"
    return entries


def assert_numerically_equal(actual, expected, signed=frozenset(), *, points: int = 3, seed: int = 0) -> None:
    """``actual == expected`` at ``points`` random points, relative to the largest entry.

    All free symbols get random values (see :func:`random_values`).
    """
    actual, expected = sp.Matrix(actual), sp.Matrix(expected)
    assert actual.shape == expected.shape
    symbols = actual.free_symbols | expected.free_symbols
    rng = random.Random(seed)
    for _ in range(points):
        values = random_values(sorted(symbols, key=lambda s: s.name), rng, signed)
        a, b = evaluate(actual, values), evaluate(expected, values)
        scale = max((abs(x) for x in a + b), default=0)
        error = max((abs(x - y) for x, y in zip(a, b)), default=0)
        assert error <= RELATIVE_TOLERANCE * scale, (
            f"differ by {error:.3e} (scale {scale:.3e}) at {values}")
