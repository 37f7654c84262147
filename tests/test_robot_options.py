"""Robot files' options through ``kronlag.load_model`` and the command line (issue 21):
``floating_base=True`` / ``--floating-base`` and ``coordinates="absolute"`` / ``--coordinates absolute``,
refused in one line where they do not apply."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

import kronlag
from kronlag.app.cli import main
from kronlag.core.errors import InputError
from kronlag.model.robot_formats import RobotFileWarning, load_robot

PENDULUM = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base"><inertial><mass value="2.0"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
  </inertial></link>
  <link name="arm"><inertial><origin xyz="0 0 -0.5"/><mass value="1.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="5" velocity="3"/></joint>
</robot>
"""


@pytest.fixture
def pendulum(tmp_path):
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM)
    return path


def test_load_model_passes_the_robot_options(pendulum):
    """``floating_base=True``: the base floats on 'root_joint' (7 coordinates, the normalization, e0 = 1
    in the assembly guess); ``coordinates="absolute"``: the arm's 7 body coordinates and the hinge's rows."""
    fixed = kronlag.load_model(pendulum)
    assert [q.name for q in fixed.system.coordinates] == ["hinge"]
    floating = kronlag.load_model(pendulum, floating_base=True)
    names = [q.name for q in floating.system.coordinates]
    assert names == [f"root_joint_{s}" for s in ("x", "y", "z", "e0", "e1", "e2", "e3")] + ["hinge"]
    assert [c.name for c in floating.system.constraints] == ["root_joint.normalization"]
    assert float(floating.q_guess["root_joint_e0"]) == 1.0
    absolute = kronlag.load_model(pendulum, coordinates="absolute")
    assert len(absolute.system.coordinates) == 7
    assert [c.name for c in absolute.system.constraints][1:] == ["hinge.x", "hinge.y", "hinge.z", "hinge.axis1",
                                                                  "hinge.axis2"]


def test_robot_options_are_refused_where_they_do_not_apply(tmp_path):
    """A TOML model file takes neither option; an SDF or MJCF file says itself whether it floats."""
    with pytest.raises(InputError, match=r"four_bar\.toml: coordinates= and floating_base= apply to robot files"):
        kronlag.load_model(kronlag.model.builtin.example_path("four_bar"), floating_base=True)
    sdf = tmp_path / "m.sdf"
    sdf.write_text('<sdf version="1.7"><model name="m"><link name="a"/></model></sdf>')
    with pytest.raises(InputError, match=r"m\.sdf: floating_base applies to URDF files only"):
        load_robot(sdf, floating_base=True)


def test_cli_floating_base_and_coordinates(pendulum, capsys):
    """``kronlag check pendulum.urdf --floating-base`` reports the floating joint's coordinates and its
    normalization; ``--coordinates absolute`` the hinge's rows; a built-in model refuses both."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        assert main(["check", str(pendulum), "--floating-base"]) == 0
        out = capsys.readouterr().out
        assert "2 bodies, 8 coordinates, 1 holonomic" in out and "root_joint.normalization" in out
        assert main(["check", str(pendulum), "--coordinates", "absolute"]) == 0
        assert "hinge.axis2" in capsys.readouterr().out
    assert main(["check", "four_bar", "--floating-base"]) != 0
    assert "--coordinates and --floating-base apply to robot files" in capsys.readouterr().err


def test_constraint_ranks_group_rows_and_name_the_dependent_ones():
    """Rows grouped by the name before their last dot, each group's rank, and the row the pivoted QR
    of Phi_q^T takes last when one depends on the others (as the solver does)."""
    import numpy as np

    from kronlag.studies.constraint_groups import ConstraintGroup, constraint_ranks

    names = ["a.x", "a.y", "b.x", "lone"]
    jacobian = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 0, 0], [0, 0, 2.0]])
    groups, dependent = constraint_ranks(names, jacobian, 1e-8)
    assert groups == (ConstraintGroup("a", ("a.x", "a.y"), 2), ConstraintGroup("b", ("b.x",), 1),
                      ConstraintGroup("lone", ("lone",), 1))
    assert dependent == ("b.x",)


def test_check_reports_each_loop_and_its_rank(tmp_path, capsys):
    """An SDF four-bar closed twice (a revolute loop joint and a redundant ball at the same point):
    ``describe`` names each loop joint with its rows and frame, ``kronlag check`` each loop's rank at
    the assembled state and the dependent rows by name."""
    text = (Path(__file__).resolve().parent / "robot_files" / "four_bar.sdf").read_text()
    loop_start = text.index('<joint name="loop"')
    loop = text[loop_start:text.index("</joint>", loop_start) + len("</joint>")]
    twice = loop.replace('name="loop" type="revolute"', 'name="again" type="ball"')
    path = tmp_path / "twice.sdf"
    path.write_text(text.replace(loop, loop + twice))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_sdf(path)
        assert [(c.joint, c.kind, c.rows) for c in system.robot.loops] == [
            ("loop", "revolute", ("loop.x", "loop.z")), ("again", "ball", ("again.x", "again.z"))]
        assert "loop closed by again (ball, coupler to follower): rows .x .z (components in the frame of world), " \
               ".y dropped (identically zero)" in system.describe()
        assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "rank of each joint's or loop's rows at the assembled state: loop 2 of 2; again 2 of 2" in out
    assert "rows dependent on the others at the assembled state (redundant): again.x, again.z" in out


NONPHYSICAL = """<?xml version="1.0"?>
<robot name="rod">
  <link name="base"/>
  <link name="rod"><inertial><mass value="1.0"/>
    <inertia ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"/></inertial></link>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="rod"/><axis xyz="0 1 0"/></joint>
