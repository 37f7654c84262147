"""The error follows the tolerance, for every method (issue 17, deliverable 3).

- IFToMM A02 (N = 2, 4) with the default method: the error of B0 against the benchmark's
  independent reference (scipy DOP853 on the exact reduced motion) is at most 1 mm on the grid
  rtol in {1e-4, 1e-6, 1e-8} x atol in {1e-6, 1e-8}, and tightening either tolerance never makes
  it more than 2 times worse (it was 2 to 12 mm, and grew when rtol was tightened);
- redundant constraints away from singular configurations (a parallelogram with a third crank,
  IFToMM A04 Bricard) run to the end with every method at rtol 1e-10, energy drift <= 1e-8;
- the degrees of freedom are the mobility at the assembled state, not m - r;
- a state that is not finite is not called a singular configuration.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import kronlag
from helpers import DOUBLE_PARALLELOGRAM_VALUES, double_parallelogram, needs_compiler
from kronlag.benchmarks.iftomm import BRICARD_ENERGY_SCALE, benchmark
from kronlag.simulation.solvers import METHODS

RTOLS = (1e-4, 1e-6, 1e-8)
ATOLS = (1e-6, 1e-8)


#: The accuracy of B0 the A02 tests ask of the default method at the default tolerances (test_iftomm).
A02_ACCURACY = 1e-5


def a02_errors(n: int) -> dict[tuple[float, float], float]:
    case = benchmark("A02", n=n)
    model = case.numeric()
    errors = {}
    for rtol in RTOLS:
        for atol in ATOLS:
            run = case.simulate(model, method="auto", rtol=rtol, atol=atol)
            assert run.method == "switching" and run.status == 0, run.message
            errors[rtol, atol] = case.error(run)
    return errors


@needs_compiler
@pytest.mark.parametrize("n", [2, pytest.param(4, marks=pytest.mark.slow)])
def test_a02_error_follows_the_tolerance(n):
    errors = a02_errors(n)
    table = ", ".join(f"rtol {r:g} atol {a:g}: {e:.2e}" for (r, a), e in errors.items())
    assert max(errors.values()) <= 1e-3, table
    for (rtol, atol), error in errors.items():
        looser = [errors[key] for key in ((rtol * 100, atol), (rtol, atol * 100)) if key in errors]
        # below the benchmark's accuracy the error is rounding amplified by the unstable passages,
        # as likely to be smaller as larger at a looser tolerance
        assert all(error <= max(2 * other, A02_ACCURACY) for other in looser), \
            f"tighter is worse at rtol {rtol:g} atol {atol:g}: {table}"


# -- redundant constraints --------------------------------------------------------------------


def parallelogram_case():
    model = kronlag.derive(double_parallelogram()).numeric(DOUBLE_PARALLELOGRAM_VALUES)
    theta = -1.0  # hanging, at rest: it swings about -pi/2, far from the cranks' alignment with the coupler
    q0, qd0 = model.assemble([theta, 0.0, theta, theta], fixed={"q1": theta}, qd_guess=[0.0] * 4,
                             qd_fixed={"q1": 0.0})
    values = DOUBLE_PARALLELOGRAM_VALUES
    scale = values["g"] * values["l"] * (3 * values["m"] + values["m_c"])
    return model, q0, qd0, scale


def assert_runs_to_the_end(model, q0, qd0, scale: float, method: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
        run = kronlag.simulate(model, (0.0, 10.0), q0, qd0, method=method, rtol=1e-10, atol=1e-10,
                               t_eval=np.linspace(0.0, 10.0, 201))
    assert run.status == 0 and run.t[-1] == 10.0, f"{method}: {run.message}"
    energy = np.asarray(run.kinetic_energy) + np.asarray(run.potential_energy)
    drift = np.max(np.abs(energy - energy[0])) / scale
    assert drift <= 1e-8, f"{method}: energy drift {drift:.2e}"


@needs_compiler
@pytest.mark.parametrize("method", sorted(METHODS))
def test_redundant_parallelogram_with_every_method(method):
    assert_runs_to_the_end(*parallelogram_case(), method)


@needs_compiler
@pytest.mark.parametrize("method", ["compiled", "switching"])
def test_redundant_rows_cost_the_compiled_path_no_steps(method):
    """Off the constraints by its drift, the CVODE state made the redundant rows nearly dependent
    instead of dependent: accelerations of order drift/rounding and 10^4-10^5 steps where the same
    mechanism without the redundant crank takes ~10^3 (switching: ALI3-P throughout, 3x more steps
    than CVODE)."""
    model, q0, qd0, _ = parallelogram_case()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
        run = kronlag.simulate(model, (0.0, 10.0), q0, qd0, method=method, t_eval=np.linspace(0.0, 10.0, 11))
    assert run.status == 0, run.message
    assert run.steps < 3000, f"{method}: {run.steps} steps for 10 s of a pendulum-like swing"


@needs_compiler
def test_mobility_of_the_redundant_parallelogram_is_one():
    model, q0, _, _ = parallelogram_case()
    assert model.m - model.r == 0 and model.mobility(q0) == 1


@pytest.fixture(scope="module")
def bricard():
    case = benchmark("A04")
    model = case.numeric()
    q0, qd0 = case.initial_state(model)
    return model, q0, qd0


@needs_compiler
@pytest.mark.slow
@pytest.mark.parametrize("method", sorted(METHODS))
def test_bricard_with_every_method(bricard, method):
    assert_runs_to_the_end(*bricard, BRICARD_ENERGY_SCALE, method)


@needs_compiler
@pytest.mark.slow
def test_mobility_of_bricard_is_one(bricard):
    model, q0, _ = bricard
    assert model.m - model.r == 0 and model.mobility(q0) == 1


# -- a diverged state is not a singular configuration ------------------------------------------


def test_a_state_that_is_not_finite_is_not_called_singular():
    model, q0, qd0, _ = parallelogram_case()
    q = q0.copy()
    q[1] = np.nan
    with pytest.raises(kronlag.NumericalError, match="not finite") as error:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
            model.forward_dynamics(q, qd0)
    assert not isinstance(error.value, kronlag.SingularConfigurationError)
    assert "positive definite" not in str(error.value)
