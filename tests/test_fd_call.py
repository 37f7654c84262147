"""The per-call path of forward dynamics (issue 21 item 6, issue 19 item 1): the C call layer's
``ForwardDynamics`` builds the result object itself; every check that protects the user stays (shapes,
non-finite states, singular M, redundant constraints), on every backend."""

from __future__ import annotations

import dataclasses
import sys
import warnings

import numpy as np
import pytest

import kronlag
from kronlag import models
from kronlag.numeric.codegen import c_backend
from helpers import (DOUBLE_PARALLELOGRAM_VALUES, backend_params, derived, double_parallelogram, needs_compiler,
                     parameter_values)

UR5_VALUES = {"g": 9.81, **{f"tau{i}": 0.3 * i - 1.0 for i in range(1, 7)}}


def ur5(backend: str) -> kronlag.NumericModel:
    return kronlag.derive(models.ur5()).numeric(UR5_VALUES, backend=backend)


def ctypes_ur5(monkeypatch) -> kronlag.NumericModel:
    """The UR5 through ctypes, as where the C call layer was not built."""
    monkeypatch.setattr(c_backend, "FAST_CALL", None)
    return ur5("c")


@pytest.mark.parametrize("backend", [*backend_params(), pytest.param("ctypes", marks=needs_compiler)])
def test_unconstrained_arm_solves_m_qdd_equal_the_forces(backend, monkeypatch):
    """No constraints: qdd = M^-1 (f_Q - C qd - g), checked against numpy's dense solve of the accessors' M and
    right-hand side (the arm's joint torques tau_i are f_Q), at states where M is far from diagonal."""
    model = ctypes_ur5(monkeypatch) if backend == "ctypes" else ur5(backend)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q, qd = rng.uniform(-np.pi, np.pi, 6), rng.uniform(-2, 2, 6)
        result = model.forward_dynamics(q, qd)
        assert type(result) is kronlag.ForwardDynamicsResult
        expected = np.linalg.solve(model.M(q), model.f_Q(q, qd) - model.Cqd(q, qd) - model.g(q))
        np.testing.assert_allclose(result.qdd, expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max())
        assert result.unique_multipliers is True and result.rank == 0
        assert result.lam.shape == (0,) and result.mu.shape == (0,) and result.qdd.dtype == np.float64


@pytest.mark.parametrize("backend", [*backend_params(), pytest.param("ctypes", marks=needs_compiler)])
def test_wrong_shapes_are_refused_with_the_item_named(backend, monkeypatch):
    model = ctypes_ur5(monkeypatch) if backend == "ctypes" else ur5(backend)
    with pytest.raises(kronlag.InputError, match=r"^q must have shape \(6,\), got \(5,\)$"):
        model.forward_dynamics(np.zeros(5), np.zeros(6))
    with pytest.raises(kronlag.InputError, match=r"^qd must have shape \(6,\), got \(6, 1\)$"):
        model.forward_dynamics(np.zeros(6), np.zeros((6, 1)))


@pytest.mark.parametrize("backend", backend_params())
def test_a_mass_matrix_not_positive_definite_is_reported_singular(backend):
    """A double pendulum whose second link has no mass: M is singular (no constraint: the unconstrained
    Cholesky path) -- a SingularConfigurationError, not accelerations of order 1 / rounding."""
    values = {**parameter_values("double_pendulum"), "m2": 0.0, "I2": 0.0}
    model = derived("double_pendulum").numeric(values, backend=backend)
    assert model.r + model.s == 0
    with pytest.raises(kronlag.SingularConfigurationError):
        model.forward_dynamics([0.3, -0.4], [1.0, 0.5])


@pytest.mark.parametrize("backend", backend_params())
def test_non_finite_state_is_a_numerical_error_not_a_singular_one(backend):
    model = ur5(backend)
    with pytest.raises(kronlag.NumericalError, match="not finite") as error:
        model.forward_dynamics([0.1, np.nan, 0, 0, 0, 0], np.zeros(6), 0.25)
    assert not isinstance(error.value, kronlag.SingularConfigurationError)
    assert "t = 0.25" in str(error.value)


