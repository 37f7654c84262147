"""Every solver converges at the order it declares (``Solver.order``, ``Solver.min_order``), as
diffrax's ``test_ode_order``: the error against a closed-form solution falls like ``h^order``.

Two constrained problems with exact solutions, both the Cartesian pendulum (``x^2 + y^2 = L^2``,
m = 2, r = 1):

- *swinging*: IFToMM A01, released from rest at (-L, 0) under gravity; exact motion by Jacobi
  elliptic functions (:func:`kronlag.benchmarks.iftomm.pendulum_exact`);
- *whirling*: no gravity, started at (-L, 0) with speed ``L w`` along -y: uniform circular
  motion ``x = -L cos(w t)``, ``y = -L sin(w t)`` (the rod's tension ``m L w^2`` keeps the speed).

Fixed-order methods (DOP853 of ``"baumgarte"``, ``"projection"`` and, compiled, ``"dop853"``, the trapezoidal rule of
``"ali3p"``) run at fixed steps ``h = max_step`` with tolerances under which the error test
passes at every step (checked: the steps are ``h``), on the whirling pendulum, whose error
constant is the same all along the orbit.  (On the swinging one the projected DOP853 converges
faster than ``h^8`` over the steps whose error is above rounding, local slopes 8.5 to 9.5, and
could not tell order 8 from 9.)  The fitted slope of ``log(error)`` against ``log(h)`` must lie
within :data:`BAND` of the declared order, so that a declaration one off fails.

Variable-order methods (CVODE's Adams-Moulton in ``"compiled"`` and ``"switching"``, IDA's BDF in
``"ggl"``) choose their steps and orders themselves, and their error against the tolerance falls
like ``tol^(q/(q+1))`` at order q (slopes 0.5, 0.67, 0.75, 0.8 for q = 1..4: too close to tell
orders apart).  So they are checked in three ways:

1. with the order capped at q (``SolverOptions.max_order``, set by a :class:`Solver` subclass
   passed as ``method``) and the tolerance tightened, the integrator settles at order q with
   steps ``h(t) = tol^(1/(q+1)) theta(t)`` of a fixed shape, so the error falls like
   ``(T / steps)^q``: the slope against the mean step is fitted, for the orders whose error stays
   well above rounding over a range of tolerances;
2. the declared ``order`` is the highest the integrator has: capped there the run is the same as
   uncapped, capped one higher it is refused;
3. ``min_order``: CVODE reports the orders it used, and the lowest is ``min_order`` (IDA's orders
   are not reported by scikit-sundae; its lowest order is checked by 1. only).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
import pytest
from helpers import needs_compiler

import kronlag
from kronlag import models
from kronlag.benchmarks import iftomm
from kronlag.simulation import METHODS, MultibodyProblem, Solver, SolverOptions
from kronlag.simulation.solvers.compiled import cvode_segment

#: Largest distance of a fitted slope from the declared order: below 0.5, so that an order
#: declared one too high or too low fails.
BAND = 0.45

#: Speed of the whirling pendulum (rad/s) and the time spans.
WHIRL = 3.0
T_FIXED = 2.0
T_VARIABLE = 2.0


@dataclass(frozen=True)
class Case:
    """A pendulum, its start and its exact bob position ``exact(t) -> (len(t), 2)``."""

    model: kronlag.NumericModel
    q0: np.ndarray
    qd0: np.ndarray
    exact: object

    def error(self, trajectory: kronlag.Trajectory) -> float:
        """Largest error of the bob position at the outputs."""
        assert trajectory.success, trajectory.message
        return float(np.max(np.abs(trajectory.q[:, :2] - self.exact(trajectory.t))))


@functools.cache
def swinging() -> Case:
    benchmark = iftomm.benchmark("A01")
    model = benchmark.numeric()
    return Case(model, *benchmark.initial_state(model), iftomm.pendulum_exact)


@functools.cache
def whirling() -> Case:
    model = kronlag.derive(models.pendulum_cartesian()).numeric({"m": 1.0, "L": 1.0, "g": 0.0})
    return Case(model, np.array([-1.0, 0.0]), np.array([0.0, -WHIRL]),
                lambda t: np.column_stack([-np.cos(WHIRL * t), -np.sin(WHIRL * t)]))


def capped(solver: type[Solver], max_order: int) -> type[Solver]:
    """``solver`` with its order capped at ``max_order``: a subclass for ``simulate(method=...)``."""

    class Capped(solver):
        name = f"{solver.name}, order <= {max_order}"

        def __init__(self, options: SolverOptions):
            super().__init__(replace(options, max_order=max_order))

    return Capped


def fitted_slope(x, y) -> float:
    """Slope of the least-squares line through ``(log x, log y)``."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def assert_order(slope: float, order: int, what: str) -> None:
    assert abs(slope - order) < BAND, f"{what}: error falls like h^{slope:.2f}, declared order {order}"


