"""Outputs at every step (``t_eval=None``): the compiled drivers compute the derived columns
(accelerations, multipliers, energies, residuals) in C for all stored steps in one pass; they
must agree with the per-point recomputation through the model's Python interface."""

from __future__ import annotations

import numpy as np
import pytest

import kronlag
from kronlag.simulation.simulate import _derived
from kronlag.simulation.problem import Solution

from helpers import derived

FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=1.5, I1=1.0 * 0.2 ** 2 / 12,
                I2=2.0 * 0.6 ** 2 / 12, I3=1.5 * 0.5 ** 2 / 12, g=9.81, tau=0.0)


def assert_outputs_match_recomputation(trajectory, skip=()):
    """Every derived column of ``trajectory`` but ``skip`` equals the per-point Python recomputation
    to 1e-12."""
    y = np.hstack([trajectory.q, trajectory.qd])
    expected, _ = _derived(trajectory.model, trajectory.t, y)
    assert set(expected) == set(Solution.DERIVED)
    for name, values in expected.items():
        if name in skip:
            continue
        np.testing.assert_allclose(getattr(trajectory, name), values, rtol=1e-12, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("method", ["compiled", "switching", "ali3p"])
def test_four_bar_every_step_outputs_equal_the_python_recomputation(method):
    model = derived("four_bar").numeric({**FOUR_BAR, "tau": 0.3}, backend="c")
    q0, qd0 = model.assemble([0.3, 0.8, 1.3], fixed={"q1": 0.3})
    trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method)
    assert trajectory.success, trajectory.message
    assert len(trajectory.t) == trajectory.steps + 1 > 50  # every step is an output
    # ALI3-P outputs its own accelerations and the multipliers that balance them (index3.c)
    assert_outputs_match_recomputation(trajectory, skip=("qdd", "lam") if method == "ali3p" else ())


def test_nonholonomic_every_step_outputs_equal_the_python_recomputation():
    model = derived("chaplygin_sleigh").numeric(dict(m=2.0, I=0.1, a=0.3), backend="c")
    q0 = [0.0, 0.0, 0.0]
    qd0 = model.assemble(q0, qd_guess=[1.0, 0.0, 2.0], qd_fixed={"x": 1.0, "theta": 2.0})[1]
    trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method="compiled")
    assert trajectory.success, trajectory.message
    assert trajectory.mu.shape[1] == 1 and np.all(np.isfinite(trajectory.mu))
    assert_outputs_match_recomputation(trajectory)


def test_range_space_solve_handles_a_mass_matrix_singular_off_the_constraints():
    from kronlag.symbolic.interop import range_space_solve

    rng = np.random.default_rng(1)
    m, k = 5, 2
    G = rng.normal(size=(k, m))
    null = np.linalg.svd(G)[2][k:].T  # (m, m - k)
    root = rng.normal(size=(m - k, m - k))
    M = null @ (root @ root.T + np.eye(m - k)) @ null.T  # singular, positive definite on null(G)
    h, c = rng.normal(size=m), rng.normal(size=k)
    expected = np.linalg.solve(np.block([[M, G.T], [G, np.zeros((k, k))]]), np.concatenate([h, c]))
    qdd, nu = range_space_solve(M.ravel().tolist(), G.ravel().tolist(), h.tolist(), c.tolist())
    np.testing.assert_allclose(np.concatenate([qdd, nu]), expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name, parameters", [
    ("four_bar", FOUR_BAR),
    ("chaplygin_sleigh", dict(m=2.0, I=0.1, a=0.3)),
    ("closed_chain_4_relative", None),  # sin and cos of sums of coordinates
])
def test_jax_jit_vmap_forward_dynamics_equals_the_c_batch(name, parameters):
    jax = pytest.importorskip("jax")
    jax.config.update("jax_enable_x64", True)
    from kronlag.symbolic.interop import jax_functions

    equations = derived(name)
    model = equations.numeric(parameters or {symbol.name: 1.0 for symbol in equations.parameters}, backend="c")
    rng = np.random.default_rng(2)
    q, qd = rng.uniform(-3, 3, (200, model.m)), rng.uniform(-3, 3, (200, model.m))
    batched = jax.jit(jax.vmap(jax_functions(model)["forward_dynamics"], in_axes=(0, 0, None, None)))
    qdd, lam, mu = batched(q, qd, model.parameter_vector(0.0), 0.0)
    reference = model.forward_dynamics_batch(q, qd)
    for got, expected in ((qdd, reference.qdd), (lam, reference.lam), (mu, reference.mu)):
        np.testing.assert_allclose(np.asarray(got), expected, rtol=1e-9, atol=1e-9)
