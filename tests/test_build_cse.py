"""Common-subexpression elimination in linear time for large kernels (issue 19.2): ``linear_cse`` names
every repeated subexpression once, computes what the plain expressions say, in dependency order, and
``cse_kernel`` uses it above ``LINEAR_CSE_OUTPUTS`` outputs."""

import random

import numpy as np
import pytest
import symengine as se

import kronlag
from kronlag import codegen, models
from kronlag.core import kernels
from kronlag.core.kernels import linear_cse


def chain_kernel_entries(n: int = 6) -> list[se.Basic]:
    """The entries of the dynamics kernel of ``closed_chain(n, "absolute")``: M's entries share the
    products of link lengths and sines, h's the sums of the links' accelerations."""
    source = codegen.KernelSource(kronlag.derive(models.closed_chain(n, "absolute")))
    return [entry for block in codegen.LAYOUTS["dynamics"] for row in source.matrix(block) for entry in row]


def free_symbols(exprs) -> set[se.Symbol]:
    return set().union(*(se.sympify(expr).free_symbols for expr in exprs))


def evaluate(temporaries, outputs, point: dict) -> np.ndarray:
    """The outputs at ``point`` (symbol -> float), the temporaries evaluated in their order."""
    values = dict(point)
    for symbol, expr in temporaries:
        values[symbol] = se.RealDouble(float(expr.xreplace(values)))
    return np.array([float(expr.xreplace(values)) for expr in outputs])


def test_linear_cse_computes_the_plain_expressions_of_a_kernel_with_heavy_sharing():
    entries = chain_kernel_entries()
    temporaries, outputs = linear_cse(entries)
    inputs = free_symbols(entries)
    assert len(temporaries) > 50 and len(outputs) == len(entries)
    rng = random.Random(3)
    for _ in range(3):
        point = {symbol: se.RealDouble(rng.uniform(0.3, 1.7)) for symbol in inputs}
        expected = np.array([float(entry.xreplace(point)) for entry in entries])
        np.testing.assert_allclose(evaluate(temporaries, outputs, point), expected, rtol=1e-12,
                                   atol=1e-12 * np.max(np.abs(expected)))


def test_linear_cse_temporaries_are_in_dependency_order_and_each_defined_once():
    entries = chain_kernel_entries()
    temporaries, outputs = linear_cse(entries)
    inputs = free_symbols(entries)
    defined: set[se.Symbol] = set()
    for symbol, expr in temporaries:
        assert free_symbols([expr]) <= inputs | defined, f"{symbol} = {expr} uses a later temporary"
        defined.add(symbol)
    assert free_symbols(outputs) <= inputs | defined
    # each repeated subexpression once: no two temporaries compute the same expression
    assert len({expr for _, expr in temporaries}) == len(temporaries)
    # and each temporary is used (at least twice where it was found, at least once here)
    used = free_symbols([expr for _, expr in temporaries] + outputs)
    assert defined <= used


def test_linear_cse_shares_a_product_with_and_without_a_numeric_factor():
    a, b, c, d = se.symbols("a b c d")
    product = a * b * c
    temporaries, outputs = linear_cse([product + d, se.Rational(1, 2) * product * 1, 3 * product - d])
    assert temporaries == [(se.Symbol("x0"), product)]
    x0 = se.Symbol("x0")
    assert outputs == [x0 + d, se.Rational(1, 2) * x0, 3 * x0 - d]


def test_linear_cse_keeps_piecewise_and_its_conditions():
    x, y = se.symbols("x y")
    shared = se.sin(x) * y
    expr = se.Piecewise((shared, x > 0), (shared ** 2, True))
    temporaries, outputs = linear_cse([expr, shared + 1])
    point = {x: se.RealDouble(-0.4), y: se.RealDouble(1.3)}
    expected = [float(expr.xreplace(point)), float((shared + 1).xreplace(point))]
    np.testing.assert_allclose(evaluate(temporaries, outputs, point), expected, rtol=1e-15)


@pytest.mark.parametrize("angles", ["absolute", "relative"])
def test_a_model_built_with_linear_cse_has_the_accelerations_of_one_built_with_symengine_cse(
        tmp_path, monkeypatch, angles):
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    eom = kronlag.derive(models.closed_chain(5, angles))
    values = {p.name: 1.0 for p in eom.parameters}
    values.update(xg=3.0, yg=0.0)
    built = {}
    for label, limit in (("symengine", 10**9), ("linear", 0)):
        monkeypatch.setattr(kernels, "LINEAR_CSE_OUTPUTS", limit)
        built[label] = eom.numeric(values, backend="c")
    monkeypatch.undo()
    guess = np.linspace(0.8, -0.8, 5) if angles == "absolute" else np.r_[0.8, np.full(4, -0.4)]
    q, qd = built["symengine"].assemble(guess)
    expected = built["symengine"].forward_dynamics(q, qd).qdd
    actual = built["linear"].forward_dynamics(q, qd).qdd
    np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-12 * np.max(np.abs(expected)))
