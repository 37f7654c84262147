"""Batched evaluation: one call over N states equals N single calls, on both backends."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import derived

from kronlag.numeric import BATCH_MATRICES, codegen

needs_compiler = pytest.mark.skipif(codegen.c_compiler() is None, reason="no C compiler")
BACKENDS = [pytest.param("c", marks=needs_compiler), "python"]
PARAMETERS = {
    "four_bar": dict(l1=1.0, l2=2.0, l3=2.0, l4=2.0, m1=1.0, m2=2.0, m3=2.0, I1=1 / 12, I2=2 / 3, I3=2 / 3,
                     g=9.81, tau=1.0),
    "chaplygin_sleigh": dict(m=2.0, I=0.1, a=0.3),
}


def states(m: int, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-3, 3, (n, m)), rng.uniform(-3, 3, (n, m)), rng.uniform(0, 5, n)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ["four_bar", "chaplygin_sleigh"])
def test_forward_dynamics_batch_equals_single_calls(name, backend, monkeypatch):
    monkeypatch.setenv("KRONLAG_THREADS", "2")  # 1200 states: split over two threads
    values = dict(PARAMETERS[name])
    if "tau" in values:
        values["tau"] = lambda t: np.cos(t)
    model = derived(name).numeric(values, backend=backend)
    q, qd, t = states(model.m, 1200 if backend == "c" else 60)
    batch = model.forward_dynamics_batch(q, qd, t, alpha=1.0, beta=2.0)
    assert batch.qdd.shape == q.shape and batch.lam.shape == (len(q), model.r)
    assert batch.mu.shape == (len(q), model.s) and batch.rank.shape == (len(q),)
    for i in range(0, len(q), 7):
        single = model.forward_dynamics(q[i], qd[i], t[i], alpha=1.0, beta=2.0)
        np.testing.assert_allclose(batch.qdd[i], single.qdd, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(batch.lam[i], single.lam, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(batch.mu[i], single.mu, rtol=1e-12, atol=1e-12)
        assert batch.rank[i] == single.rank
    same_time = model.forward_dynamics_batch(q[:5], qd[:5], 0.5)
    np.testing.assert_allclose(same_time.qdd[3], model.forward_dynamics(q[3], qd[3], 0.5).qdd, rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_evaluate_batch_equals_single_calls(backend):
    model = derived("four_bar").numeric({**PARAMETERS["four_bar"], "tau": lambda t: 1 + t}, backend=backend)
    q, qd, t = states(model.m, 700)
    for name in BATCH_MATRICES:
        batch = model.evaluate_batch(name, q, qd, t)
        accessor = getattr(model, name)
        for i in (0, 350, 699):
            arguments = (q[i], qd[i], t[i]) if name in ("C", "C_christoffel", "Cqd", "f_Q", "gamma", "gamma_nh") \
                else (q[i], t[i])
            expected = np.atleast_1d(accessor(*arguments))
            np.testing.assert_allclose(batch[i], expected, rtol=1e-12, atol=1e-12, err_msg=name)


def test_batch_inputs_are_checked():
    model = derived("four_bar").numeric(PARAMETERS["four_bar"], backend="python")
    q, qd, _ = states(3, 4)
    with pytest.raises(ValueError, match=r"q must have shape \(N, 3\), got \(4, 2\)"):
        model.forward_dynamics_batch(q[:, :2], qd)
    with pytest.raises(ValueError, match=r"t must be a number or have shape \(4,\)"):
        model.forward_dynamics_batch(q, qd, np.zeros(3))
    with pytest.raises(ValueError, match="Cqd depends on the speeds"):
        model.evaluate_batch("Cqd", q)
    with pytest.raises(ValueError, match="unknown matrix 'K'"):
        model.evaluate_batch("K", q)


@pytest.mark.parametrize("backend", BACKENDS)
def test_inverse_dynamics_trajectory_recovers_the_torque_of_forward_dynamics(backend):
    """Forward dynamics under tau(t) = cos t, then inverse dynamics of that motion on q1: u = tau."""
    eom = derived("four_bar")
    driven = eom.numeric({**PARAMETERS["four_bar"], "tau": np.cos}, backend=backend)
    free = eom.numeric({**PARAMETERS["four_bar"], "tau": 0.0}, backend=backend)
    rng = np.random.default_rng(5)
    q0 = np.array([np.pi / 2, 0.5, 1.0])
    states = [driven.assemble(q0 + rng.uniform(-0.2, 0.2, 3), fixed={"q1": q0[0] + rng.uniform(-1, 1)},
                              qd_guess=rng.uniform(-1, 1, 3), qd_fixed={"q1": rng.uniform(-2, 2)})
              for _ in range(20)]
    q, qd = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    t = rng.uniform(0, 6, len(q))
    forward = driven.forward_dynamics_batch(q, qd, t)
    inverse = free.inverse_dynamics_trajectory(t, q, qd, forward.qdd, actuated=("q1",))
    np.testing.assert_allclose(inverse.forces[:, 0], np.cos(t), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(inverse.lam, forward.lam, rtol=1e-9, atol=1e-9)
    assert inverse.unique