</robot>
"""


def test_nonphysical_inertia_is_refused_unless_allowed(tmp_path):
    """A tensor whose principal moments violate the triangle inequality (example-robot-data's Go1
    placeholder, all six entries 1e-6): refused in one located line; ``allow_nonphysical_inertia=True``
    keeps it with a warning naming the link, and the numeric model, which checks the bodies again,
    refuses the body that is still not physical."""
    from kronlag.core.errors import ModelError, ModelFileError

    path = tmp_path / "rod.urdf"
    path.write_text(NONPHYSICAL)
    with pytest.raises(ModelFileError, match=r"rod\.urdf:4: <link name='rod'>: <inertial>: .*triangle inequality"):
        kronlag.load_urdf(path)
    with pytest.warns(RobotFileWarning, match=r"rod\.urdf:4: <link name='rod'>: .*triangle inequality.*\(kept: "
                                              r"allow_nonphysical_inertia=True\)"):
        system = kronlag.load_urdf(path, allow_nonphysical_inertia=True)
    with pytest.raises(ModelError, match=r"body 'rod': the principal moments .* triangle inequality"):
        kronlag.derive(system).numeric(system.robot.values, backend="python")


@pytest.mark.slow
def test_go1_with_its_placeholder_inertial_agrees_with_pinocchio(monkeypatch):
    """Go1 as shipped: its massless 'base' link's placeholder tensor is kept (a warning), merged by the
    fixed joint into the trunk, whose body is physical; M, g, C qd and the accelerations agree with
    Pinocchio's free flyer to <= 1e-9 (bench_robots.compare_floating)."""
    import numpy as np

    pytest.importorskip("pinocchio")
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    import bench_robots

    folder = bench_robots.robots_folder()
    if folder is None:
        pytest.skip("example-robot-data is not installed")
    path = folder / "go1_description/urdf/go1.urdf"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        system = kronlag.load_urdf(path, floating_base=True, allow_nonphysical_inertia=True)
    assert [str(w.message).split(": ")[1] for w in caught if "triangle" in str(w.message)] == ["<link name='base'>"]
    rng = np.random.default_rng(5)
    values = {**system.robot.values, **{joint.torque: rng.uniform(-1, 1) for joint in system.robot.joints
                                        if joint.torque}}
    model = kronlag.derive(system).numeric(values, backend="python")
    worst = bench_robots.compare_floating(path, system, model, values, states=3)
    assert max(worst.values()) <= 1e-9, worst


def test_angles_written_to_twelve_digits_are_the_multiples_of_pi_over_2_they_mean():
    """kinova.urdf writes pi as 3.14159265359 (2.1e-13 off): taken as pi, its sines vanish exactly and
    the kernel loses 3.5x of its operations; a coarse 1.5708 (3.7e-6 off pi/2) is taken as written."""
    import sympy as sp

    from kronlag.model.robot_formats.tree import exact_angle

    assert exact_angle(3.14159265359) == sp.pi
    assert exact_angle(-1.57079632679) == -sp.pi / 2
    assert exact_angle(4.71238898038) == 3 * sp.pi / 2
    assert exact_angle(1.5708) == sp.Float(1.5708)
    assert exact_angle(3.1415926535) == sp.Float(3.1415926535)  # 10 digits, 9e-11 off: as written