# -- fixed order: fixed steps ------------------------------------------------------------------

#: Steps per T_FIXED and tolerances under which the error test passes at every step.  ALI3-P
#: stops Newton's method at 1e-3 of its error tolerance and the trapezoidal rule turns an
#: unconverged position into an acceleration error 4/h^2 times larger: its tolerances are tight
#: (1e-8 for both after the division by Index3Solver.TOLERANCE_SCALE) and its steps short enough to
#: pass them.
FIXED_STEPS = {
    "baumgarte": ((12, 16, 24, 32, 48), {"rtol": 1e6, "atol": 1e-12}),
    "dop853": ((12, 16, 24, 32, 48), {"rtol": 1e6, "atol": 1e-12}),
    "projection": ((8, 12, 16, 24), {"rtol": 1e6, "atol": 1e-12}),
    "ali3p": ((1600, 3200, 6400, 12800), {"rtol": 3e-3, "atol": 3e-3}),
}


@functools.cache
def fixed_step_slope(method: str) -> float:
    case, (counts, tolerances) = whirling(), FIXED_STEPS[method]
    errors = []
    for n in counts:
        h = T_FIXED / n
        run = kronlag.simulate(case.model, (0.0, T_FIXED), case.q0, case.qd0, method=method, max_step=h, **tolerances)
        steps = np.diff(run.t)
        # the premise: every step but a few at the start (DOP853's first step estimate) is h
        assert steps.max() <= h * (1 + 1e-9) and np.count_nonzero(np.isclose(steps, h, rtol=1e-9)) >= n - 2
        errors.append(case.error(run))
    return fitted_slope(T_FIXED / np.array(counts), errors)


@needs_compiler
@pytest.mark.parametrize("method", sorted(FIXED_STEPS))
def test_fixed_order_method_converges_at_its_order(method):
    solver = METHODS[method]
    assert not solver.variable_order() and solver.min_order == solver.order
    assert_order(fixed_step_slope(method), solver.order, method)


# -- variable order: capped orders -------------------------------------------------------------

#: Orders checked by their convergence (1. of the module docstring) and the tolerances (powers of
#: ten, in half decades) over which each converges at its order with the error above rounding.
CAPS = {
    # CVODE runs at the requested tolerances divided by CompiledSolver.TOLERANCE_SCALE (1e4)
    "compiled": {1: (-1, -4), 2: (-2, -7), 3: (-3, -9), 4: (-3, -10)},
    "switching": {1: (-1, -4), 2: (-2, -7)},
    "ggl": {1: (-3, -5), 2: (-4, -7)},
}
OUTPUTS = np.linspace(0.0, T_VARIABLE, 21)


def run_variable(method: str, tol: float, max_order: int | None = None) -> kronlag.Trajectory:
    case, solver = swinging(), METHODS[method]
    return kronlag.simulate(case.model, (0.0, T_VARIABLE), case.q0, case.qd0, t_eval=OUTPUTS, rtol=tol, atol=tol,
                            method=solver if max_order is None else capped(solver, max_order))