@needs_compiler
def test_the_c_result_is_the_dataclass_with_independent_arrays():
    """The result built in C is an ordinary ForwardDynamicsResult: its fields, repr, dataclass helpers, own
    arrays (writing one changes no other and no later result), and no reference leaked per call."""
    model = derived("four_bar").numeric(parameter_values("four_bar"), backend="c")
    reference = derived("four_bar").numeric(parameter_values("four_bar"), backend="python")
    q, qd = model.assemble([0.4] + [0.5] * (model.m - 1), fixed={model.coordinate_names[0]: 0.4},
                           qd_guess=[1.0] + [0.0] * (model.m - 1), qd_fixed={model.coordinate_names[0]: 1.0})
    result, expected = model.forward_dynamics(q, qd, alpha=1.0, beta=2.0), reference.forward_dynamics(
        q, qd, alpha=1.0, beta=2.0)
    assert [field.name for field in dataclasses.fields(result)] == ["qdd", "lam", "mu", "unique_multipliers", "rank"]
    np.testing.assert_allclose(result.qdd, expected.qdd, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result.lam, expected.lam, rtol=1e-9, atol=1e-12)
    assert (result.unique_multipliers, result.rank) == (expected.unique_multipliers, expected.rank)
    assert "ForwardDynamicsResult(qdd=array(" in repr(result)
    assert dataclasses.replace(result, rank=7).rank == 7
    before = result.lam.copy()
    result.qdd[:] = 1e9
    np.testing.assert_array_equal(result.lam, before)
    np.testing.assert_allclose(model.forward_dynamics(q, qd, alpha=1.0, beta=2.0).qdd, expected.qdd, rtol=1e-9,
                               atol=1e-12)
    fresh = model.forward_dynamics(q, qd)
    references = [sys.getrefcount(fresh.qdd), sys.getrefcount(fresh.lam), sys.getrefcount(fresh.mu)]
    assert references == [2, 2, 2]  # the result's slot and getrefcount's argument: nothing leaked
    counts = sys.getrefcount(kronlag.ForwardDynamicsResult), sys.getrefcount(True)
    for _ in range(1000):
        model.forward_dynamics(q, qd)
    assert abs(sys.getrefcount(kronlag.ForwardDynamicsResult) - counts[0]) <= 2
    assert abs(sys.getrefcount(True) - counts[1]) <= 50


@needs_compiler
def test_the_call_layer_refuses_a_result_type_it_cannot_fill():
    """ForwardDynamics fills the result's slots in place: a class without those slots is refused when the
    caller is made, not written over at the first call."""
    call = c_backend.FAST_CALL
    if call is None:
        pytest.skip("the C call layer is not built")

    @dataclasses.dataclass
    class NoSlots:
        qdd: object
        lam: object
        mu: object
        unique_multipliers: bool
        rank: int

    with pytest.raises(TypeError, match="must be a slot"):
        call.ForwardDynamics(1, 2, 0, 0, 1, NoSlots)
    with pytest.raises(TypeError):
        call.ForwardDynamics(1, 2, 0, 0, 1, 3)


@pytest.mark.parametrize("backend", backend_params())
def test_redundant_constraints_warn_once_and_keep_unique_accelerations(backend):
    """The double parallelogram's redundant bar: rank < r, the warning once per model, the minimum-norm
    multipliers flagged, the accelerations those of the system without the redundant row's dependence."""
    model = kronlag.derive(double_parallelogram()).numeric(DOUBLE_PARALLELOGRAM_VALUES, backend=backend)
    q, _ = model.assemble([0.3, 0.0, 0.3, 0.3], fixed={"q1": 0.3})
    with pytest.warns(kronlag.RedundantConstraintsWarning, match="redundant constraints"):
        first = model.forward_dynamics(q, np.zeros(model.m))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        second = model.forward_dynamics(q, np.zeros(model.m))
    assert not first.unique_multipliers and first.rank < model.r + model.s
    np.testing.assert_allclose(second.qdd, first.qdd)
    residual = model.M(q) @ first.qdd + model.Phi_q(q).T @ first.lam - model.f_Q(q, np.zeros(model.m)) \
        + model.g(q)
    assert np.abs(residual).max() < 1e-9 * max(1.0, np.abs(model.g(q)).max())
