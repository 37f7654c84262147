"""Forward and inverse dynamics, assembly, redundant constraints and singular configurations."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest
import sympy as sp
from helpers import backend_params, derived, double_parallelogram, numeric, parameter_values, random_state

import kronlag
from kronlag import models

cos, sin = sp.cos, sp.sin

FOUR_BAR = dict(l1=1.0, l2=2.5, l3=2.0, l4=2.8, m1=1.0, m2=2.0, m3=1.5, I1=0.1, I2=0.8, I3=0.4, g=9.81, tau=0.7)


@functools.cache
def four_bar(backend: str, redundant: bool = False, tau: float = 0.7) -> kronlag.NumericModel:
    """The four-bar of the paper; ``redundant`` adds a third constraint, loop x + 2 loop y."""
    system = models.four_bar()
    if redundant:
        l1, l2, l3, l4 = sp.symbols("l1 l2 l3 l4")
        q1, q2, q3 = system.coordinates
        system.add_constraint(l1 * cos(q1) + l2 * cos(q2) - l3 * cos(q3) - l4
                              + 2 * (l1 * sin(q1) + l2 * sin(q2) - l3 * sin(q3)), name="redundant")
    return kronlag.derive(system).numeric({**FOUR_BAR, "tau": tau}, backend=backend)


def four_bar_state(model: kronlag.NumericModel) -> tuple[np.ndarray, np.ndarray]:
    return model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": -2.0})


def consistent_state(model: kronlag.NumericModel, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """A random state, projected onto the constraints (positions held close to random)."""
    q, qd, t = random_state(model.equations, seed)
    if model.r:
        q, _ = model.assemble(q)
    G = np.vstack([model.Phi_q(q, t), model.A(q, t)])
    target = np.concatenate([np.zeros(model.r), -model.b(q, t)])
    if len(target):
        qd = qd + np.linalg.lstsq(G, target - G @ qd, rcond=None)[0]
    return q, qd, t


MODELS = ["four_bar", "quick_return", "slider_crank", "heavy_top", "chaplygin_sleigh", "closed_chain_4_relative",
          "double_pendulum"]


@pytest.mark.parametrize("backend", backend_params())
@pytest.mark.parametrize("name", MODELS)
def test_forward_dynamics_solves_the_augmented_system(name, backend):
    model = numeric(name, backend)
    q, qd, t = consistent_state(model, 7)
    for alpha, beta in ((0.0, 0.0), (5.0, 7.0)):
        result = model.forward_dynamics(q, qd, t, alpha=alpha, beta=beta)
        assert result.qdd.shape == (model.m,) and result.lam.shape == (model.r,) and result.mu.shape == (model.s,)
        assert result.unique_multipliers and result.rank == model.r + model.s
        M, Phi_q, A = model.M(q, t), model.Phi_q(q, t), model.A(q, t)
        h = model.f_Q(q, qd, t) - model.Cqd(q, qd, t) - model.g(q, t)
        residual = np.concatenate([
            M @ result.qdd + Phi_q.T @ result.lam + A.T @ result.mu - h,
            Phi_q @ result.qdd - (model.gamma(q, qd, t) - 2 * alpha * Phi_q @ qd - beta ** 2 * model.Phi(q, t)),
            A @ result.qdd - (model.gamma_nh(q, qd, t) - alpha * (A @ qd + model.b(q, t)))])
        scale = max(1.0, np.max(np.abs(M @ result.qdd)), np.max(np.abs(h)))
        assert np.max(np.abs(residual)) < 1e-12 * scale


@pytest.mark.parametrize("backend", backend_params())
@pytest.mark.parametrize("name", ["four_bar", "quick_return", "closed_chain_4_relative", "chaplygin_sleigh"])
def test_constraint_accelerations_by_finite_differences(name, backend):
    """d/dt [Phi_q qd; A qd + b] = 0 along q + qd e + qdd e^2 / 2, independently of gamma."""
    model = numeric(name, backend)
    q, qd, t = consistent_state(model, 8)
    qdd = model.forward_dynamics(q, qd, t).qdd

    def velocity_constraints(e: float) -> np.ndarray:
        qe, qde = q + qd * e + qdd * e ** 2 / 2, qd + qdd * e
        return np.concatenate([model.Phi_q(qe, t) @ qde, model.A(qe, t) @ qde + model.b(qe, t)])

    e = 1e-5
    rate = (velocity_constraints(e) - velocity_constraints(-e)) / (2 * e)
    assert np.max(np.abs(rate)) < 1e-6 * max(1.0, np.max(np.abs(qdd)))


@pytest.mark.parametrize("backend", backend_params())
def test_inverse_dynamics_returns_the_force_that_forward_dynamics_used(backend):
    driven, free = four_bar(backend, tau=0.7), four_bar(backend, tau=0.0)
    q, qd = four_bar_state(driven)
    forward = driven.forward_dynamics(q, qd)
    inverse = free.inverse_dynamics(q, qd, forward.qdd, actuated=("q1",))
    np.testing.assert_allclose(inverse.forces, [0.7], rtol=1e-10)
    np.testing.assert_allclose(inverse.lam, forward.lam, rtol=1e-10)
    assert inverse.mu.shape == (0,) and inverse.unique
    # and back: forward dynamics under the computed torque gives the prescribed acceleration
    again = four_bar(backend, tau=float(inverse.forces[0])).forward_dynamics(q, qd)
    np.testing.assert_allclose(again.qdd, forward.qdd, rtol=1e-10)


@pytest.mark.parametrize("backend", backend_params())
def test_inverse_dynamics_of_a_prescribed_motion(backend):
    """Prescribed crank motion q1(t) = 1 + sin t; q2, q3 follow from the constraints."""
    model = four_bar(backend, tau=0.0)
    times = np.linspace(0.0, 1.0, 5)
    states = []
    q = np.array([1.0, 0.5, 1.5])
    for time in times:
        q, qd = model.assemble(q, fixed={"q1": 1 + np.sin(time)}, qd_fixed={"q1": np.cos(time)})
        # qdd: crank acceleration -sin t, the others from Phi_q qdd = gamma
        Phi_q = model.Phi_q(q)
        qdd1 = -np.sin(time)
        rest = np.linalg.solve(Phi_q[:, 1:], model.gamma(q, qd) - Phi_q[:, 0] * qdd1)
        states.append((q, qd, np.concatenate([[qdd1], rest])))
    q_path, qd_path, qdd_path = (np.array(x) for x in zip(*states))
    result = model.inverse_dynamics_trajectory(times, q_path, qd_path, qdd_path, actuated=("q1",))
    assert result.forces.shape == (5, 1) and result.lam.shape == (5, 2) and result.mu.shape == (5, 0)
    for i, time in enumerate(times):
        driven = kronlag.derive(models.four_bar()).numeric({**FOUR_BAR, "tau": float(result.forces[i, 0])},
                                                            backend="python")
        np.testing.assert_allclose(driven.forward_dynamics(q_path[i], qd_path[i], time).qdd, qdd_path[i],
                                   rtol=1e-9, atol=1e-12)


def test_inverse_dynamics_rejects_an_impossible_motion():
    model = numeric("double_pendulum", "python")
    with pytest.raises(ValueError, match="cannot produce this motion"):
        model.inverse_dynamics([0.1, 0.2], [0.0, 0.0], [1.0, 1.0], actuated=("q1",))
    with pytest.raises(ValueError, match="unknown actuated"):
        model.inverse_dynamics([0.1, 0.2], [0.0, 0.0], [1.0, 1.0], actuated=("q7",))
    both = model.inverse_dynamics([0.1, 0.2], [0.3, 0.0], [1.0, 1.0], actuated=("q1", sp.Symbol("q2")))
    q, qd = np.array([0.1, 0.2]), np.array([0.3, 0.0])
    np.testing.assert_allclose(both.forces, model.M(q) @ [1.0, 1.0] + model.Cqd(q, qd) + model.g(q), rtol=1e-12)


@pytest.mark.parametrize("backend", backend_params())
def test_assemble_holds_fixed_values(backend):
    model = numeric("quick_return", backend)
    guess = model.assemble(np.array([0.5, 1.4, 2.8]))[0] + 0.05
    q, qd = model.assemble(guess, fixed={"phi1": guess[0]}, qd_fixed={"phi1": 1.5}, qd_guess=[1.0, 1.0, 1.0])
    assert np.max(np.abs(model.Phi(q))) < 1e-12
    assert q[0] == guess[0] and qd[0] == 1.5
    assert np.max(np.abs(model.Phi_q(q) @ qd)) < 1e-12
    sleigh = numeric("chaplygin_sleigh", backend)
    q, qd = sleigh.assemble([0.0, 0.0, 0.3], qd_fixed={"x": 1.0, "theta": 0.5})
    assert np.max(np.abs(sleigh.A(q) @ qd + sleigh.b(q))) < 1e-12
    assert (qd[0], qd[2]) == (1.0, 0.5)


def test_assembly_errors_give_the_residual():
    model = four_bar("python")
    # with D at l4 = 6 and the crank at q1 = 3, B is 6.99 from D: out of reach of l2 + l3 = 4.5
    far = kronlag.derive(models.four_bar()).numeric({**FOUR_BAR, "l4": 6.0}, backend="python")
    with pytest.raises(kronlag.AssemblyError, match="max \\|Phi\\|") as error:
        far.assemble([1.0, 0.5, 1.5], fixed={"q1": 3.0})
    assert error.value.residual > 1e-3
    q, _ = four_bar_state(model)
    with pytest.raises(kronlag.AssemblyError, match="velocity constraints"):
        model.assemble(q, fixed={"q1": 1.0}, qd_fixed={"q1": 1.0, "q2": 1.0, "q3": 1.0})
    with pytest.raises(ValueError, match="unknown coordinate"):
        model.assemble(q, fixed={"x": 1.0})


@pytest.mark.parametrize("backend", backend_params())
def test_redundant_constraint_gives_the_same_accelerations(backend):
    plain, redundant = four_bar(backend), four_bar(backend, redundant=True)
    q, qd = four_bar_state(plain)
    assert redundant.r == 3 and np.max(np.abs(redundant.Phi(q))) < 1e-12
    reference = plain.forward_dynamics(q, qd, alpha=1.0, beta=2.0)
    with pytest.warns(kronlag.RedundantConstraintsWarning, match="rank 2 < 3"):
        result = redundant.forward_dynamics(q, qd, alpha=1.0, beta=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # warned once per model only
        redundant.forward_dynamics(q, qd)
    assert not result.unique_multipliers and result.rank == 2
    np.testing.assert_allclose(result.qdd, reference.qdd, rtol=1e-10)
    # the constraint forces Phi_q^T lambda are unique, the minimum-norm lambda is one split of them
    np.testing.assert_allclose(redundant.Phi_q(q).T @ result.lam, plain.Phi_q(q).T @ reference.lam, rtol=1e-10)
    assert np.linalg.norm(result.lam) < np.linalg.norm(reference.lam)


@pytest.mark.parametrize("backend", backend_params())
def test_overconstrained_parallelogram_against_its_one_degree_of_freedom_reference(backend):
    values = dict(l=0.7, d=1.3, m=1.2, m_c=2.5, J=0.09, J_c=0.6, g=9.81)
    model = kronlag.derive(double_parallelogram()).numeric(values, backend=backend)
    theta, omega = 0.8, 1.7
    q, qd = model.assemble([theta, 0.0, theta, theta], fixed={"q1": theta},
                           qd_guess=[omega, 0, omega, omega], qd_fixed={"q1": omega})
    np.testing.assert_allclose(q, [theta, 0.0, theta, theta], atol=1e-12)
    with pytest.warns(kronlag.RedundantConstraintsWarning):
        result = model.forward_dynamics(q, qd)
    assert result.rank == 3 and not result.unique_multipliers
    # one coordinate theta: T = 1/2 J_theta omega^2, Pi = g l cos... ; the coupler translates on a circle of radius l
    l, m, m_c, inertia, g = (values[k] for k in ("l", "m", "m_c", "J", "g"))
    j_theta = 3 * (inertia + m * l ** 2 / 4) + m_c * l ** 2
    theta_dd = -g * l * (3 * m / 2 + m_c) * np.cos(theta) / j_theta
    np.testing.assert_allclose(result.qdd, [theta_dd, 0.0, theta_dd, theta_dd], atol=1e-10)


@pytest.mark.parametrize("backend", backend_params())
def test_singular_configuration_is_an_error(backend):
    values = {**parameter_values("double_pendulum"), "m2": 0.0, "I2": 0.0}
    model = derived("double_pendulum").numeric(values, backend=backend)
    with pytest.raises(kronlag.SingularConfigurationError, match=r"q = \[0.1, 0.2\]") as error:
        model.forward_dynamics([0.1, 0.2], [0.0, 1.0], 0.5)
    np.testing.assert_array_equal(error.value.qd, [0.0, 1.0])
    assert error.value.t == 0.5


def closed_chain_model(n: int, angles: str, backend: str) -> tuple[kronlag.NumericModel, np.ndarray]:
    """``closed_chain(n, angles)`` with random links, and a configuration near one where it closes."""
    rng = np.random.default_rng(n)
    lengths, masses = rng.uniform(0.5, 1.5, n), rng.uniform(0.5, 2.0, n)
    relative = rng.uniform(-0.6, 0.6, n) + np.r_[0.3, np.zeros(n - 1)]
    absolute = np.cumsum(relative)
    values = {**{f"l{i + 1}": lengths[i] for i in range(n)}, **{f"m{i + 1}": masses[i] for i in range(n)},
              **{f"I{i + 1}": masses[i] * lengths[i] ** 2 / 12 for i in range(n)},
              "xg": float(lengths @ np.cos(absolute)), "yg": float(lengths @ np.sin(absolute)), "g": 9.81}
    model = kronlag.derive(models.closed_chain(n, angles)).numeric(values, backend=backend)
    return model, relative if angles == "relative" else absolute


def dense_augmented_solution(model: kronlag.NumericModel, q, qd, t, alpha, beta) -> tuple[np.ndarray, np.ndarray]:
    """``[qdd; lambda; mu]`` of ``[[M, G^T], [G, 0]] [qdd; nu] = [h; c]`` by a dense least-squares solve of
    the whole (m + r + s) system: the minimum-norm solution, so the minimum-norm multipliers when
    rows of ``G = [Phi_q; A]`` are redundant (singular values below the rank tolerance dropped)."""
    M, Phi_q, A = model.M(q, t), model.Phi_q(q, t), model.A(q, t)
    G = np.vstack([Phi_q, A])
    h = model.f_Q(q, qd, t) - model.Cqd(q, qd, t) - model.g(q, t)
    c = np.concatenate([model.gamma(q, qd, t) - 2 * alpha * Phi_q @ qd - beta ** 2 * model.Phi(q, t),
                        model.gamma_nh(q, qd, t) - alpha * (A @ qd + model.b(q, t))])
    k = len(G)
    augmented = np.block([[M, G.T], [G, np.zeros((k, k))]])
    solution = np.linalg.lstsq(augmented, np.concatenate([h, c]), rcond=1e-9)[0]
    return solution[:model.m], solution[model.m:]


def closed_chain_states(n: int, angles: str, backend: str) -> tuple[kronlag.NumericModel, list]:
    """``closed_chain(n, angles)`` at three assembled states with random consistent speeds."""
    model, q_near = closed_chain_model(n, angles, backend)
    states = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        q, _ = model.assemble(q_near + rng.uniform(-0.05, 0.05, model.m))
        qd, Phi_q = rng.uniform(-1, 1, model.m), model.Phi_q(q)
        states.append((q, qd - np.linalg.pinv(Phi_q) @ (Phi_q @ qd), 0.3 * seed))
    return model, states


def redundant_four_bar_states(backend: str) -> tuple[kronlag.NumericModel, list]:
    model = four_bar(backend, redundant=True)
    return model, [(*four_bar_state(model), 0.0)]


def double_parallelogram_states(backend: str) -> tuple[kronlag.NumericModel, list]:
    values = dict(l=0.7, d=1.3, m=1.2, m_c=2.5, J=0.09, J_c=0.6, g=9.81)
    model = kronlag.derive(double_parallelogram()).numeric(values, backend=backend)
    states = []
    for theta, omega in ((0.8, 1.7), (-0.4, 0.6)):
        q, qd = model.assemble([theta, 0.0, theta, theta], fixed={"q1": theta},
                               qd_guess=[omega, 0, omega, omega], qd_fixed={"q1": omega})
        states.append((q, qd, 0.0))
    return model, states


def random_consistent_states(name: str, backend: str) -> tuple[kronlag.NumericModel, list]:
    model = numeric(name, backend)
    return model, [consistent_state(model, seed) for seed in range(3)]


#: Models and states for the comparison with a dense solve, by case.
AUGMENTED_CASES = {
    "closed_chain_12_relative": functools.partial(closed_chain_states, 12, "relative"),
    "closed_chain_12_absolute": functools.partial(closed_chain_states, 12, "absolute"),
    "closed_chain_30_absolute": functools.partial(closed_chain_states, 30, "absolute"),
    "four_bar_redundant": redundant_four_bar_states,
    "double_parallelogram": double_parallelogram_states,
    "chaplygin_sleigh": functools.partial(random_consistent_states, "chaplygin_sleigh"),
    "heavy_top": functools.partial(random_consistent_states, "heavy_top"),
}


@pytest.mark.parametrize("backend", backend_params())
@pytest.mark.parametrize("case", AUGMENTED_CASES)
def test_forward_dynamics_matches_a_dense_solve_of_the_augmented_system(case, backend):
    """The structured solver (null-space QR + Cholesky in C) against NumPy's dense least squares on the
    full augmented matrix, at random consistent states, with and without Baumgarte terms; redundant
    constraints included (four-bar with a third loop equation, the double parallelogram)."""
    model, states = AUGMENTED_CASES[case](backend)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
        for q, qd, t in states:
            for alpha, beta in ((0.0, 0.0), (5.0, 7.0)):
                result = model.forward_dynamics(q, qd, t, alpha=alpha, beta=beta)
                qdd, nu = dense_augmented_solution(model, q, qd, t, alpha, beta)
                np.testing.assert_allclose(result.qdd, qdd, rtol=1e-8, atol=1e-8 * np.max(np.abs(qdd)))
                multipliers = np.concatenate([result.lam, result.mu])
                scale = max(1.0, np.max(np.abs(nu), initial=0.0))
                np.testing.assert_allclose(multipliers, nu, rtol=1e-7, atol=1e-8 * scale)
