"""kronlag.simulate against independent references.

The four-bar (Van Khang 2011, Sec. 4.1) has one degree of freedom.  The
reference below is built without kronlag: the closed-form geometry gives
q2(q1), q3(q1) (intersection of the circles about B and D); the kinetic and
potential energies of the three uniform bars written in q1 alone give the
reduced Lagrange equation

    m(q1) q1dd + 1/2 m'(q1) q1d^2 + V'(q1) = tau,   T = 1/2 m(q1) q1d^2,

integrated with solve_ivp (DOP853) at rtol 1e-12.  The multipliers follow from
the crank/coupler/follower equations with the hand-written M, C qd, g and
Phi_q of the paper (method.md) and the reduced accelerations.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest
import sympy as sp
from helpers import derived
from scipy.integrate import solve_ivp

import kronlag
from kronlag.simulation import METHODS

L1, L2, L3, L4 = 0.2, 0.6, 0.5, 0.5
M1, M2, M3 = 1.0, 2.0, 1.5
GRAVITY = 9.81
FOUR_BAR = dict(l1=L1, l2=L2, l3=L3, l4=L4, m1=M1, m2=M2, m3=M3, I1=M1 * L1 ** 2 / 12,
                I2=M2 * L2 ** 2 / 12, I3=M3 * L3 ** 2 / 12, g=GRAVITY)
Q1_START = 0.3
T_END = 3.0
T_EVAL = np.linspace(0.0, T_END, 31)

#: Accuracy of q1 (rad) against the reduced reference and constraint drift bounds, per method.
Q1_TOLERANCE = {"baumgarte": 1e-6, "projection": 1e-6, "compiled": 1e-5, "dop853": 1e-6, "ggl": 1e-4,
                "ali3p": 1e-5, "switching": 1e-5}
POSITION_DRIFT = {"baumgarte": 1e-8, "projection": 1e-11, "compiled": 1e-11, "dop853": 1e-11, "ggl": 1e-9,
                  "ali3p": 1e-11, "switching": 1e-11}
VELOCITY_DRIFT = {"baumgarte": 1e-7, "projection": 1e-12, "compiled": 1e-12, "dop853": 1e-12, "ggl": 1e-7,
                  "ali3p": 1e-11, "switching": 1e-12}


@functools.cache
def four_bar_model(tau: float = 0.0, backend: str = "c") -> kronlag.NumericModel:
    return derived("four_bar").numeric({**FOUR_BAR, "tau": tau}, backend=backend)


@functools.cache
def reduced_four_bar():
    """``(geometry, mass, mass_slope, potential_slope)``: numeric functions of q1 from the
    closed-form four-bar (elbow of the initial assembly)."""
    q1 = sp.Symbol("q1")
    bx, by = L1 * sp.cos(q1), L1 * sp.sin(q1)
    ex, ey = L4 - bx, -by
    d2 = ex ** 2 + ey ** 2
    a = (L2 ** 2 - L3 ** 2 + d2) / (2 * d2)          # along BD, divided by |BD|
    h = sp.sqrt(L2 ** 2 / d2 - a ** 2)               # across BD, divided by |BD|
    cx, cy = bx + a * ex - h * ey, by + a * ey + h * ex
    q2 = sp.atan2(cy - by, cx - bx)
    q3 = sp.atan2(cy, cx - L4)
    angles = [q1, q2, q3]
    centres = [(bx / 2, by / 2), ((bx + cx) / 2, (by + cy) / 2), ((L4 + cx) / 2, cy / 2)]
    masses, lengths = [M1, M2, M3], [L1, L2, L3]
    # T = 1/2 mass(q1) q1d^2 with velocities d/dt = q1d d/dq1.
    mass = sum(mi * (sp.diff(x, q1) ** 2 + sp.diff(y, q1) ** 2) + mi * li ** 2 / 12 * sp.diff(angle, q1) ** 2
               for mi, li, (x, y), angle in zip(masses, lengths, centres, angles))
    potential = GRAVITY * sum(mi * y for mi, (x, y) in zip(masses, centres))
    slopes = [sp.diff(angle, q1) for angle in angles]
    curvatures = [sp.diff(slope, q1) for slope in slopes]
    geometry = sp.lambdify(q1, [angles, slopes, curvatures], cse=True)
    functions = [sp.lambdify(q1, expr, cse=True) for expr in (mass, sp.diff(mass, q1), sp.diff(potential, q1))]
    return (geometry, *functions)


@functools.cache
def reference(tau: float = 0.0):
    """Dense solution ``(q1, q1d)`` of the reduced equation from rest at ``Q1_START``."""
    _, mass, mass_slope, potential_slope = reduced_four_bar()

    def rhs(t, y):
        q1, q1d = y
        return [q1d, (tau - 0.5 * mass_slope(q1) * q1d ** 2 - potential_slope(q1)) / mass(q1)]

    solution = solve_ivp(rhs, (0.0, T_END), [Q1_START, 0.0], method="DOP853", rtol=1e-12, atol=1e-12,
                         t_eval=T_EVAL)
    assert solution.success
    return solution, rhs


def full_state(q1: float, q1d: float, q1dd: float):
    """``q, qd, qdd`` (3,) of the four-bar from the reduced state."""
    geometry = reduced_four_bar()[0]
    angles, slopes, curvatures = (np.array(x, dtype=float) for x in geometry(q1))
    return angles, slopes * q1d, slopes * q1dd + curvatures * q1d ** 2


def reference_multipliers(q, qd, qdd, tau: float) -> np.ndarray:
    """``lambda`` from the crank/coupler/follower equations ``M qdd + C qd + g + Phi_q^T lam = f_Q``,
    with M, C qd, g, Phi_q written out as in the paper (corrected Eq. 29-31)."""
    q1, q2, q3 = q
    c, s, a = np.cos(q1 - q2), np.sin(q1 - q2), M2 * L1 * L2
    I1, I2, I3 = (FOUR_BAR[f"I{i}"] for i in (1, 2, 3))
    mass = np.array([[I1 + M1 * L1 ** 2 / 4 + M2 * L1 ** 2, a * c / 2, 0],
                     [a * c / 2, I2 + M2 * L2 ** 2 / 4, 0],
                     [0, 0, I3 + M3 * L3 ** 2 / 4]])
    velocity_terms = a * s / 2 * np.array([qd[1] ** 2, -qd[0] ** 2, 0])
    gravity = GRAVITY * np.array([(M1 / 2 + M2) * L1 * np.cos(q1), M2 * L2 * np.cos(q2) / 2,
                                  M3 * L3 * np.cos(q3) / 2])
    jacobian = np.array([[-L1 * np.sin(q1), -L2 * np.sin(q2), L3 * np.sin(q3)],
                         [L1 * np.cos(q1), L2 * np.cos(q2), -L3 * np.cos(q3)]])
    rest = np.array([tau, 0, 0]) - mass @ qdd - velocity_terms - gravity
    return np.linalg.lstsq(jacobian.T, rest, rcond=None)[0]


def initial_state() -> tuple[np.ndarray, np.ndarray]:
    """The four-bar at rest at ``q1 = Q1_START`` (from the closed-form geometry)."""
    return full_state(Q1_START, 0.0, 0.0)[0], np.zeros(3)


@functools.cache
def four_bar_run(method: str, tau: float = 0.0) -> kronlag.Trajectory:
    model = four_bar_model(tau)
    q0, qd0 = initial_state()
    return kronlag.simulate(model, (0.0, T_END), q0, qd0, method=method, t_eval=T_EVAL)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_four_bar_follows_reduced_equation(method):
    trajectory = four_bar_run(method, 0.5)
    solution, _ = reference(0.5)
    assert trajectory.success, trajectory.message
    np.testing.assert_allclose(trajectory.t, T_EVAL)
    np.testing.assert_allclose(trajectory.q[:, 0], solution.y[0], atol=Q1_TOLERANCE[method], rtol=0)
    np.testing.assert_allclose(trajectory.qd[:, 0], solution.y[1], atol=20 * Q1_TOLERANCE[method], rtol=0)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_four_bar_constraint_drift(method):
    trajectory = four_bar_run(method, 0.5)
    assert np.max(np.abs(trajectory.position_residual)) <= POSITION_DRIFT[method]
    assert np.max(np.abs(trajectory.velocity_residual)) <= VELOCITY_DRIFT[method]


def test_four_bar_multipliers_match_reduced_solution():
    tau = 0.5
    trajectory = four_bar_run("projection", tau)
    solution, rhs = reference(tau)
    for k in range(0, len(T_EVAL), 5):
        q1, q1d = solution.y[:, k]
        q, qd, qdd = full_state(q1, q1d, rhs(0.0, [q1, q1d])[1])
        np.testing.assert_allclose(trajectory.q[k], q, atol=1e-6)
        np.testing.assert_allclose(trajectory.qdd[k], qdd, atol=1e-4)
        np.testing.assert_allclose(trajectory.lam[k], reference_multipliers(q, qd, qdd, tau), rtol=1e-5,
                                   atol=1e-5)


def test_methods_agree():
    runs = [four_bar_run(method, 0.5) for method in sorted(METHODS)]
    for run in runs[1:]:
        np.testing.assert_allclose(run.q, runs[0].q, atol=2e-4)
        np.testing.assert_allclose(run.lam, runs[0].lam, rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("method", ["projection", "compiled"])
def test_four_bar_conserves_energy(method):
    energy = four_bar_run(method, 0.0).total_energy
    assert np.ptp(energy) <= 1e-6 * abs(energy[0])


@pytest.mark.parametrize("name, parameters, q0, qd0", [
    ("double_pendulum", dict(l1=1.0, l2=0.7, m1=1.0, m2=0.5, I1=1 / 12, I2=0.5 * 0.49 / 12, g=9.81),
     [1.0, -0.5], [0.0, 2.0]),
    ("heavy_top", dict(m=1.0, l=0.1, g=9.81, Ixx=0.01, Izz=0.02), [0.0, 0.4, 0.0], [0.5, 0.0, 40.0]),
])
def test_conservative_models_conserve_energy(name, parameters, q0, qd0):
    model = derived(name).numeric(parameters, backend="c")
    for method in ("compiled", "projection"):
        trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method, t_eval=np.linspace(0, 2, 21))
        assert trajectory.success, trajectory.message
        energy = trajectory.total_energy
        assert np.ptp(energy) <= 1e-6 * np.max(np.abs(trajectory.kinetic_energy)), method


@pytest.mark.parametrize("method", ["compiled", "dop853", "projection", "baumgarte", "ggl"])
def test_chaplygin_sleigh_keeps_its_blade(method):
    model = derived("chaplygin_sleigh").numeric(dict(m=2.0, I=0.1, a=0.3), backend="c")
    q0 = [0.0, 0.0, 0.0]
    qd0 = model.assemble(q0, qd_guess=[1.0, 0.0, 2.0], qd_fixed={"x": 1.0, "theta": 2.0})[1]
    trajectory = kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method, t_eval=np.linspace(0, 2, 21))
    assert trajectory.success, trajectory.message
    assert trajectory.mu.shape == (21, 1) and trajectory.velocity_residual.shape == (21, 1)
    bound = 1e-7 if method in ("baumgarte", "ggl") else 1e-12
    assert np.max(np.abs(trajectory.velocity_residual)) <= bound
    # No friction, no forces: the energy is conserved.
    assert np.ptp(trajectory.kinetic_energy) <= 1e-6 * trajectory.kinetic_energy[0]


@pytest.mark.parametrize("method", sorted(METHODS))
def test_step_limit_returns_partial_trajectory(method):
    model = four_bar_model(0.5)
    q0, qd0 = initial_state()
    trajectory = kronlag.simulate(model, (0.0, 100.0), q0, qd0, method=method, max_steps=20)
    assert trajectory.status == -1 and not trajectory.success
    assert "maximum number of steps" in trajectory.message or "TOO_MUCH_WORK" in trajectory.message
    assert 1 < len(trajectory.t) <= 21 and trajectory.t[-1] < 100.0
    assert trajectory.q.shape == (len(trajectory.t), 3) and np.all(np.isfinite(trajectory.q))


@pytest.mark.parametrize("method", sorted(METHODS))
def test_singular_configuration_returns_partial_trajectory(method):
    # Massless links: M vanishes, the accelerations are undetermined from the start.
    parameters = {**FOUR_BAR, **{name: 0.0 for name in ("m1", "m2", "m3", "I1", "I2", "I3")}, "tau": 0.0}
    model = derived("four_bar").numeric(parameters, backend="c")
    q0, qd0 = initial_state()
    trajectory = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method=method)
    assert trajectory.status == -1
    assert len(trajectory.t) >= 1 and trajectory.t[0] == 0.0
    np.testing.assert_allclose(trajectory.q[0], q0, atol=1e-12)


def test_auto_is_switching_and_outputs_every_step():
    model = four_bar_model(0.5)
    q0, qd0 = initial_state()
    trajectory = kronlag.simulate(model, (0.0, 1.0), q0, qd0)
    assert trajectory.method == "switching" and trajectory.success
    assert trajectory.t[0] == 0.0 and trajectory.t[-1] == 1.0 and len(trajectory.t) == trajectory.steps + 1
    assert np.all(np.diff(trajectory.t) > 0)


@pytest.mark.parametrize("method", ["compiled", "switching"])
def test_every_step_outputs_are_those_at_the_same_output_times(method):
    # With outputs at every step the driver evaluates the constraints at the accepted state once, for
    # the singularity watch and the output's projection; the outputs at those times asked for by
    # t_eval are projected from scratch: the same states, accelerations, energies and residuals.
    model = four_bar_model(0.5)
    q0, qd0 = initial_state()
    every = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method=method)
    again = kronlag.simulate(model, (0.0, 1.0), q0, qd0, method=method, t_eval=every.t)
    assert every.success and again.success and every.steps == again.steps
    for name in ("q", "qd", "qdd", "lam", "kinetic_energy", "potential_energy", "position_residual",
                 "velocity_residual"):
        np.testing.assert_allclose(getattr(every, name), getattr(again, name), rtol=0, atol=1e-12, err_msg=name)
    assert np.abs(every.position_residual).max() < POSITION_DRIFT[method]
    assert np.abs(every.velocity_residual).max() < VELOCITY_DRIFT[method]


def test_numpy_backend_uses_python_methods():
    with pytest.warns(DeprecationWarning, match="backend='numpy' is deprecated, use backend='python'"):
        model = four_bar_model(0.5, backend="numpy")
    q0, qd0 = initial_state()
    trajectory = kronlag.simulate(model, (0.0, T_END), q0, qd0, t_eval=T_EVAL)
    assert trajectory.method == "projection"
    np.testing.assert_allclose(trajectory.q, four_bar_run("projection", 0.5).q, atol=1e-9)
    with pytest.raises(ValueError, match="compiled"):
        kronlag.simulate(model, (0.0, 1.0), q0, qd0, method="compiled")


def test_progress_is_reported():
    model = four_bar_model(0.5)
    q0, qd0 = initial_state()
    for method in ("compiled", "projection"):
        times = []
        kronlag.simulate(model, (0.0, 0.5), q0, qd0, method=method, progress=times.append)
        assert times and times[-1] == 0.5 and np.all(np.diff(times) > 0)


def test_bad_arguments():
    model = four_bar_model(0.5)
    q0, qd0 = initial_state()
    with pytest.raises(ValueError, match="unknown method"):
        kronlag.simulate(model, (0, 1), q0, qd0, method="rk4")
    with pytest.raises(ValueError, match="t_span"):
        kronlag.simulate(model, (1, 0), q0, qd0)
    with pytest.raises(ValueError, match="t_eval"):
        kronlag.simulate(model, (0, 1), q0, qd0, t_eval=[0.5, 0.2])
    with pytest.raises(ValueError, match="3 entries"):
        kronlag.simulate(model, (0, 1), q0[:2], qd0)


def test_trajectory_exports(tmp_path):
    trajectory = four_bar_run("compiled", 0.5)
    columns = trajectory.columns()
    expected = (["t", "q1", "q2", "q3", "q1d", "q2d", "q3d", "q1dd", "q2dd", "q3dd", "lambda[loop x]", "lambda[loop y]",
                 "kinetic_energy", "potential_energy", "position_residual1", "position_residual2",
                 "velocity_residual1", "velocity_residual2"])
    assert list(columns) == expected
    trajectory.to_csv(tmp_path / "run.csv")
    assert (tmp_path / "run.csv").read_text().splitlines()[0].split(",") == expected
    table = np.loadtxt(tmp_path / "run.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, expected.index("q2")], trajectory.q[:, 1])
    trajectory.to_npz(tmp_path / "run.npz")
    with np.load(tmp_path / "run.npz") as archive:
        np.testing.assert_array_equal(archive["lambda[loop y]"], trajectory.lam[:, 1])
        assert str(archive["method"]) == "compiled" and int(archive["status"]) == 0
    pandas = pytest.importorskip("pandas")
    frame = trajectory.to_dataframe()
    assert isinstance(frame, pandas.DataFrame) and list(frame.columns) == expected
    assert trajectory.success and len(trajectory) == len(T_EVAL)


def test_time_varying_parameter_runs_in_python():
    model = derived("four_bar").numeric({**FOUR_BAR, "tau": lambda t: 0.5}, backend="c")
    q0, qd0 = initial_state()
    trajectory = kronlag.simulate(model, (0.0, T_END), q0, qd0, t_eval=T_EVAL)
    assert model.time_varying and trajectory.method == "projection"
    np.testing.assert_allclose(trajectory.q, four_bar_run("projection", 0.5).q, atol=1e-12)


def test_plot_delegates_to_plotting():
    import matplotlib

    matplotlib.use("Agg")
    figure = four_bar_run("compiled", 0.5).plot()
    assert isinstance(figure, matplotlib.figure.Figure)


@pytest.mark.parametrize("method", ["baumgarte", "projection", "compiled", "dop853"])
def test_redundant_constraints_give_the_same_motion(method):
    """A third loop equation (loop x + 2 loop y) makes Phi_q rank-deficient: same motion."""
    system = kronlag.models.four_bar()
    l1, l2, l3, l4 = sp.symbols("l1 l2 l3 l4")
    q1, q2, q3 = system.coordinates
    system.add_constraint(l1 * sp.cos(q1) + l2 * sp.cos(q2) - l3 * sp.cos(q3) - l4
                          + 2 * (l1 * sp.sin(q1) + l2 * sp.sin(q2) - l3 * sp.sin(q3)), name="redundant")
    redundant = kronlag.derive(system).numeric({**FOUR_BAR, "tau": 0.5})
    plain = four_bar_model(tau=0.5)
    q0, qd0 = plain.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 2.0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", kronlag.RedundantConstraintsWarning)
        assert not redundant.forward_dynamics(q0, qd0).unique_multipliers
        reference = kronlag.simulate(plain, (0.0, 1.0), q0, qd0, method=method, t_eval=T_EVAL[:11])
        trajectory = kronlag.simulate(redundant, (0.0, 1.0), q0, qd0, method=method, t_eval=T_EVAL[:11])
    assert trajectory.success, trajectory.message
    np.testing.assert_allclose(trajectory.q, reference.q, atol=1e-7)
    assert np.max(np.abs(trajectory.position_residual)) < 1e-9
