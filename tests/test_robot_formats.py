"""Robot files (issue 21): the hardened XML layer, the URDF reader's bad-input messages, its mechanics
against hand values, load_model / CLI dispatch, and agreement with Pinocchio on example-robot-data's
arms (skipped without pin and example-robot-data)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import example_robot, robots_bench

import kronlag
from kronlag.core.errors import ModelFileError
from kronlag.model.robot_formats import RobotFileWarning

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
    (dict(mass=-1.0), r":\d+: <link name='b'>: <inertial>: mass = -1 .*a mass must not be negative"),
    (dict(ixx=-0.01), r":\d+: <link name='b'>: <inertial>: the inertia tensor is not positive semidefinite"),
    (dict(ixx=0.01, iyy=0.01, izz=0.05), r":\d+: <link name='b'>: <inertial>: .* violate the triangle inequality"),
    (dict(mass=0.0, ixx=0, iyy=0, izz=0), r":\d+: <link name='b'>: is a zero-mass leaf"),
])
def test_non_physical_inertials(tmp_path, change, expected):
    assert re.search(expected, error_of(two_links(tmp_path, **change)))


def test_unknown_joint_type(tmp_path):
    path = urdf(tmp_path, '  <link name="base"/>\n', link("a"), joint("j1", "base", "a", kind="hinge"))
    assert re.search(r"robot\.urdf:\d+: <joint name='j1'>: unknown joint type 'hinge'", error_of(path))


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
    (line,) = system.drawing  # the animation's stick figure: from the hinge to the tip
    assert [tuple(float(x) for x in point.subs("hinge", 0)) for point in line.points] == [(0, 0, 0), (1, 0, 0)]
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

FAST_ROBOTS = ("ur5", "z1", "double_pendulum")
SLOW_ROBOTS = ("panda", "so100", "kinova", "xarm7", "ur3")


def _agree(name, backend="auto"):
    bench = robots_bench()
    path = example_robot(bench.ROBOTS[name])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_urdf(path)
    rng = np.random.default_rng(3)
    tau = np.array([rng.uniform(-1, 1) if joint.torque else 0.0 for joint in system.robot.joints if joint.coordinate])
    values = {**system.robot.values, **{joint.torque: value for joint, value in
                                        zip([j for j in system.robot.joints if j.coordinate], tau) if joint.torque}}
    model = kronlag.derive(system).numeric(values, backend=backend)
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
    """The generated code of these takes 10-200 s to compile (the fast arms test the C backend)."""
    system = _agree(name, backend="python")
    if name == "panda":  # the finger's mimic joint is the one constraint
        assert [c.name for c in system.constraints] == ["panda_finger_joint2.mimic"]


# -- MJCF ---------------------------------------------------------------------------------------------

FILES = Path(__file__).resolve().parent / "robot_files"


def mjcf(tmp_path, body: str, equality: str = "", name: str = "model.xml") -> Path:
    path = tmp_path / name
    path.write_text(f'<mujoco model="m"><compiler angle="radian"/><worldbody>{body}</worldbody>'
                    f"<equality>{equality}</equality></mujoco>")
    return path


PENDULUM = ('<body name="arm" pos="0 0 0"><joint name="hinge" axis="0 1 0"/>'
            '<inertial pos="0.5 0 0" mass="1" diaginertia="0.001 0.02 0.02"/></body>')


def mjcf_error(path) -> str:
    with pytest.raises(ModelFileError) as caught, warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        kronlag.load_mjcf(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message
    return message


@pytest.mark.parametrize("body, equality, expected", [
    (PENDULUM.replace('axis="0 1 0"', 'type="screw"'), "", r"<joint name='hinge'>: unknown joint type 'screw'; MJCF joint types are hinge, slide, ball, free"),
    (PENDULUM.replace('<inertial pos="0.5 0 0" mass="1" diaginertia="0.001 0.02 0.02"/>', '<geom type="mesh"/>'), "",
     r"<geom>: type 'mesh': kronlag computes inertia from sphere"),
    (PENDULUM.replace('mass="1"', 'mass="-1"'), "", r"<body name='arm'>: <inertial>: mass = -1 .*must not be negative"),
    (PENDULUM, '<connect body1="arm" body2="nope" anchor="0 0 0"/>', r"<connect>: body2='nope' is not a body"),
    (PENDULUM, '<joint joint1="hinge" joint2="nope"/>', r"<joint>: names the joint 'nope'"),
    (PENDULUM.replace('axis="0 1 0"', 'axis="0 1 0" class="stiff"'), "", r"class='stiff': no <default"),
])
def test_bad_mjcf(tmp_path, body, equality, expected):
    assert re.search(expected, mjcf_error(mjcf(tmp_path, body, equality))), mjcf_error(mjcf(tmp_path, body, equality))


def test_weld_keeps_the_rows_that_are_not_identically_zero(tmp_path):
    """A hinge about y welded to the world off its axis: the rows x, z and ry move, y, rx, rz are
    identically zero (dropped, listed as redundant); the mobility is 0."""
    system = kronlag.load_mjcf(mjcf(tmp_path, PENDULUM, '<weld name="w" body1="world" body2="arm" anchor="0.1 0 0"/>'))
    assert [c.name for c in system.constraints] == ["w.x", "w.z", "w.ry"]
    assert system.robot.redundant == ["w.y", "w.rx", "w.rz"]
    model = kronlag.derive(system).numeric(system.robot.values)
    assert model.mobility([0.0]) == 0


def test_joint_equality_is_the_polynomial(tmp_path):
    two = PENDULUM + PENDULUM.replace('name="arm"', 'name="arm2"').replace('name="hinge"', 'name="hinge2"')
    system = kronlag.load_mjcf(mjcf(tmp_path, two, '<joint name="gear" joint1="hinge2" joint2="hinge" '
                                                   'polycoef="0.1 -2 0.5 0 0"/>'))
    (constraint,) = system.constraints
    assert constraint.name == "gear.joint"
    q = 0.3
    assert float(constraint.expression.subs({"hinge": q, "hinge2": 0.1 - 2 * q + 0.5 * q ** 2})) == pytest.approx(0)


@pytest.mark.slow
def test_mjcf_tree_agrees_with_mujoco():
    """A spatial arm with default classes, degrees, euler (zyx), quat, axisangle, xyaxes, two joints in
    one body, a slide, fullinertia and a welded body: M and C qd + g agree with MuJoCo's mj_fullM and
    qfrc_bias."""
    mujoco = pytest.importorskip("mujoco")
    path = FILES / "arm.xml"
    with pytest.warns(RobotFileWarning, match="mujoco/actuator"):
        system = kronlag.load_mjcf(path)
    model = kronlag.derive(system).numeric(system.robot.values)
    peer = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(peer)
    names = [joint.name for joint in system.robot.joints if joint.coordinate]
    qpos, dof = [peer.joint(n).qposadr[0] for n in names], [peer.joint(n).dofadr[0] for n in names]
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, qd = rng.uniform(-1, 1, len(names)), rng.uniform(-1, 1, len(names))
        data.qpos[qpos], data.qvel[dof] = q, qd
        mujoco.mj_forward(peer, data)
        mass = np.zeros((peer.nv, peer.nv))
        mujoco.mj_fullM(peer, data, mass)
        mass, bias = mass[np.ix_(dof, dof)], data.qfrc_bias[dof]
        assert np.abs(model.M(q) - mass).max() <= 1e-9 * np.abs(mass).max()
        assert np.abs(model.Cqd(q, qd) + model.g(q) - bias).max() <= 1e-9 * max(1.0, np.abs(bias).max())


def _planar_four_bar():
    """The four-bar of four_bar.xml built by hand in the plane (x, z -> X, Y; angle = -rotation about y)
    with planar bodies in absolute coordinates and revolute joints."""
    import sympy as sp

    symbols = sp.symbols("x1 y1 a1 x2 y2 a2 x3 y3 a3")
    x1, y1, a1, x2, y2, a2, x3, y3, a3 = symbols
    g, R = sp.Symbol("g"), sp.Rational
    system = kronlag.System(symbols, parameters=[g], gravity=(0, -g))
    for name, mass, inertia, x, y, a in (("crank", 1, R(12, 10000), x1, y1, a1), ("coupler", 2, R(3, 100), x2, y2, a2),
                                         ("follower", R(3, 2), R(55, 10000), x3, y3, a3)):
        system.add_body(kronlag.PlanarBody(name, mass=mass, inertia=inertia, position=(x, y), angle=a))
    system.add_joint("revolute", "ground", "crank", at_a=(0, 0), at_b=(0, R(-5, 100)))
    system.add_joint("revolute", "crank", "coupler", at_a=(0, R(5, 100)), at_b=(R(-2, 10), R(-5, 100)))
    system.add_joint("revolute", "ground", "follower", at_a=(R(35, 100), 0), at_b=(R(-25, 1000), R(-1, 10)))
    system.add_joint("revolute", "coupler", "follower", at_a=(R(2, 10), R(5, 100)), at_b=(R(25, 1000), R(1, 10)))
    return kronlag.derive(system).numeric({"g": 9.81})


def _turn(angle):
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


@pytest.mark.slow
@pytest.mark.parametrize("name, redundant", [("four_bar.xml", ["loop.y"]),
                                             ("four_bar.sdf", ["loop.y", "loop.axis1", "loop.axis2"])])
def test_closed_loop_is_exact(name, redundant):
    """The four-bar from MJCF (closed by a connect) and from SDF (by a revolute joint whose child is
    already in the tree): the identically zero rows are dropped (redundant), the loop closes, the
    mobility is 1, and the accelerations agree with the same four-bar built with planar bodies."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        system = kronlag.model.robot_formats.load_robot(FILES / name)
    assert [c.name for c in system.constraints] == ["loop.x", "loop.z"] and system.robot.redundant == redundant
    model = kronlag.derive(system).numeric(system.robot.values)
    q, qd = model.assemble([0.3, 0, 0], fixed={"crank_angle": 0.3}, qd_guess=[1.0, 0, 0], qd_fixed={"crank_angle": 1.0})
    assert model.mobility(q) == 1
    ours = model.forward_dynamics(q, qd).qdd
    planar = _planar_four_bar()
    t1, t2, t3 = q[0], q[0] + q[1], q[2]
    guess = [*(_turn(-t1) @ [0, 0.05]), -t1, *(_turn(-t1) @ [0, 0.1] + _turn(-t2) @ [0.2, 0.05]), -t2,
             *(np.array([0.35, 0]) + _turn(-t3) @ [0.025, 0.1]), -t3]
    pq, pqd = planar.assemble(guess, fixed={"a1": -t1}, qd_guess=np.zeros(9), qd_fixed={"a1": -qd[0]})
    assert np.abs(pq - guess).max() <= 1e-12  # the same configuration
    reference = planar.forward_dynamics(pq, pqd).qdd
    expected = np.array([-reference[2], -(reference[5] - reference[2]), -reference[8]])
    assert np.abs(ours - expected).max() <= 1e-9 * np.abs(expected).max()


