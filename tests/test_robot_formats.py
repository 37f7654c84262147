"""Robot files (issue 21): the hardened XML layer, the URDF reader's bad-input messages, its mechanics
against hand values, load_model / CLI dispatch, and agreement with Pinocchio on example-robot-data's
arms (skipped without pin and example-robot-data)."""

from __future__ import annotations

import importlib.util
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import kronlag
from kronlag.core.errors import ModelFileError
from kronlag.model.robot_formats import RobotFileWarning

BENCH = Path(__file__).resolve().parents[1] / "bench" / "bench_robots.py"

LINK = """  <link name="{name}">
    <inertial><origin xyz="{cx} 0 0" rpy="0 0 0"/><mass value="{mass}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>
  </link>
"""
JOINT = """  <joint name="{name}" type="{kind}">
    <parent link="{parent}"/><child link="{child}"/>
    <origin xyz="{x} 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>{extra}
  </joint>
"""


def link(name, mass=1.0, cx=0.5, ixx=0.01, iyy=0.02, izz=0.02) -> str:
    return LINK.format(name=name, mass=mass, cx=cx, ixx=ixx, iyy=iyy, izz=izz)


def joint(name, parent, child, kind="revolute", x=0.0, extra="") -> str:
    return JOINT.format(name=name, kind=kind, parent=parent, child=child, x=x, extra=extra)


def urdf(tmp_path, *parts, name="robot.urdf", header='<robot name="r">\n') -> Path:
    path = tmp_path / name
    path.write_text('<?xml version="1.0"?>\n' + header + "".join(parts) + "</robot>\n")
    return path


def two_links(tmp_path, **second):
    return urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "a"), link("b", **second),
                joint("j2", "a", "b", x=1.0))


def error_of(path) -> str:
    with pytest.raises(ModelFileError) as caught, warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        kronlag.load_urdf(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message
    return message


# -- the XML layer ----------------------------------------------------------------------------------

def test_entity_expansion_is_refused(tmp_path):
    laughs = ('<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY a "aaaaaaaaaa">'
              '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>\n<robot name="&b;"/>\n')
    path = tmp_path / "laughs.urdf"
    path.write_text(laughs)
    assert "refused" in error_of(path) and "entit" in error_of(path).lower()


def test_external_entity_is_refused(tmp_path):
    path = tmp_path / "external.urdf"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY secret SYSTEM "file:///etc/passwd">]>\n'
                    '<robot name="&secret;"/>\n')
    assert "refused" in error_of(path)


def test_malformed_xml_names_line_and_column(tmp_path):
    path = urdf(tmp_path, '  <link name="base">\n', '  <link name="a"/>\n')
    message = error_of(path)
    assert re.search(r"robot\.urdf:\d+: malformed XML at column \d+: mismatched tag", message), message


def test_depth_is_limited(tmp_path):
    path = tmp_path / "deep.urdf"
    path.write_text("<robot>" + "<a>" * 300 + "</a>" * 300 + "</robot>")
    assert "nest more than" in error_of(path)


@pytest.mark.parametrize("text, name", [
    ('<robot xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:macro name="m"/></robot>', "r.urdf"),
    ('<robot><link name="${prefix}base"/></robot>', "r.urdf"),
    ("<robot/>", "r.urdf.xacro"),
])
def test_xacro_is_not_evaluated(tmp_path, text, name):
    path = tmp_path / name
    path.write_text(text)
    message = error_of(path)
    assert "xacro" in message and "run `xacro" in message


def test_attributes_are_numbers_not_expressions(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a").replace('value="1.0"', 'value="__import__(\'os\')"'),
                joint("j1", "base", "a"))
    assert "mass" in error_of(path) and "expected 1 finite number" in error_of(path)


# -- bad URDF input: one line naming file, line and element ----------------------------------------

@pytest.mark.parametrize("change, expected", [
    (dict(mass=-1.0), r":\d+: <link name='b'>: <inertial>: mass = -1 is negative"),
    (dict(ixx=-0.01), r":\d+: <link name='b'>: <inertia>: the tensor is not positive definite"),
    (dict(ixx=0.01, iyy=0.01, izz=0.05), r":\d+: <link name='b'>: <inertia>: .* violate the triangle inequality"),
    (dict(mass=0.0, ixx=0, iyy=0, izz=0), r":\d+: <link name='b'>: is a zero-mass leaf"),
])
def test_non_physical_inertials(tmp_path, change, expected):
    assert re.search(expected, error_of(two_links(tmp_path, **change)))


def test_unknown_joint_type(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "a", kind="hinge"))
    assert re.search(r"robot\.urdf:\d+: <joint name='j1'>: unknown joint type 'hinge'", error_of(path))


def test_floating_joint_is_reported_not_supported(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "a", kind="floating"))
    assert "not supported by the URDF reader yet" in error_of(path)


def test_mimic_of_unknown_joint(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "a"), link("b"),
                joint("j2", "base", "b", extra='<mimic joint="nope"/>'))
    assert re.search(r":\d+: <mimic>: of joint 'j2': 'nope' is not a joint of the file", error_of(path))


def test_two_roots(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', '  <link name="other"/>\n', link("a"), joint("j1", "base", "a"))
    assert re.search(r":\d+: <link name=.other.>: a second root link: 2 links \(base, other\)", error_of(path))


def test_a_link_with_two_parents_is_a_loop(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), link("b"), joint("j1", "base", "a"),
                joint("j2", "base", "b"), joint("j3", "a", "b"))
    assert re.search(r"<joint name='j3'>: link 'b' already has the parent joint 'j2'", error_of(path))


