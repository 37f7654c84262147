"""The fast SymEngine -> SymPy conversion gives exactly what sympy.sympify gives."""

import pytest
import symengine as se
import sympy as sp

from kronlag import models
from kronlag.symbolic import derivation


def _systems():
    # The Panda arm is left out: converting its C_christoffel twice takes a minute.
    yield from (factory() for name, factory in models.BUILTIN_MODELS.items() if name != "panda")
    yield models.closed_chain(5, "relative")
    yield models.closed_chain(6, "absolute")


@pytest.mark.parametrize("system", list(_systems()), ids=lambda s: s.name)
def test_converted_matrices_are_structurally_equal_to_sympify(system, monkeypatch):
    captured = []
    original = derivation._SympyConverter.matrix

    def capture(self, matrix, shape):
        captured.append(matrix)
        return original(self, matrix, shape)

    monkeypatch.setattr(derivation._SympyConverter, "matrix", capture)
    derivation.derive(system).C_christoffel
    converter = derivation._SympyConverter({})
    for matrix in captured:
        for entry in matrix:
            converted, reference = converter(entry), sp.sympify(entry)
            assert converted == reference and converted.args == reference.args, (entry, converted, reference)


def test_number_times_sum_is_distributed_like_sympy():
    x, y = se.symbols("x y")
    expr = se.Mul(se.Rational(-1, 2), x + y) + 3 * x
    assert derivation._SympyConverter({})(expr) == sp.sympify(expr)
