"""kronlag.interop: CasADi and JAX functions agree with the NumericModel."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import derived

from kronlag.symbolic.interop import MATRICES, casadi_functions, jax_functions

MODELS = ["four_bar", "chaplygin_sleigh", "quick_return"]


def numeric(name: str):
    equations = derived(name)
    return equations.numeric({p.name: 0.7 + 0.1 * i for i, p in enumerate(equations.parameters)}, backend="python")


def random_states(model, count: int = 3, seed: int = 1):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-1, 1, model.m), rng.uniform(-1, 1, model.m), float(rng.uniform(0, 1)))
            for _ in range(count)]


def references(model, q, qd, t):
    values = {name: getattr(model, name)(q, qd, t) if name in ("C", "Cqd", "f_Q", "gamma", "gamma_nh")
              else getattr(model, name)(q, t) for name in MATRICES}
    dynamics = model.forward_dynamics(q, qd, t)
    return values, dynamics


@pytest.mark.parametrize("name", MODELS)
def test_casadi_functions_agree_with_the_numeric_model(name):
    ca = pytest.importorskip("casadi")
    model = numeric(name)
    functions = casadi_functions(model, actuated=[model.coordinate_names[0]])
    assert isinstance(functions["forward_dynamics"], ca.Function)
    for q, qd, t in random_states(model):
        p = model.parameter_vector(t)
        values, dynamics = references(model, q, qd, t)
        for matrix, expected in values.items():
            got = np.array(functions[matrix](q, qd, p, t), dtype=float)
            np.testing.assert_allclose(got.reshape(np.shape(expected)), expected, rtol=1e-10, atol=1e-12,
                                       err_msg=matrix)
        qdd, lam, mu = (np.array(x, dtype=float).ravel() for x in functions["forward_dynamics"](q, qd, p, t))
        np.testing.assert_allclose(qdd, dynamics.qdd, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(np.concatenate([lam, mu]), np.concatenate([dynamics.lam, dynamics.mu]),
                                   rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("name", MODELS)
def test_jax_functions_jit_and_vmap_agree_with_the_numeric_model(name):
    jax = pytest.importorskip("jax")
    jax.config.update("jax_enable_x64", True)
    model = numeric(name)
    functions = jax_functions(model)
    states = random_states(model)
    p = model.parameter_vector()
    for q, qd, _ in states:
        values, _ = references(model, q, qd, 0.0)
        for matrix, expected in values.items():
            got = np.asarray(jax.jit(functions[matrix])(q, qd, p, 0.0))
            np.testing.assert_allclose(got.reshape(np.shape(expected)), expected, rtol=1e-10, atol=1e-12,
                                       err_msg=matrix)
    Q, QD = (np.array([state[i] for state in states]) for i in (0, 1))
    qdd, lam, mu = jax.jit(jax.vmap(functions["forward_dynamics"], in_axes=(0, 0, None, None)))(Q, QD, p, 0.0)
    for k, (q, qd, _) in enumerate(states):
        expected = model.forward_dynamics(q, qd)
        np.testing.assert_allclose(qdd[k], expected.qdd, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(lam[k], expected.lam, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(mu[k], expected.mu, rtol=1e-9, atol=1e-10)


def test_inverse_dynamics_recovers_the_drive_torque_in_both_backends():
    pytest.importorskip("casadi")
    jax = pytest.importorskip("jax")
    jax.config.update("jax_enable_x64", True)
    equations = derived("four_bar")
    model = equations.numeric(dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1, m2=2, m3=3, I1=0.003, I2=0.06, I3=0.06,
                                   g=9.81, tau=1.5), backend="python")
    q, qd = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 3.0})
    p = model.parameter_vector().copy()
    qdd = model.forward_dynamics(q, qd).qdd  # the motion under tau = 1.5
    p[model.parameter_names.index("tau")] = 0.0  # now the actuator must supply it
    expected = model.with_parameters(tau=0.0).inverse_dynamics(q, qd, qdd, actuated=["q1"])
    assert expected.forces[0] == pytest.approx(1.5, rel=1e-10)
    forces, lam, _ = casadi_functions(model)["inverse_dynamics"](q, qd, qdd, p, 0.0)
    assert float(forces) == pytest.approx(1.5, rel=1e-9)
    np.testing.assert_allclose(np.array(lam).ravel(), expected.lam, rtol=1e-9)
    forces, lam, _ = jax_functions(model)["inverse_dynamics"](q, qd, qdd, p, 0.0)
    assert float(forces[0]) == pytest.approx(1.5, rel=1e-9)
    np.testing.assert_allclose(np.asarray(lam), expected.lam, rtol=1e-9)


def test_unknown_actuated_coordinate_is_named():
    pytest.importorskip("jax")
    with pytest.raises(ValueError, match="unknown actuated coordinate.*'q9'"):
        jax_functions(derived("four_bar"), actuated=["q9"])


@pytest.mark.slow
def test_optimal_control_example_swings_the_crank_to_its_target(tmp_path, monkeypatch, capsys):
    """The torque IPOPT finds, replayed through kronlag.simulate, lands the crank on the target."""
    pytest.importorskip("casadi")
    import runpy
    from pathlib import Path

    monkeypatch.chdir(tmp_path)
    script = Path(__file__).parents[1] / "examples" / "optimal_control" / "four_bar_min_effort.py"
    namespace = runpy.run_path(str(script), run_name="__main__")
    assert (tmp_path / "four_bar_min_effort.png").stat().st_size > 10_000
    replay, rest = namespace["replay"], namespace["rest"]
    assert replay.success
    assert replay.q[-1, 0] == pytest.approx(rest.q[0] + namespace["SWING"], abs=1e-4)
    assert abs(replay.qd[-1, 0]) < 1e-3
    assert namespace["effort"] > 0