def test_unknown_link(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "c"))
    assert "names the link 'c', which the file does not define" in error_of(path)


def test_skipped_elements_are_listed_once(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a").replace("</link>", "<collision/><collision/></link>"),
                joint("j1", "base", "a", extra="<calibration/>"), "<transmission/>\n")
    with pytest.warns(RobotFileWarning) as record:
        system = kronlag.load_urdf(path)
    assert len(record) == 1
    assert "joint/calibration, link/collision (2), robot/transmission" in str(record[0].message)
    assert system.robot.skipped == "joint/calibration, link/collision (2), robot/transmission"


# -- mechanics against hand values -----------------------------------------------------------------

def test_pendulum_with_fixed_tip_matches_hand_values(tmp_path):
    """One revolute joint about z, a link with its COM 0.5 along x and a 2 kg tip fixed 1 m out: M is
    the inertia about the axis, g the gravity torque (z axis vertical: none), with the axis turned to
    horizontal the gravity torque m g l cos q."""
    tip = link("tip", mass=2.0, cx=0.0, ixx=0.001, iyy=0.001, izz=0.001)
    path = urdf(tmp_path, '  <link name="base"/>\n', link("arm", mass=1.0, cx=0.5, izz=0.02),
                joint("hinge", "base", "arm").replace('<axis xyz="0 0 1"/>', '<axis xyz="0 -1 0"/>'),
                tip, joint("weld", "arm", "tip", kind="fixed", x=1.0))
    system = kronlag.load_urdf(path)
    assert [b.name for b in system.bodies] == ["arm"] and [q.name for q in system.coordinates] == ["hinge"]
    model = kronlag.derive(system).numeric({"g": 9.81, "tau_hinge": 0.0})
    # about the axis (y): the arm's iyy (0.02 as given) + 1 * 0.5^2, the tip's 0.001 + 2 * 1^2
    inertia = 0.02 + 0.25 + 0.001 + 2.0
    q = 0.3
    assert model.M([q])[0, 0] == pytest.approx(inertia, rel=1e-12)
    # rotation about -y by q lifts the x axis: the COM height is (0.5*1 + 1*2) sin q; V = m g h
    assert model.g([q])[0] == pytest.approx(9.81 * 2.5 * np.cos(q), rel=1e-12)


def test_mimic_is_a_holonomic_constraint_with_multiplier_and_offset(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "a"), link("b"),
                joint("j2", "base", "b", kind="prismatic", extra='<mimic joint="j1" multiplier="-2" offset="0.1"/>'
                      '<limit lower="-1" upper="1" effort="5" velocity="2"/><dynamics damping="0.3"/>'))
    system = kronlag.load_urdf(path)
    (constraint,) = system.constraints
    assert constraint.name == "j2.mimic"
    assert float(constraint.expression.subs({"j1": 0.5, "j2": -0.9})) == pytest.approx(0.0, abs=1e-15)
    j2 = system.robot.joint("j2")
    assert (j2.limits.lower, j2.limits.upper, j2.limits.effort, j2.limits.velocity, j2.limits.damping) == (
        -1.0, 1.0, 5.0, 2.0, 0.3)
    assert j2.mimic == ("j1", -2.0, 0.1) and j2.torque is None
    assert system.robot.q_reference == {"j1": 0.0, "j2": 0.1}


def test_load_model_and_cli_accept_urdf(tmp_path, capsys):
    path = two_links(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = kronlag.load_model(path)
    assert model.system.name == "r" and model.numeric_values() == {"g": 9.81, "tau_j1": 0.0, "tau_j2": 0.0}
    from kronlag.app.cli import main

    assert main(["check", str(path)]) == 0
    assert "m = 2 coordinates" in capsys.readouterr().out
    assert main(["check", str(tmp_path / "missing.urdf")]) == 2


# -- agreement with Pinocchio on files nobody here wrote -------------------------------------------

def _bench():
    spec = importlib.util.spec_from_file_location("bench_robots", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


FAST_ROBOTS = ("ur5", "z1", "double_pendulum")
SLOW_ROBOTS = ("panda", "so100", "kinova", "xarm7", "ur3")


def _agree(name):
    pytest.importorskip("pinocchio")
    bench = _bench()
    folder = bench.robots_folder()
    if folder is None:
        pytest.skip("example-robot-data is not installed")
    path = folder / bench.ROBOTS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_urdf(path)
    rng = np.random.default_rng(3)
    tau = np.array([rng.uniform(-1, 1) if joint.torque else 0.0 for joint in system.robot.joints if joint.coordinate])
    values = {**system.robot.values, **{joint.torque: value for joint, value in
                                        zip([j for j in system.robot.joints if j.coordinate], tau) if joint.torque}}
    model = kronlag.derive(system).numeric(values)
    worst = bench.compare(path, system, model, tau, states=3)
    assert max(worst.values()) <= 1e-9, worst
    return system


@pytest.mark.slow
@pytest.mark.parametrize("name", FAST_ROBOTS)
def test_arms_agree_with_pinocchio(name):
    _agree(name)


@pytest.mark.slow
@pytest.mark.parametrize("name", SLOW_ROBOTS)
def test_more_arms_agree_with_pinocchio(name):
    system = _agree(name)
    if name == "panda":  # the finger's mimic joint is the one constraint
        assert [c.name for c in system.constraints] == ["panda_finger_joint2.mimic"]
