"""Bad inputs and failure modes of kronlag.simulate (issue: trustworthy simulation).

Each case is checked against what must happen -- a clear error before any work, or a
partial trajectory with status -1 and a message naming the place -- never a crash or a
silent wrong answer.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest
from helpers import derived

import kronlag
import kronlag.benchmarks.iftomm
from kronlag.numeric.tolerances import APPROACH_RTOL, rank_magnitudes, row_scales, singular_ratio
from kronlag.simulation import METHODS, InitialStateWarning

FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=1.5, I1=0.2 ** 2 / 12, I2=2 * 0.6 ** 2 / 12,
                I3=1.5 * 0.5 ** 2 / 12, g=9.81, tau=0.5)


@functools.cache
def four_bar():
    model = derived("four_bar").numeric(FOUR_BAR)
    q0, qd0 = model.assemble([0.3, 0.8, 1.35], fixed={"q1": 0.3})
    return model, q0, qd0


@pytest.mark.parametrize("options, message", [
    (dict(t_eval=[]), "t_eval is empty"),
    (dict(t_eval=[0.0, np.nan]), "t_eval"),
    (dict(max_steps=0), "max_steps"),
    (dict(max_steps=-1), "max_steps"),
    (dict(rtol=-1e-8), "rtol"),
    (dict(rtol=0.0), "rtol"),
    (dict(atol=np.nan), "atol"),
    (dict(max_step=0.0), "max_step"),
])
def test_bad_options_are_refused_before_any_work(options, message):
    model, q0, qd0 = four_bar()
    with pytest.raises(ValueError, match=message):
        kronlag.simulate(model, (0.0, 1.0), q0, qd0, **options)


def test_non_finite_initial_state_names_the_coordinate():
    model, q0, qd0 = four_bar()
    q0 = q0.copy()
    q0[1] = np.nan
    with pytest.raises(ValueError, match="q0 is not finite for q2"):
        kronlag.simulate(model, (0.0, 1.0), q0, qd0)


def test_non_finite_parameter_is_refused():
    with pytest.raises(ValueError, match="parameter g: expected a finite number"):
        derived("four_bar").numeric({**FOUR_BAR, "g": float("nan")})


def test_slightly_inconsistent_start_is_corrected_with_a_warning():
    model, q0, qd0 = four_bar()
    with pytest.warns(InitialStateWarning, match=r"q moved by [0-9.e-]+, qd by"):
        trajectory = kronlag.simulate(model, (0.0, 0.1), q0 + 1e-6, qd0)
    assert trajectory.success
    assert np.max(np.abs(trajectory.position_residual)) < 1e-10


def test_consistent_start_gives_no_warning():
    model, q0, qd0 = four_bar()
    with warnings.catch_warnings():
        warnings.simplefilter("error", InitialStateWarning)
        kronlag.simulate(model, (0.0, 0.1), q0, qd0)


def test_start_far_from_the_constraints_is_an_assembly_error():
    model, q0, qd0 = four_bar()
    with pytest.raises(kronlag.AssemblyError, match="another assembly branch"):
        kronlag.simulate(model, (0.0, 0.1), q0 + np.array([0.0, 0.3, -0.2]), qd0)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_failed_runs_have_equal_length_arrays(method):
    model, q0, qd0 = four_bar()
    trajectory = kronlag.simulate(model, (0.0, 100.0), q0, qd0, method=method, max_steps=5,
                                  t_eval=np.linspace(0.0, 100.0, 7))
    assert trajectory.status == -1 and trajectory.result is kronlag.Result.MAX_STEPS
    n = len(trajectory.t)
    for name in ("q", "qd", "qdd", "lam", "kinetic_energy", "potential_energy", "position_residual",
                 "velocity_residual"):
        assert len(getattr(trajectory, name)) == n, name


def test_gimbal_lock_is_named_as_a_singular_configuration():
    # Heavy top in Euler angles (precession, nutation, spin) started at nutation 0: the
    # angular velocity does not determine the precession and spin rates, M is singular.
    model = derived("heavy_top").numeric(dict(m=1.0, l=0.1, g=9.81, Ixx=0.01, Izz=0.02))
    q0, qd0 = np.array([0.0, 1e-9, 0.0]), np.array([0.0, 0.5, 0.0])
    for method in ("compiled", "dop853"):
        trajectory = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method=method)
        assert trajectory.status == -1 and trajectory.result is kronlag.Result.SINGULAR, method
        assert "singular configuration" in trajectory.message and "t = " in trajectory.message
        assert "q = [" in trajectory.message


def test_singular_ratio_matches_the_singular_values_at_a_passage():
    # IFToMM A02 (N = 2) with all bars horizontal: Phi_q drops from rank 4 to rank N = 2; off it,
    # the ratio is of the size of the smallest singular value relative to the largest (of the rows
    # in their units at the start: the horizontal closure rows vanish there, they are not rescaled).
    benchmark = kronlag.benchmarks.iftomm.benchmark("A02")
    model = benchmark.numeric()
    names = model.coordinate_names
    q = np.zeros(model.m)
    horizontal = model.Phi_q(q)
    cranks = np.array([0.3 if name.startswith("phi") else 0.0 for name in names])  # tilted, couplers level
    generic = int(np.linalg.matrix_rank(model.Phi_q(cranks), tol=1e-8))
    assert generic == model.r and np.linalg.matrix_rank(horizontal, tol=1e-8) == 2, names
    scales = row_scales(model.Phi_q(cranks), model.rank_rtol)  # the rows' units at a start with tilted cranks
    ratio, _ = singular_ratio(horizontal, generic, scales)
    assert ratio < 1e-12
    tilted = np.array([0.01 if name.startswith("phi") else 0.0 for name in names])
    ratio, _ = singular_ratio(model.Phi_q(tilted), generic, scales)
    singular_values = np.linalg.svd(model.Phi_q(tilted) / scales[:, None], compute_uv=False)
    assert ratio == pytest.approx(singular_values[-1] / singular_values[0], rel=0.5)
    assert ratio < APPROACH_RTOL
    assert len(rank_magnitudes(horizontal)[0]) == model.r


def test_index1_methods_stop_at_the_approach_and_the_default_passes():
    benchmark = kronlag.benchmarks.iftomm.benchmark("A02")
    model = benchmark.numeric()
    q0, qd0 = benchmark.initial_state(model)
    for method in ("compiled", "dop853", "projection"):
        trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method)
        assert trajectory.status == -1 and trajectory.result is kronlag.Result.APPROACH
        assert "approaches a singular configuration" in trajectory.message
        assert trajectory.t[-1] < 0.72 and len(trajectory.events) == 1
    trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0)
    assert trajectory.success and trajectory.method == "switching" and trajectory.result is kronlag.Result.SUCCESS
    # two passages in 2 s (all bars horizontal at t ~ 0.71 s and 1.23 s), named by their constraints
    assert len(trajectory.events) == 2
    for event, expected in zip(trajectory.events, (0.714, 1.229)):
        assert event.t == pytest.approx(expected, abs=5e-3)
        assert event.ratio < APPROACH_RTOL and event.constraints
    assert benchmark.error(trajectory) < 1e-5


@functools.cache
def parallelogram():
    """Three parallel cranks (absolute angles th0..th2, pivots 1 m apart, 1 m long, 1 kg, slender) and
    one rigid coupler (centre x, y, angle phi; 2 m, 2 kg) pinned to the three crank tips: 6 constraints
    of rank 5 (the middle crank is redundant), one degree of freedom."""
    import sympy as sp

    from kronlag.model.builtin.planar import _bar

    th = kronlag.coordinates("th0 th1 th2")
    x, y, phi = kronlag.coordinates("x y phi")
    g = sp.Symbol("g")
    system = kronlag.System([*th, x, y, phi], parameters=[g], gravity=(0, -g), name="parallelogram")
    for k in range(3):
        system.add_body(_bar(f"crank{k}", 1, sp.Rational(1, 12), (k, 0), 1, th[k]))
    system.add_body(kronlag.PlanarBody("coupler", mass=2, inertia=sp.Rational(2 * 4, 12), position=(x, y),
                                       angle=phi))
    for k in range(3):
        system.add_constraint(k + sp.cos(th[k]) - (x + (k - 1) * sp.cos(phi)), name=f"pin{k} x")
        system.add_constraint(sp.sin(th[k]) - (y + (k - 1) * sp.sin(phi)), name=f"pin{k} y")
    return kronlag.derive(system).numeric({"g": 9.81})


@pytest.mark.parametrize("method", ["auto", "compiled", "projection"])
def test_parallelogram_with_a_redundant_crank_swings_like_the_reduced_pendulum(method):
    # Reduced by hand: th0 = th1 = th2 = th, phi = 0, the coupler translates with the crank tips:
    # T = 1/2 (3 * m L^2 / 3 + m_c L^2) th'^2 = 3/2 th'^2, V = (3 * m L / 2 + m_c L) g sin th = 3.5 g sin th.
    from scipy.integrate import solve_ivp

    model = parallelogram()
    start = -np.pi / 2 + 0.5                                   # far from the horizontal singular positions
    q0 = np.array([start] * 3 + [1 + np.cos(start), np.sin(start), 0.0])
    assert np.linalg.matrix_rank(model.Phi_q(q0), tol=1e-8) == 5
    times = np.linspace(0.0, 5.0, 51)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
        trajectory = kronlag.simulate(model, (0.0, 5.0), q0, np.zeros(6), method=method, t_eval=times)
    reference = solve_ivp(lambda t, y: [y[1], -3.5 * 9.81 * np.cos(y[0]) / 3.0], (0.0, 5.0), [start, 0.0],
                          method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times)
    assert trajectory.success, trajectory.message
    assert trajectory.events == ()
    np.testing.assert_allclose(trajectory.q[:, :3], np.repeat(reference.y[0][:, None], 3, axis=1), atol=1e-5)
    assert np.max(np.abs(trajectory.position_residual)) < 1e-9


@pytest.mark.parametrize("method", ["ali3p", "switching"])
@pytest.mark.parametrize("rtol", [1e-2, 1e-4, 1e-6])
def test_index3_methods_keep_the_branch_even_at_loose_tolerances(method, rtol):
    # The physical motion of A02 keeps all cranks parallel (one rotation); the other branch at the
    # horizontal singular configuration does not.  Loose tolerances make large phase errors, but
    # the cranks must stay parallel through all ten passages.
    benchmark = kronlag.benchmarks.iftomm.benchmark("A02")
    model = benchmark.numeric()
    q0, qd0 = benchmark.initial_state(model)
    cranks = [i for i, name in enumerate(model.coordinate_names) if name.startswith("phi")]
    trajectory = kronlag.simulate(model, benchmark.t_span, q0, qd0, method=method, rtol=rtol, atol=rtol)
    assert trajectory.success, trajectory.message
    angles = np.mod(trajectory.q[:, cranks] - trajectory.q[:, cranks[:1]] + np.pi, 2 * np.pi) - np.pi
    assert np.max(np.abs(angles)) < 1e-6


@pytest.mark.parametrize("method", ["auto", "compiled"])
def test_parallelogram_started_at_its_singular_configuration_is_never_silently_wrong(method):
    # Cranks horizontal and in line with the coupler: Phi_q has rank 4 (the redundant crank and the
    # singular configuration), 5 once the motion leaves it. The reduced pendulum is the reference.
    from scipy.integrate import solve_ivp

    model = parallelogram()
    speed = 2.0
    q0, qd0 = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), np.array([speed, speed, speed, 0.0, speed, 0.0])
    assert np.linalg.matrix_rank(model.Phi_q(q0), tol=1e-8) == 4
    times = np.linspace(0.0, 2.0, 41)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
        trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method, t_eval=times)
    reference = solve_ivp(lambda t, y: [y[1], -3.5 * 9.81 * np.cos(y[0]) / 3.0], (0.0, 2.0), [0.0, speed],
                          method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times)
    if method == "auto":  # the default starts with ALI3-P, which is sure of the branch
        assert trajectory.success, trajectory.message
    if trajectory.success:
        np.testing.assert_allclose(trajectory.q[:, :3], np.repeat(reference.y[0][:, None], 3, axis=1), atol=1e-5)
    else:
        assert "t = " in trajectory.message and "q = " in trajectory.message
