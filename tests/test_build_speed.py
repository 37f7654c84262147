"""Building in seconds (issue 19.2): generated C split into functions of bounded size, and the default
method's driver compiled with the model, so that a first ``simulate`` compiles nothing."""

import re

import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag import codegen
from kronlag.core.kernels import expression_kernel
from kronlag.numeric.codegen import build

M_INPUTS, OUTPUTS = 40, 400


def long_statement_kernel():
    """400 outputs, each a sum of 40 terms with its own coefficients (nothing for CSE to share), and
    the coefficient matrix: the kernel computes ``coefficients @ q``."""
    q = sp.symbols(f"q0:{M_INPUTS}")
    coefficients = np.array([[(7 * i + 3 * k) % 97 + 1 for i in range(M_INPUTS)] for k in range(OUTPUTS)]) / 64.0
    expressions = sp.Matrix([sum(sp.Rational(int(c * 64), 64) * qi for c, qi in zip(row, q)) for row in coefficients])
    return expression_kernel({"out": expressions}, [("t", sp.Symbol("t")), ("q", q), ("qd", ()), ("p", ())],
                             name="long"), coefficients


def test_generated_functions_are_split_by_size_not_by_statement_count():
    kernel, _ = long_statement_kernel()
    text, chunks = codegen.c_kernel(kernel, 1)
    bodies = re.findall(r"void kronlag_long_\d+\([^)]*\)\n\{\n(.*?)\n\}", text, re.DOTALL)
    longest_statement = max(len(line) for body in bodies for line in body.splitlines())
    assert len(bodies) == chunks > 1
    # 250 statements of some 600 characters each made one function of 150 000 characters before
    assert max(len(body) for body in bodies) <= codegen.c_backend.C_CHUNK + 2 * longest_statement


def test_a_kernel_split_by_size_computes_what_its_expressions_say(tmp_path, monkeypatch):
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    kernel, coefficients = long_statement_kernel()
    library = codegen.CLibrary([kernel], m=M_INPUTS, n_parameters=0)
    q = np.random.default_rng(1).uniform(-2, 2, M_INPUTS)
    out = library.evaluator("long", (OUTPUTS,))(0.0, q, np.zeros(M_INPUTS), np.zeros(0))
    np.testing.assert_allclose(out, coefficients @ q, rtol=1e-13, atol=1e-13)


def test_the_first_simulate_after_building_a_model_compiles_nothing(tmp_path, monkeypatch):
    pytest.importorskip("sksundae")
    if codegen.c_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))  # an empty cache: nothing compiled before
    n = 3
    eom = kronlag.derive(kronlag.models.closed_chain(n, "relative"))
    values = {p.name: 1.0 for p in eom.parameters}
    values.update(xg=0.6 * n, yg=0.0)
    model = eom.numeric(values, backend="c")
    q0, qd0 = model.assemble(np.r_[0.8, np.full(n - 1, -0.8)])

    def no_compiling(*arguments, **options):
        raise AssertionError("the first simulate compiled a library")

    monkeypatch.setattr(build, "_build", no_compiling)
    trajectory = kronlag.simulate(model, (0.0, 0.05), q0, qd0)
    assert trajectory.success
