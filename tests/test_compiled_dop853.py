"""The compiled DOP853 method (``method="dop853"``, ``simulation/c/dop853.c``): scipy's DOP853 written in C
step for step on the Baumgarte ODE, outputs projected.

Checked against what others computed: scipy's own DOP853 on the same equations (the ``"baumgarte"``
method, whose right-hand side is the same forward dynamics) takes the same steps; the whirling
pendulum's closed-form motion; IFToMM A01's exact solution.  Its order (8) is checked with the other
fixed-order methods in ``test_solver_order.py``, its stop at singular configurations in
``test_robustness.py`` and controllers in ``test_controllers.py`` (every method)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import needs_compiler

import kronlag
from kronlag import models
from kronlag.benchmarks import iftomm
from kronlag.simulation import METHODS

pytestmark = needs_compiler

FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=1.5, I1=1.0 / 300, I2=0.06, I3=1.5 * 0.25 / 12,
                g=9.81, tau=0.0)


def four_bar():
    model = kronlag.derive(models.four_bar()).numeric(FOUR_BAR)
    q0, qd0 = model.assemble([0.3, 0.8, 1.3], fixed={"q1": 0.3})
    return model, q0, qd0


def test_it_takes_the_steps_scipy_dop853_takes_on_the_same_equations():
    model, q0, qd0 = four_bar()
    compiled = kronlag.simulate(model, (0.0, 10.0), q0, qd0, method="dop853", rtol=1e-8, atol=1e-10)
    scipy_run = kronlag.simulate(model, (0.0, 10.0), q0, qd0, method="baumgarte", rtol=1e-8, atol=1e-10)
    assert compiled.success and compiled.method == "dop853"
    # the same steps and evaluations (rejections and the first step's included), to the odd decision
    # that rounding turns: the error estimate is a sum with cancellation, whose last digits differ
    # between numpy's dot and a loop (four-bar: 400 steps, 6086 evaluations both)
    assert abs(compiled.steps - scipy_run.steps) <= 4 and abs(compiled.nfev - scipy_run.nfev) <= 60
    early = scipy_run.t <= 1.0  # step sizes equal to the rounding of that estimate, before it has grown
    np.testing.assert_allclose(compiled.t[early], scipy_run.t[early], rtol=1e-5)
    np.testing.assert_allclose(compiled.q[early], scipy_run.q[early], rtol=0, atol=1e-5)


def test_dense_outputs_agree_with_scipy_and_are_projected():
    model, q0, qd0 = four_bar()
    times = np.linspace(0.0, 2.0, 41)
    compiled = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method="dop853", rtol=1e-10, atol=1e-12, t_eval=times)
    scipy_run = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method="baumgarte", rtol=1e-10, atol=1e-12, t_eval=times)
    np.testing.assert_array_equal(compiled.t, times)
    assert np.max(np.abs(compiled.q - scipy_run.q)) < 1e-9
    assert np.max(np.abs(compiled.position_residual)) < 1e-13  # projected: scipy's run keeps its drift
    assert np.max(np.abs(compiled.velocity_residual)) < 1e-12
    energy = compiled.total_energy  # no torque: conserved
    assert np.ptp(energy) < 1e-9 * abs(energy[0])


def test_the_whirling_pendulum_follows_its_closed_form():
    """No gravity, the bob started at (-1, 0) with speed 3 along -y: x = -cos(3 t), y = -sin(3 t), and the
    rod's tension m L w^2 = 9 N as the multiplier."""
    model = kronlag.derive(models.pendulum_cartesian()).numeric({"m": 1.0, "L": 1.0, "g": 0.0})
    times = np.linspace(0.0, 2.0, 21)
    run = kronlag.simulate(model, (0.0, 2.0), [-1.0, 0.0], [0.0, -3.0], method="dop853", rtol=1e-11, atol=1e-13,
                           t_eval=times)
    exact = np.column_stack([-np.cos(3 * times), -np.sin(3 * times)])
    assert np.max(np.abs(run.q - exact)) < 1e-9
    # Phi = (x^2 + y^2 - L^2) / 2 or similar: the multiplier is the tension over a constant factor
    assert np.ptp(run.lam[:, 0]) < 1e-8 * np.max(np.abs(run.lam[:, 0]))


def test_ifto_mm_a01_agrees_with_the_exact_pendulum():
    benchmark = iftomm.benchmark("A01")
    model = benchmark.numeric()
    q0, qd0 = benchmark.initial_state(model)
    times = np.linspace(0.0, 2.0, 41)
    run = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method="dop853", rtol=1e-10, atol=1e-12, t_eval=times)
    assert np.max(np.abs(run.q[:, :2] - iftomm.pendulum_exact(times))) < 1e-8


def test_every_step_outputs_and_the_step_limit():
    model, q0, qd0 = four_bar()
    run = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method="dop853")
    assert run.success and len(run.t) == run.steps + 1 and np.all(np.diff(run.t) > 0)
    limited = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method="dop853", max_steps=3)
    assert limited.result is kronlag.Result.MAX_STEPS and len(limited.t) == 4
    capped = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method="dop853", max_step=0.01)
    assert np.max(np.diff(capped.t)) <= 0.01 * (1 + 1e-12)


def test_limits_and_exact_stiction_are_refused_naming_the_methods_that_watch_them():
    system = models.four_bar()
    system.add_limit(system.coordinates[0], lower=-1.0, upper=1.0, restitution=0.5, name="stop")
    model = kronlag.derive(system).numeric(FOUR_BAR)
    q0, qd0 = model.assemble([0.3, 0.8, 1.3], fixed={"q1": 0.3})
    with pytest.raises(kronlag.InputError, match="method='dop853' does not watch limits; use 'switching'"):
        kronlag.simulate(model, (0.0, 1.0), q0, qd0, method="dop853")


def test_it_is_a_fixed_order_method_of_order_8_with_the_compiled_method_s_formulation():
    solver = METHODS["dop853"]
    assert solver.order == solver.min_order == 8 and not solver.variable_order()
    assert solver.formulation == METHODS["compiled"].formulation and solver.samples_inside
