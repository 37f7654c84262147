"""The approach test does not depend on the constraints' units (kronlag.numeric.tolerances.singular_ratio).

Each row of ``Phi_q`` is measured in its own unit, its norm at the start of the run: a constraint
written in other units (one row multiplied by 1000, as a loop in millimetres beside rows in metres or
radians) gets the same decision and the same trajectory.  Before, the ratio of the rows' raw sizes
decided, and the index-1 methods stopped at the first step of a four-bar whose vertical loop row was
in millimetres.  The C watch (``simulation/c/monitor.c``) and the Python one agree.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from helpers import MODEL_BUILDERS

import kronlag
import kronlag.benchmarks.iftomm
from kronlag.numeric.tolerances import APPROACH_RTOL, row_scales, singular_ratio

FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=1.5, I1=0.2 ** 2 / 12, I2=2 * 0.6 ** 2 / 12,
                I3=1.5 * 0.5 ** 2 / 12, g=9.81, tau=0.5)
#: The factor one constraint row is multiplied by: metres to millimetres.
FACTOR = 1000


def _scaled(system: kronlag.System, row: str) -> kronlag.System:
    """``system`` with the constraint ``row`` multiplied by :data:`FACTOR` (in place)."""
    system.constraints[:] = [dataclasses.replace(item, expression=FACTOR * item.expression) if item.name == row
                             else item for item in system.constraints]
    return system


@functools.cache
def four_bars() -> tuple[kronlag.NumericModel, kronlag.NumericModel]:
    """The four-bar, and the same with its vertical loop row in millimetres."""
    plain = kronlag.derive(MODEL_BUILDERS["four_bar"]()).numeric(FOUR_BAR)
    scaled = kronlag.derive(_scaled(MODEL_BUILDERS["four_bar"](), "loop y")).numeric(FOUR_BAR)
    return plain, scaled


@functools.cache
def a02s() -> tuple[kronlag.benchmarks.iftomm.Benchmark, kronlag.NumericModel, kronlag.NumericModel]:
    """IFToMM A02 (N = 2), and the same with the first coupler's horizontal closure row times 1000."""
    benchmark = kronlag.benchmarks.iftomm.benchmark("A02")
    plain = benchmark.numeric()
    system = benchmark.build(**benchmark.options)
    row = system.constraints[0].name
    scaled = kronlag.derive(_scaled(system, row)).numeric(dict(benchmark.parameters))
    return benchmark, plain, scaled


def test_the_ratio_is_invariant_to_a_row_in_other_units():
    plain, scaled = four_bars()
    q0, _ = plain.assemble([0.3, 0.8, 1.35], fixed={"q1": 0.3})
    q = q0 + np.array([0.2, -0.1, 0.15])  # another configuration of the run (the units are the start's)
    ratios = [singular_ratio(model.Phi_q(q), model.r, row_scales(model.Phi_q(q0), model.rank_rtol))[0]
              for model in (plain, scaled)]
    assert ratios[1] == pytest.approx(ratios[0], rel=1e-12)
    # the rows' raw sizes differ by the factor: their raw ratio would decide otherwise
    raw = np.linalg.svd(scaled.Phi_q(q0), compute_uv=False)
    assert raw[-1] / raw[0] < APPROACH_RTOL < ratios[0]


@pytest.mark.parametrize("method", ["compiled", "dop853", "projection", "ggl", "switching"])
def test_a_row_in_millimetres_gets_the_same_trajectory(method):
    plain, scaled = four_bars()
    q0, qd0 = plain.assemble([0.3, 0.8, 1.35], fixed={"q1": 0.3})
    times = np.linspace(0.0, 1.0, 11)
    runs = [kronlag.simulate(model, (0.0, 1.0), q0, qd0, method=method, t_eval=times) for model in (plain, scaled)]
    for run in runs:
        assert run.success, run.message
        assert [interval.method for interval in run.intervals] == [runs[0].intervals[0].method]
    # GGL's residual holds the rows themselves (IDA weighs them by size): the same to its tolerance
    close = 1e-5 if method == "ggl" else 1e-9
    np.testing.assert_allclose(runs[1].q, runs[0].q, rtol=0, atol=close)
    lam = runs[1].lam.copy()
    lam[:, 1] *= FACTOR  # the multiplier of a row times 1000 is the old one / 1000
    np.testing.assert_allclose(lam, runs[0].lam, rtol=1e-6, atol=close * 100)


def test_a02_with_a_row_in_millimetres_is_handed_over_at_the_same_points():
    benchmark, plain, scaled = a02s()
    q0, qd0 = benchmark.initial_state(plain)
    runs = [kronlag.simulate(model, (0.0, 2.0), q0, qd0) for model in (plain, scaled)]
    for run in runs:
        assert run.success, run.message
    intervals = [[(interval.method, interval.t_start) for interval in run.intervals] for run in runs]
    assert [method for method, _ in intervals[1]] == [method for method, _ in intervals[0]]
    assert len(intervals[0]) == 5  # compiled, ali3p through each of the two passages, compiled
    # the hand-overs fall on accepted steps: the same to a step (the solves' rounding differs)
    np.testing.assert_allclose([t for _, t in intervals[1]], [t for _, t in intervals[0]], rtol=0, atol=1e-2)
    np.testing.assert_allclose([event.t for event in runs[1].events], [event.t for event in runs[0].events],
                               atol=1e-3)  # t* extrapolated from the sampled ratio: to a step
    for run in runs:
        assert np.max(np.abs(benchmark.errors(run))) < 1e-5
    # the index-1 method stops at the approach, not at the start (where the raw rows decided)
    stops = [kronlag.simulate(model, (0.0, 2.0), q0, qd0, method="compiled") for model in (plain, scaled)]
    assert [stop.result for stop in stops] == [kronlag.Result.APPROACH] * 2
    assert stops[1].t[-1] == pytest.approx(stops[0].t[-1], abs=1e-3)
    assert 0.6 < stops[0].t[-1] < 0.714


@pytest.mark.parametrize("which", ["plain", "scaled"])
def test_the_compiled_watch_agrees_with_the_python_definition(which):
    # The passages recorded by the C watch (index3.c's and cvode.c's, monitor.c) carry the smallest
    # sampled ratio and q there: tolerances.singular_ratio with the run's units gives the same number.
    benchmark, plain, scaled = a02s()
    model = plain if which == "plain" else scaled
    q0, qd0 = benchmark.initial_state(plain)
    run = kronlag.simulate(model, (0.0, 2.0), q0, qd0)
    scales = row_scales(model.Phi_q(q0), model.rank_rtol)  # the run's units (stepping.approach_scales)
    assert len(run.events) == 2
    for event in run.events:
        ratio, _ = singular_ratio(model.Phi_q(event.q), model.r, scales)
        assert event.ratio == pytest.approx(ratio, rel=1e-9, abs=1e-15)
