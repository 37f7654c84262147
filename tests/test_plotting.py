"""kronlag.plotting: the time-history figure of a trajectory."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import four_bar_trajectory, heavy_top_trajectory
from PIL import Image

import kronlag
from kronlag.studies.drives import InverseDynamicsRun
from kronlag.views.plotting import plot_inverse_dynamics, plot_trajectory

CONSTRAINED_PANELS = ["Coordinates", "Velocities", "Lagrange multipliers", "Constraint drift", "Energy",
                      "Total-energy drift"]


@pytest.fixture(scope="module")
def four_bar():
    return four_bar_trajectory(np.linspace(0.0, 1.0, 101))


def _titles(figure) -> list[str]:
    return [axes.get_title() for axes in figure.axes]


def _legend_labels(axes) -> list[str]:
    return [text.get_text() for text in axes.get_legend().get_texts()]


def test_png_is_written_and_shows_the_curves(four_bar, tmp_path):
    path = tmp_path / "plot.png"
    figure = four_bar.plot(path=path)  # Trajectory.plot delegates to plot_trajectory
    image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    width, height = figure.get_size_inches() * figure.dpi
    assert image.shape == (round(height), round(width), 3)
    ink = (image < 200).any(axis=-1)
    assert 0.02 < ink.mean() < 0.5
    tab_blue = np.array([31, 119, 180])  # the first line of every panel
    assert (np.abs(image - tab_blue).sum(axis=-1) < 30).sum() > 500


def test_panels_are_titled_labelled_and_not_empty(four_bar):
    figure = plot_trajectory(four_bar)
    assert _titles(figure) == CONSTRAINED_PANELS
    panels = dict(zip(CONSTRAINED_PANELS, figure.axes))
    assert _legend_labels(panels["Coordinates"]) == ["$q_{1}$", "$q_{2}$", "$q_{3}$"]
    assert _legend_labels(panels["Velocities"]) == [r"$\dot{q}_{1}$", r"$\dot{q}_{2}$", r"$\dot{q}_{3}$"]
    assert _legend_labels(panels["Lagrange multipliers"]) == ["lambda[loop x]", "lambda[loop y]"]
    assert panels["Constraint drift"].get_yscale() == "log"
    for axes in figure.axes:
        assert axes.lines and axes.get_ylabel()
    assert [axes.get_xlabel() for axes in figure.axes[-2:]] == ["time $t$"] * 2
    assert "four_bar" in figure.get_suptitle()
    drift = panels["Total-energy drift"].lines[0].get_ydata()
    total = four_bar.kinetic_energy + four_bar.potential_energy
    np.testing.assert_allclose(drift, total - total[0])


def test_unconstrained_model_has_no_multiplier_or_drift_panels():
    figure = plot_trajectory(heavy_top_trajectory(np.linspace(0.0, 1.0, 21)))
    assert _titles(figure) == ["Coordinates", "Velocities", "Energy", "Total-energy drift"]
    assert _legend_labels(figure.axes[0]) == [r"$\psi$", r"$\theta$", r"$\phi$"]


def test_failed_run_and_exact_constraints_are_reported(four_bar):
    failed = dataclasses.replace(four_bar, result=kronlag.Result.SOLVER_FAILED, message="step size too small",
                                 position_residual=np.zeros_like(four_bar.position_residual),
                                 velocity_residual=np.zeros_like(four_bar.velocity_residual))
    figure = plot_trajectory(failed)
    assert "FAILED: step size too small" in figure.get_suptitle()
    drift = figure.axes[CONSTRAINED_PANELS.index("Constraint drift")]
    assert not drift.lines
    assert [text.get_text() for text in drift.texts] == ["constraints satisfied exactly"]


@pytest.mark.parametrize(("suffix", "magic"), [(".pdf", b"%PDF"), (".svg", b"<?xml")])
def test_format_follows_the_extension(suffix, magic, tmp_path):
    path = tmp_path / f"plot{suffix}"
    plot_trajectory(heavy_top_trajectory(np.linspace(0.0, 1.0, 11)), path=path)
    assert path.read_bytes().startswith(magic)


def test_show_uses_pyplot(four_bar, monkeypatch):
    import matplotlib.pyplot as plt

    shown = []
    monkeypatch.setattr(plt, "show", lambda: shown.append(True))
    figure = plot_trajectory(four_bar, show=True)
    try:
        assert shown == [True]
        assert plt.fignum_exists(figure.number)
    finally:
        plt.close(figure)


def test_labels_carry_the_units_given_and_no_others(four_bar):
    figure = plot_trajectory(four_bar, units={"q1": "rad", "q3": "rad", "t": "s", "energy": "J"})
    panels = dict(zip(CONSTRAINED_PANELS, figure.axes))
    assert _legend_labels(panels["Coordinates"]) == ["$q_{1}$ (rad)", "$q_{2}$", "$q_{3}$ (rad)"]
    assert _legend_labels(panels["Velocities"]) == [r"$\dot{q}_{1}$ (rad/s)", r"$\dot{q}_{2}$",
                                                    r"$\dot{q}_{3}$ (rad/s)"]
    assert panels["Energy"].get_ylabel() == "energy (J)"
    assert [axes.get_xlabel() for axes in figure.axes[-2:]] == ["time $t$ (s)"] * 2


def test_inverse_dynamics_figure():
    t = np.linspace(0.0, 1.0, 11)
    q = np.column_stack([t, 2 * t])
    run = InverseDynamicsRun(actuated=("a",), coordinate_names=("a", "x"), t=t, q=q, qd=np.ones_like(q),
                             qdd=np.zeros_like(q), forces=np.sin(t)[:, None], lam=np.cos(t)[:, None],
                             mu=np.zeros((11, 0)))
    figure = plot_inverse_dynamics(run, units={"a": "rad", "t": "s", "energy": "J"})
    assert _titles(figure) == ["Coordinates", "Actuator forces", "Lagrange multipliers"]
    assert _legend_labels(figure.axes[1]) == ["on $a$ (N*m)"]
    np.testing.assert_array_equal(figure.axes[1].lines[0].get_ydata(), np.sin(t))
    np.testing.assert_array_equal(figure.axes[0].lines[0].get_ydata(), t)
    assert figure.axes[-1].get_xlabel() == "time $t$ (s)"


@pytest.fixture(scope="module")
def engine():
    """The slider-crank engine (bodies + four named joints) over a few milliseconds."""
    import kronlag
    from kronlag.model.builtin import load_example

    engine = load_example("slider_crank_engine", apply_drives=False)
    model = kronlag.derive(engine.system).numeric(engine.numeric_values(), backend="python")
    q_guess, qd_guess = engine.guess_vectors()
    q0, qd0 = model.assemble(q_guess, fixed={"theta_crank": 0.0}, qd_guess=qd_guess, qd_fixed={"theta_crank": 157.0})
    return kronlag.simulate(model, (0, 0.005), q0, qd0, method="projection", t_eval=np.linspace(0, 0.005, 11))


ENGINE_JOINTS = ["main_bearing", "crank_pin", "wrist_pin", "cylinder"]


def test_joint_reactions_have_a_panel_each_and_couples_share_one(engine):
    figure = engine.plot(units={"t": "s", "energy": "J"})
    titles = _titles(figure)
    assert titles[:6] == CONSTRAINED_PANELS
    assert titles[6:] == ["main_bearing: force of ground on crank", "crank_pin: force of crank on rod",
                          "wrist_pin: force of rod on piston", "cylinder: force of ground on piston",
                          "Joint couples (on body B)"]
    panels = dict(zip(titles, figure.axes))
    main = panels["main_bearing: force of ground on crank"]
    assert _legend_labels(main) == ["$F_x$", "$F_y$", "$|F|$"]
    assert main.get_ylabel() == "force (N)"
    force = engine.reaction("main_bearing").force
    np.testing.assert_array_equal(main.lines[0].get_ydata(), force[:, 0])
    np.testing.assert_allclose(main.lines[2].get_ydata(), np.hypot(force[:, 0], force[:, 1]))
    # revolute joints in the plane transmit no couple: only the prismatic cylinder has one
    couples = panels["Joint couples (on body B)"]
    assert _legend_labels(couples) == ["cylinder $M_z$"] and couples.get_ylabel() == "couple (N*m)"
    # 11 panels on a 6 x 2 grid: the empty cell is removed, the lowest axes of each column carry the time
    assert len(figure.axes) == 11
    assert [axes.get_xlabel() for axes in (figure.axes[-1], figure.axes[-2])] == ["time $t$ (s)"] * 2


def test_reactions_are_selected_by_joint_name(engine):
    assert len(plot_trajectory(engine, reactions=False).axes) == 6
    assert _titles(plot_trajectory(engine, reactions=["crank_pin"]))[6:] == ["crank_pin: force of crank on rod"]
    assert len(plot_trajectory(engine, reactions=True).axes) == 11
    with pytest.raises(ValueError, match=r"no joint named 'crank' in slider_crank_engine \(joints: main_bearing, "):
        plot_trajectory(engine, reactions=["crank"])
    with pytest.raises(TypeError, match=r"write \['cylinder'\]"):
        plot_trajectory(engine, reactions="cylinder")


def test_reactions_true_needs_joints(four_bar):
    with pytest.raises(ValueError, match="four_bar has no joints"):
        plot_trajectory(four_bar, reactions=True)
    assert len(plot_trajectory(four_bar).axes) == 6


def test_inverse_dynamics_figure_shows_the_joint_forces():
    t = np.linspace(0.0, 1.0, 11)
    q = np.column_stack([t, 2 * t])
    run = InverseDynamicsRun(actuated=("a",), coordinate_names=("a", "x"), t=t, q=q, qd=np.ones_like(q),
                             qdd=np.zeros_like(q), forces=np.sin(t)[:, None], lam=np.cos(t)[:, None],
                             mu=np.zeros((11, 0)),
                             reactions={"pin.Fx": 3 * t, "pin.Fy": 4 * t, "pin.Mz": 0 * t})
    figure = plot_inverse_dynamics(run, units={"a": "rad", "t": "s", "energy": "J"})
    assert _titles(figure)[-1] == "Joint reaction forces"
    assert _legend_labels(figure.axes[-1]) == ["pin"] and figure.axes[-1].get_ylabel() == "$|F|$ (N)"
    np.testing.assert_allclose(figure.axes[-1].lines[0].get_ydata(), 5 * t)


def test_kinematics_figure():
    from kronlag.studies.drives import Kinematics
    from kronlag.views.plotting import plot_kinematics

    t = np.linspace(0.0, 1.0, 11)
    q = np.column_stack([t, 2 * t])
    point = {"position": np.column_stack([np.cos(t), np.sin(t)]), "velocity": np.zeros((11, 2)),
             "acceleration": np.zeros((11, 2))}
    run = Kinematics(t, q, np.ones_like(q), np.zeros_like(q), ("a", "x"), {"P": point})
    figure = plot_kinematics(run, units={"a": "rad", "x": "m", "t": "s"})
    assert _titles(figure) == ["Coordinates", "Speeds", "Accelerations", "Points"]
    assert _legend_labels(figure.axes[2]) == [r"$\ddot{a}$ (rad/s^2)", r"$\ddot{x}$ (m/s^2)"]
    assert _legend_labels(figure.axes[3]) == ["P x", "P y"]
    np.testing.assert_array_equal(figure.axes[3].lines[1].get_ydata(), np.sin(t))