def test_load_model_reads_mjcf(tmp_path, capsys):
    path = mjcf(tmp_path, PENDULUM)
    assert kronlag.load_model(path).system.name == "m"
    from kronlag.app.cli import main

    assert main(["check", str(path)]) == 0
    assert "no constraints: a tree" in capsys.readouterr().out


# -- SDF ----------------------------------------------------------------------------------------------

def sdf(tmp_path, model: str) -> Path:
    path = tmp_path / "model.sdf"
    path.write_text(f'<sdf version="1.7"><model name="m">{model}</model></sdf>')
    return path


SDF_LINK = ('<link name="arm"><inertial><pose>0.5 0 0 0 0 0</pose><mass>1</mass><inertia><ixx>0.001</ixx>'
            '<iyy>0.02</iyy><izz>0.02</izz></inertia></inertial></link>')
SDF_HINGE = ('<joint name="hinge" type="revolute"><parent>world</parent><child>arm</child>'
             '<axis><xyz>0 1 0</xyz></axis></joint>')


@pytest.mark.parametrize("model, expected", [
    (SDF_LINK + SDF_LINK.replace('"arm"', '"leg"'), r"<link name='leg'>: a second root link"),
    (SDF_LINK + SDF_HINGE.replace('type="revolute"', 'type="gearbox"'),
     r"<joint name='hinge'>: type 'gearbox' in the tree"),
    (SDF_LINK + SDF_HINGE.replace("<child>arm", "<child>nope"), r"<child>nope</child> is not a link"),
    (SDF_LINK.replace("<link name=\"arm\">", '<link name="arm"><pose relative_to="nowhere">0 0 0 0 0 0</pose>')
     + SDF_HINGE, r"relative_to='nowhere' is not a link or joint"),
    (SDF_LINK.replace("<mass>1</mass>", "<mass>-1</mass>") + SDF_HINGE,
     r"<link name='arm'>: <inertial>: mass = -1 .*must not be negative"),
])
def test_bad_sdf(tmp_path, model, expected):
    path = sdf(tmp_path, model)
    with pytest.raises(ModelFileError) as caught:
        kronlag.load_sdf(path)
    assert re.search(expected, str(caught.value)) and str(path) in str(caught.value), str(caught.value)


def test_sdf_pendulum_matches_hand_values(tmp_path):
    """A link placed by relative_to and a joint posed in the child's frame: M about the hinge."""
    model = (SDF_LINK.replace('<link name="arm">', '<link name="arm"><pose relative_to="hinge">0 0 0 0 0 0</pose>')
             + SDF_HINGE.replace("<parent>", "<pose relative_to=\"__model__\">0 0 1 0 0 0</pose><parent>"))
    system = kronlag.load_sdf(sdf(tmp_path, model))
    model = kronlag.derive(system).numeric(system.robot.values)
    assert model.M([0.4])[0, 0] == pytest.approx(0.02 + 0.25, rel=1e-12)
    assert model.g([0.0])[0] == pytest.approx(-9.81 * 0.5, rel=1e-12)
    assert [float(x) for x in system.robot.frames["arm"].origin.subs("hinge", 0.3)] == [0, 0, 1]