@needs_compiler
@pytest.mark.parametrize(("method", "order"), [(method, order) for method in CAPS for order in CAPS[method]])
def test_variable_order_method_converges_at_each_capped_order(method, order):
    solver = METHODS[method]
    assert solver.variable_order() and solver.min_order <= order <= solver.order
    first, last = CAPS[method][order]
    runs = [run_variable(method, tol, order) for tol in np.logspace(first, last, 2 * (first - last) + 1)]
    mean_steps = [T_VARIABLE / run.steps for run in runs]
    errors = [swinging().error(run) for run in runs]
    assert_order(fitted_slope(mean_steps, errors), order, f"{method} capped at {order}")


@needs_compiler
@pytest.mark.parametrize("method", sorted(CAPS))
def test_declared_order_is_the_highest_the_integrator_has(method):
    order = METHODS[method].order
    free, at_order = run_variable(method, 1e-9), run_variable(method, 1e-9, order)
    assert np.array_equal(free.q, at_order.q) and free.steps == at_order.steps
    try:
        beyond = run_variable(method, 1e-9, order + 1)
    except ValueError as error:  # scikit-sundae refuses it before IDA starts
        assert "max_order" in str(error)
    else:
        assert beyond.result is kronlag.Result.SOLVER_FAILED and beyond.steps == 0


@needs_compiler
@pytest.mark.parametrize("tol", [1e-6, 1e-10])
def test_cvode_uses_orders_from_its_lowest_up(tol):
    case = swinging()
    problem = MultibodyProblem(model=case.model, t0=0.0, t1=T_VARIABLE, q0=case.q0, qd0=case.qd0, t_eval=None,
                               alpha=10.0, beta=10.0)
    options = SolverOptions(rtol=tol, atol=tol, max_step=np.inf, max_steps=100_000, progress=None)
    lowest, highest = cvode_segment(problem, options, 0.0, problem.y0).orders
    for method in ("compiled", "switching"):
        solver = METHODS[method]
        assert lowest == solver.min_order and solver.min_order < highest <= solver.order


# -- the interface the order tests use: simulate(method=Solver subclass) ------------------------


def test_simulate_takes_a_solver_subclass_and_names_the_trajectory_after_it():
    case = whirling()
    solver = capped(METHODS["projection"], 3)
    run = kronlag.simulate(case.model, (0.0, 0.1), case.q0, case.qd0, method=solver)
    assert run.success and run.method == solver.name == "projection, order <= 3"


@pytest.mark.parametrize("method", ["rk4", 3, None, Solver, METHODS["projection"](None), ["projection"]])
def test_a_method_that_is_no_name_and_no_solver_is_an_input_error(method):
    case = whirling()
    with pytest.raises(kronlag.InputError, match="method"):
        kronlag.simulate(case.model, (0.0, 0.1), case.q0, case.qd0, method=method)


def test_orders_are_numbers_and_the_ranges_hold_together():
    for name, solver in METHODS.items():
        assert isinstance(solver.order, int) and isinstance(solver.min_order, int), name
        assert 1 <= solver.min_order <= solver.order and solver.integrator, name
    # the switching method's range holds both of its integrators'
    switching, orders = METHODS["switching"], [METHODS[name] for name in ("compiled", "ali3p")]
    assert switching.min_order == min(s.min_order for s in orders) and switching.order == max(s.order for s in orders)


def test_every_driver_code_reads_back_as_its_result():
    for result in kronlag.Result:
        assert kronlag.Result.of_code(result.code) is result
    # CVODE's own flags (CV_ERR_FAILURE, CV_CONV_FAILURE, ...) are failures of the integrator
    assert all(kronlag.Result.of_code(flag) is kronlag.Result.SOLVER_FAILED for flag in range(-99, 0))
