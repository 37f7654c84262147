"""kronlag.analysis: static equilibrium and linearization, against independent references.

References: the analytic small-oscillation frequencies of the double pendulum, a
one-degree-of-freedom model of the four-bar reduced by hand from its closed-form
loop geometry, and sympy.physics.mechanics' Linearizer.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize
import sympy as sp
import sympy.physics.mechanics as me

import kronlag
from kronlag.core.errors import EquilibriumError

GRAVITY, LENGTH, MASS = 9.81, 0.5, 1.0
FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=3.0, g=9.81, tau=0.0)
FOUR_BAR_VALUES = dict(FOUR_BAR, I1=1.0 * 0.2 ** 2 / 12, I2=2.0 * 0.6 ** 2 / 12, I3=3.0 * 0.5 ** 2 / 12)


def cartesian_double_pendulum() -> kronlag.System:
    """Two point masses on massless rods, in the redundant coordinates x1, y1, x2, y2."""
    x1, y1, x2, y2 = kronlag.coordinates("x1 y1 x2 y2")
    m, l, g = sp.symbols("m l g")
    system = kronlag.System([x1, y1, x2, y2], parameters=[m, l, g], gravity=(0, -g),
                            name="cartesian_double_pendulum")
    system.add_body(kronlag.PointMass("p1", mass=m, position=(x1, y1)))
    system.add_body(kronlag.PointMass("p2", mass=m, position=(x2, y2)))
    system.add_constraint(x1 ** 2 + y1 ** 2 - l ** 2, name="rod1")
    system.add_constraint((x2 - x1) ** 2 + (y2 - y1) ** 2 - l ** 2, name="rod2")
    return system


@pytest.fixture(scope="module")
def pendulum():
    return kronlag.derive(cartesian_double_pendulum()).numeric(dict(m=MASS, l=LENGTH, g=GRAVITY))


@pytest.fixture(scope="module")
def four_bar():
    return kronlag.derive(kronlag.models.four_bar()).numeric(FOUR_BAR_VALUES)


def test_cartesian_double_pendulum_hangs_and_swings_at_the_analytic_frequencies(pendulum):
    rest = pendulum.equilibrium([0.1, -0.4, 0.2, -0.9])
    np.testing.assert_allclose(rest.q, [0, -LENGTH, 0, -2 * LENGTH], atol=1e-10)
    np.testing.assert_allclose(rest.lam, [2 * MASS * GRAVITY / (2 * LENGTH), MASS * GRAVITY / (2 * LENGTH)],
                               rtol=1e-10)  # rod tensions / (2 l): Phi_q rows are 2 (x, y)
    linear = pendulum.linearize(rest.q)
    # equal masses and lengths: w^2 = (g / l) (2 -+ sqrt 2)
    expected = np.sqrt(GRAVITY / LENGTH * (2 + np.array([-1, 1]) * np.sqrt(2)))
    np.testing.assert_allclose(linear.natural_frequencies, expected, rtol=1e-10)
    assert len(linear.coordinates) == 2 and set(linear.coordinates) <= {"x1", "y1", "x2", "y2"}
    slow = linear.mode_shapes[:, 0]  # angles in ratio 1 : sqrt 2, so x2 / x1 = 1 + sqrt 2
    assert slow[2] / slow[0] == pytest.approx(1 + np.sqrt(2), rel=1e-9)
    np.testing.assert_allclose(slow[[1, 3]], 0, atol=1e-9)  # no vertical motion to first order
    np.testing.assert_allclose(linear.damping_ratios, 0, atol=1e-12)


def test_without_the_multiplier_stiffness_the_redundant_pendulum_has_no_stiffness(pendulum):
    """In x, y coordinates gravity has no stiffness: all of K_r comes from d(Phi_q^T lambda)/dq."""
    rest = pendulum.equilibrium([0.0, -0.5, 0.0, -1.0])
    R = pendulum.linearize(rest.q).velocity_transformation
    gravity_stiffness = np.array([np.gradient([pendulum.g(rest.q + h * e)[i] for h in (-1e-6, 0, 1e-6)],
                                              1e-6)[1] for e in np.eye(4) for i in range(4)]).reshape(4, 4)
    np.testing.assert_allclose(R.T @ gravity_stiffness @ R, 0, atol=1e-8)


# -- four-bar: a one-degree-of-freedom model reduced by hand ------------------------------------------


def loop_geometry(q1: float) -> dict[str, np.ndarray]:
    """Hanging assembly of the four-bar for crank angle q1, in closed form.

    C is the intersection of the circles about B (radius l2) and D (radius l3)
    on the lower side of BD; returns the centres of mass and link angles.
    """
    l1, l2, l3, l4 = (FOUR_BAR[name] for name in ("l1", "l2", "l3", "l4"))
    B, D = l1 * np.array([np.cos(q1), np.sin(q1)]), np.array([l4, 0.0])
    d = np.linalg.norm(D - B)
    along = (d ** 2 + l2 ** 2 - l3 ** 2) / (2 * d)
    across = np.sqrt(l2 ** 2 - along ** 2)
    unit = (D - B) / d
    normal = np.array([unit[1], -unit[0]])  # BD turned clockwise: below for BD pointing right
    C = B + along * unit + across * normal
    centres = np.array([B / 2, (B + C) / 2, (C + D) / 2])
    angles = np.array([q1, np.arctan2(*(C - B)[::-1]), np.arctan2(*(C - D)[::-1])])
    return {"centres": centres, "angles": angles}


def reduced_four_bar(q1: float, h: float = 1e-5) -> tuple[float, float, float]:
    """Generalized inertia J(q1), potential slope dV/dq1 and stiffness d2V/dq1^2 of the hand-reduced model."""
    masses = np.array([FOUR_BAR["m1"], FOUR_BAR["m2"], FOUR_BAR["m3"]])
    inertias = np.array([FOUR_BAR_VALUES[name] for name in ("I1", "I2", "I3")])

    def potential(angle):
        return FOUR_BAR["g"] * masses @ loop_geometry(angle)["centres"][:, 1]

    ahead, behind = loop_geometry(q1 + h), loop_geometry(q1 - h)
    velocity = (ahead["centres"] - behind["centres"]) / (2 * h)
    rate = (ahead["angles"] - behind["angles"]) / (2 * h)
    inertia = masses @ (velocity ** 2).sum(axis=1) + inertias @ rate ** 2
    h2 = 1e-4
    slope = (potential(q1 + h2) - potential(q1 - h2)) / (2 * h2)
    curvature = (-potential(q1 + 2 * h2) + 16 * potential(q1 + h2) - 30 * potential(q1)
                 + 16 * potential(q1 - h2) - potential(q1 - 2 * h2)) / (12 * h2 ** 2)
    return inertia, slope, curvature


def test_four_bar_hanging_equilibrium_and_frequency_match_the_hand_reduced_model(four_bar):
    lowest = scipy.optimize.minimize_scalar(
        lambda q1: FOUR_BAR["g"] * np.array([1.0, 2.0, 3.0]) @ loop_geometry(q1)["centres"][:, 1],
        bounds=(-2.5, -0.8), method="bounded", options={"xatol": 1e-12})
    inertia, _, stiffness = reduced_four_bar(lowest.x)
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    assert rest.q[0] == pytest.approx(lowest.x, abs=1e-6)
    np.testing.assert_allclose(rest.q[1:], loop_geometry(rest.q[0])["angles"][1:], atol=1e-9)
    linear = four_bar.linearize(rest.q)
    assert len(linear.coordinates) == 1
    np.testing.assert_allclose(linear.natural_frequencies, [np.sqrt(stiffness / inertia)], rtol=1e-6)
    crank = four_bar.linearize(rest.q, independent=["q1"])
    assert crank.mass[0, 0] == pytest.approx(inertia, rel=1e-8)
    assert crank.stiffness[0, 0] == pytest.approx(stiffness, rel=1e-6)


def test_holding_force_on_a_held_crank_is_the_slope_of_the_potential(four_bar):
    rest = four_bar.equilibrium(loop_geometry(0.3)["angles"] + 0.05, fixed={"q1": 0.3})
    _, slope, _ = reduced_four_bar(0.3)
    assert rest.q[0] == 0.3
    assert rest.holding_forces["q1"] == pytest.approx(slope, rel=1e-7)
    np.testing.assert_allclose(rest.reactions, rest.lam)


def test_a_torque_input_drives_the_crank_through_the_reduced_inertia(four_bar):
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    inertia, _, _ = reduced_four_bar(rest.q[0])
    linear = four_bar.linearize(rest.q, independent=["q1"], inputs=["tau"], outputs=["q1", "q3", "q1d"])
    assert linear.B[1, 0] == pytest.approx(1 / inertia, rel=1e-7)
    dq3_dq1 = (loop_geometry(rest.q[0] + 1e-6)["angles"][2] - loop_geometry(rest.q[0] - 1e-6)["angles"][2]) / 2e-6
    np.testing.assert_allclose(linear.C, [[1, 0], [dq3_dq1, 0], [0, 1]], atol=1e-7)
    assert linear.D.shape == (3, 1)


def test_no_equilibrium_raises_with_the_residual():
    model = kronlag.derive(kronlag.models.four_bar()).numeric(dict(FOUR_BAR_VALUES, tau=100.0))
    with pytest.raises(EquilibriumError, match="no static equilibrium") as error:
        model.equilibrium([-1.5, -0.5, -1.5])
    assert error.value.residual > 1e-3


def test_bad_independent_coordinates_and_inputs_are_named(four_bar):
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    with pytest.raises(ValueError, match="independent coordinates"):
        four_bar.linearize(rest.q, independent=["q1", "q2"])
    with pytest.raises(ValueError, match="unknown input 'force'"):
        four_bar.linearize(rest.q, inputs=["force"])
    with pytest.raises(ValueError, match="not on the constraint manifold"):
        four_bar.linearize([0.0, 0.0, 0.0])


# -- sympy.physics.mechanics Linearizer -----------------------------------------------------------------


def test_agrees_with_sympy_linearizer_at_a_moving_state(pendulum):
    """Both A matrices at a state with speeds (a point of a trajectory), same independent coordinates."""
    x1, y1, x2, y2 = coordinates = me.dynamicsymbols("x1 y1 x2 y2")
    speeds = [q.diff() for q in coordinates]
    m, l, g = sp.symbols("m l g")
    lagrangian = m / 2 * sum(v ** 2 for v in speeds) - m * g * (y1 + y2)
    method = me.LagrangesMethod(lagrangian, coordinates,
                                hol_coneqs=[x1 ** 2 + y1 ** 2 - l ** 2, (x2 - x1) ** 2 + (y2 - y1) ** 2 - l ** 2])
    eom = method.form_lagranges_equations()
    values = {m: MASS, l: LENGTH, g: GRAVITY}
    angles, rates = np.array([0.3, -0.2]), np.array([0.5, -0.7])
    q = LENGTH * np.array([np.sin(angles[0]), -np.cos(angles[0]),
                           np.sin(angles).sum(), -np.cos(angles).sum()])
    qd = LENGTH * np.array([np.cos(angles[0]) * rates[0], np.sin(angles[0]) * rates[0],
                            np.cos(angles) @ rates, np.sin(angles) @ rates])
    point = {**values, **dict(zip(coordinates, q)), **dict(zip(speeds, qd))}
    accelerations = [float(v) for v in method.rhs().subs(values).subs(point)[4:8]]
    point.update(dict(zip([v.diff() for v in speeds], accelerations)))
    # the multipliers consistent with `eom` (LagrangesMethod.rhs returns them with the opposite sign)
    residual = eom.subs(point)
    lam_coefficients = np.array(residual.jacobian(method.lam_vec), dtype=float)
    offset = np.array(residual.subs(dict.fromkeys(method.lam_vec, 0)), dtype=float)[:, 0]
    point.update(zip(method.lam_vec, np.linalg.lstsq(lam_coefficients, -offset, rcond=None)[0]))
    linearizer = method.to_linearizer(q_ind=[x1, x2], qd_ind=[speeds[0], speeds[2]], q_dep=[y1, y2],
                                      qd_dep=[speeds[1], speeds[3]])
    A_reference, _ = linearizer.linearize(op_point=point, A_and_B=True)
    linear = pendulum.linearize(q, qd, independent=["x1", "x2"])
    np.testing.assert_allclose(linear.A, np.array(A_reference, dtype=float), rtol=1e-9, atol=1e-9)


# -- output ---------------------------------------------------------------------------------------------


def test_state_space_for_python_control(four_bar):
    control = pytest.importorskip("control")
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    system = four_bar.linearize(rest.q, inputs=["tau"], outputs=["q1"]).to_control()
    assert isinstance(system, control.StateSpace)
    poles = np.sort(np.abs(np.imag(system.poles())))
    np.testing.assert_allclose(poles, np.repeat(four_bar.linearize(rest.q).natural_frequencies, 2), rtol=1e-9)


def test_mode_animation_stays_on_the_constraint_manifold(four_bar, tmp_path):
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    linear = four_bar.linearize(rest.q)
    motion = linear.mode_trajectory(0, amplitude=0.2, samples=9)
    np.testing.assert_allclose([four_bar.Phi(q) for q in motion.q], 0, atol=1e-10)
    crank = motion.q[:, 0] - rest.q[0]
    assert np.max(np.abs(crank)) == pytest.approx(0.2 * np.max(np.abs(linear.mode_shapes[0, 0])), rel=1e-2)
    path = linear.animate_mode(0, tmp_path / "mode.gif", fps=5, duration=0.4, width=120, trace=False)
    assert path.stat().st_size > 0


def test_cli_equilibrium_prints_the_hanging_state_and_its_frequency(capsys):
    from kronlag.app.cli import main

    status = main(["equilibrium", "four_bar", "--guess", "q1=-1.5", "--guess", "q2=-0.5", "--guess", "q3=-1.5",
                   "--modes"])
    output = capsys.readouterr().out
    assert status == 0
    lowest = scipy.optimize.minimize_scalar(
        lambda q1: FOUR_BAR["g"] * np.array([1.0, 2.0, 3.0]) @ loop_geometry(q1)["centres"][:, 1],
        bounds=(-2.5, -0.8), method="bounded", options={"xatol": 1e-12})
    inertia, _, stiffness = reduced_four_bar(lowest.x)
    crank = next(line for line in output.splitlines() if line.strip().startswith("q1 "))
    assert float(crank.split("=")[1]) == pytest.approx(lowest.x, abs=1e-6)
    mode = next(line for line in output.splitlines() if line.strip().startswith("mode 0:"))
    assert float(mode.split()[2]) == pytest.approx(np.sqrt(stiffness / inertia), rel=1e-6)
    assert main(["equilibrium", "four_bar", "--fix", "q9=1"]) == 2
    assert "unknown coordinate(s) q9" in capsys.readouterr().err


def test_symbolic_linearization_of_a_cartesian_pendulum_matches_the_hand_reduction():
    """One mass on a rod, coordinates x, y, x independent: y = -sqrt(l^2 - x^2) below the pivot,
    so M_r = m (1 + x^2 / y^2) and, at rest (x = 0, lambda = m g / (2 l)), K_r = m g / l."""
    from kronlag.studies.linearization import symbolic_linearization

    x, y = kronlag.coordinates("x y")
    m, l, g = sp.symbols("m l g", positive=True)
    system = kronlag.System([x, y], parameters=[m, l, g], gravity=(0, -g), name="cartesian_pendulum")
    system.add_body(kronlag.PointMass("bob", mass=m, position=(x, y)))
    system.add_constraint(x ** 2 + y ** 2 - l ** 2, name="rod")
    equations = kronlag.derive(system)
    reduced = symbolic_linearization(equations, ["x"])
    assert sp.simplify(reduced["M_r"][0, 0] - m * (1 + x ** 2 / y ** 2)) == 0
    (lam,) = equations.lambdas
    at_rest = {x: 0, y: -l, lam: m * g / (2 * l), **dict.fromkeys(equations.speeds, 0),
               **dict.fromkeys(equations.accelerations, 0)}
    assert sp.simplify(reduced["K_r"].subs(at_rest)[0, 0] - m * g / l) == 0
    assert sp.simplify(reduced["D_r"].subs(at_rest)[0, 0]) == 0


def test_symbolic_linearization_of_the_four_bar_agrees_with_the_numeric_one(four_bar):
    from kronlag.studies.linearization import symbolic_linearization

    equations = four_bar.equations
    reduced = symbolic_linearization(equations, ["q1"])
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    linear = four_bar.linearize(rest.q, independent=["q1"])
    point = {**dict(zip(equations.coordinates, rest.q)), **dict(zip(equations.lambdas, rest.lam)),
             **dict.fromkeys(equations.speeds, 0), **dict.fromkeys(equations.accelerations, 0),
             **{p: four_bar.parameter_values()[p.name] for p in equations.parameters}}
    assert float(reduced["M_r"].subs(point)[0, 0]) == pytest.approx(linear.mass[0, 0], rel=1e-10)
    assert float(reduced["K_r"].subs(point)[0, 0]) == pytest.approx(linear.stiffness[0, 0], rel=1e-9)
    with pytest.raises(ValueError, match="expected 1 distinct names"):
        symbolic_linearization(equations, ["q1", "q2"])


def test_a_point_as_output_moves_with_the_closed_form_geometry(four_bar):
    rest = four_bar.equilibrium([-1.5, -0.5, -1.5])
    eq = four_bar.equations
    q1, q3 = eq.coordinates[0], eq.coordinates[2]
    l3, l4 = (p for p in eq.parameters if p.name in ("l3", "l4"))
    pin_x = l4 + l3 * sp.cos(q3)  # x of the joint C
    linear = four_bar.linearize(rest.q, independent=["q1"], outputs=[pin_x, "q1"])
    geometry = [loop_geometry(rest.q[0] + h) for h in (-1e-6, 1e-6)]
    pin = [FOUR_BAR["l4"] + FOUR_BAR["l3"] * np.cos(g["angles"][2]) for g in geometry]
    assert linear.C[0, 0] == pytest.approx((pin[1] - pin[0]) / 2e-6, rel=1e-6)
    assert linear.outputs == (str(pin_x), "q1")
    with pytest.raises(ValueError, match="only coordinates and parameters"):
        four_bar.linearize(rest.q, outputs=[q1 * eq.speeds[0]])


def test_damping_ratio_of_a_damped_oscillator_on_an_inclined_line():
    """A mass on the line y = x (coordinates x, y), a zero-length spring to the origin and viscous
    damping in both directions: along the line m s'' + c s' + k s = 0."""
    x, y = kronlag.coordinates("x y")
    m, k, c = sp.symbols("m k c", positive=True)
    system = kronlag.System([x, y], parameters=[m, k, c], name="inclined_oscillator")
    system.add_body(kronlag.PointMass("slider", mass=m, position=(x, y)))
    system.add_spring((x, y), (0, 0), stiffness=k)
    system.add_generalized_force([-c * kronlag.speed_symbol(x), -c * kronlag.speed_symbol(y)], name="viscous")
    system.add_constraint(y - x, name="line")
    model = kronlag.derive(system).numeric(dict(m=2.0, k=50.0, c=3.0))
    rest = model.equilibrium([0.1, 0.1])
    np.testing.assert_allclose(rest.q, 0, atol=1e-12)
    linear = model.linearize(rest.q)
    omega, zeta = np.sqrt(50.0 / 2.0), 3.0 / (2 * np.sqrt(50.0 * 2.0))
    np.testing.assert_allclose(linear.natural_frequencies, [omega], rtol=1e-12)
    np.testing.assert_allclose(linear.damping_ratios, [zeta], rtol=1e-12)
    expected_poles = -zeta * omega + np.array([-1j, 1j]) * omega * np.sqrt(1 - zeta ** 2)
    np.testing.assert_allclose(np.sort_complex(linear.eigenvalues), np.sort_complex(expected_poles), rtol=1e-12)


@pytest.mark.slow
def test_cli_animates_a_mode(tmp_path, capsys):
    from kronlag.app.cli import main

    hanging = ["--guess", "q1=-1.5", "--guess", "q2=-0.5", "--guess", "q3=-1.5"]
    assert main(["equilibrium", "four_bar", *hanging, "--animate-mode", str(tmp_path / "mode.txt")]) == 2
    assert "must end in .gif, .mp4 or .html" in capsys.readouterr().err
    assert main(["equilibrium", "four_bar", *hanging, "--animate-mode", str(tmp_path / "mode.gif"), "--mode", "1"]) == 2
    assert "--mode 1: the model has modes 0 to 0" in capsys.readouterr().err
    assert main(["equilibrium", "four_bar", *hanging, "--animate-mode", str(tmp_path / "mode.gif")]) == 0
    assert (tmp_path / "mode.gif").stat().st_size > 10_000
