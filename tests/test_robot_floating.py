"""Floating bases and multi-coordinate joints in robot files (issue 21): Euler-parameter rotations
in a RotationSequence, URDF ``floating``/``planar``, SDF ``ball``/``universal`` and models not fixed to
the world, against hand values; example-robot-data's legged robots against Pinocchio's free flyer
and Cassie's closed loops (skipped without pin and example-robot-data)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import example_robot, robots_bench

import kronlag
from kronlag.model.robot_formats import RobotFileWarning
from kronlag.model.rotations import EULER_PARAMETERS, RotationSequence

BODY = """  <link name="{name}">
    <inertial><origin xyz="{c}" rpy="0 0 0"/><mass value="2.0"/>
      <inertia ixx="0.1" ixy="0.01" ixz="0" iyy="0.2" iyz="0.02" izz="0.25"/></inertial>
  </link>
"""


def robot(tmp_path, kind: str, centre: str = "0 0 0") -> Path:
    path = tmp_path / "robot.urdf"
    path.write_text('<?xml version="1.0"?>\n<robot name="r">\n  <link name="world"/>\n'
                    + BODY.format(name="body", c=centre)
                    + f'  <joint name="base" type="{kind}"><parent link="world"/><child link="body"/>'
                      '<axis xyz="0 0 1"/></joint>\n</robot>\n')
    return path


def unit(rng) -> np.ndarray:
    e = rng.normal(size=4)
    return e / np.linalg.norm(e)


def test_euler_parameter_factor_gives_the_angular_velocity():
    """omega_body of R = Rz(0.3) R(e) Rx(a) from the factors equals vee(R^T Rd), computed here."""
    e, a = sp.symbols("e0:4"), sp.Symbol("a")
    sequence = RotationSequence([("z", sp.Float(0.3)), (EULER_PARAMETERS, e), ("x", a)])
    rng = np.random.default_rng(5)
    point = {**dict(zip(e, unit(rng))), a: 0.7}
    rates = dict(zip(e, rng.normal(size=4)))
    rates = {**rates, a: 1.3}
    direction = np.array([point[x] for x in e])
    tangent = np.array([rates[x] for x in e]) - (np.array([rates[x] for x in e]) @ direction) * direction
    rates.update(dict(zip(e, tangent)))
    rotation = sequence.matrix
    rotation_dot = sum((rotation.diff(x) * rates[x] for x in (*e, a)), sp.zeros(3))
    spin = np.array((rotation.T * rotation_dot).subs(point), dtype=float)
    omega = sum(np.array(axis.subs(point), dtype=float).ravel() * float(sp.diff(angle, x)) * rates[x]
                for axis, angle in sequence.body_axes() for x in (*e, a))
    assert np.allclose(omega, [spin[2, 1], spin[0, 2], spin[1, 0]], atol=1e-12)
    assert sequence.axis_names == ("z", None, "x")


def test_floating_joint_is_a_free_body(tmp_path):
    """A URDF floating joint: seven named coordinates, the normalization constraint, e0 = 1 at the
    reference; a free body falls with g and spins by Euler's equations (I wd = -w x I w)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_urdf(robot(tmp_path, "floating"))
    names = [q.name for q in system.coordinates]
    assert names == ["base_x", "base_y", "base_z", "base_e0", "base_e1", "base_e2", "base_e3"]
    assert [c.name for c in system.constraints] == ["base.normalization"]
    assert system.robot.q_reference == {**dict.fromkeys(names, 0.0), "base_e0": 1.0}
    assert system.robot.joint("base").coordinates == tuple(names)
    model = kronlag.derive(system).numeric(system.robot.values)
    rng = np.random.default_rng(2)
    e, omega = unit(rng), rng.normal(size=3)
    e0, e1, e2, e3 = e
    rates = np.array([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])
    q = np.concatenate([rng.normal(size=3), e])
    qd = np.concatenate([rng.normal(size=3), rates.T @ omega / 2])
    qdd = model.forward_dynamics(q, qd).qdd
    assert np.allclose(qdd[:3], [0, 0, -9.81], atol=1e-12)
    inertia = np.array([[0.1, 0.01, 0], [0.01, 0.2, 0.02], [0, 0.02, 0.25]])
    expected = np.linalg.solve(inertia, -np.cross(omega, inertia @ omega))
    assert np.allclose(2 * rates @ qdd[3:], expected, atol=1e-10)


def test_planar_joint_moves_in_the_plane_normal_to_its_axis(tmp_path):
    """M of a body on a planar joint (axis z) with its centre of mass 0.5 off the joint, by hand."""
    system = kronlag.load_urdf(robot(tmp_path, "planar", centre="0.5 0 0"))
    assert [q.name for q in system.coordinates] == ["base_x", "base_y", "base_theta"]
    model = kronlag.derive(system).numeric(system.robot.values)
    mass = model.M([0.3, -0.2, 0.0])
    assert np.allclose(mass, [[2, 0, 0], [0, 2, 1.0], [0, 1.0, 0.25 + 2 * 0.25]], atol=1e-12)
    assert np.allclose(model.g([0.0, 0.0, 0.4]), 0.0, atol=1e-12)  # gravity along the axis: no work


SDF_BODY = ('<link name="bob"><pose>0 0 -1 0 0 0</pose><inertial><mass>2</mass><inertia><ixx>0.1</ixx>'
            '<iyy>0.2</iyy><izz>0.3</izz></inertia></inertial></link>')


def sdf(tmp_path, model: str) -> Path:
    path = tmp_path / "model.sdf"
    path.write_text(f'<sdf version="1.7"><model name="m">{model}</model></sdf>')
    return path


def test_sdf_universal_joint_in_the_tree(tmp_path):
    """A pendulum on a universal joint (x, then y) at the origin, its bob 1 below: M by hand."""
    joint = ('<joint name="cardan" type="universal"><parent>world</parent><child>bob</child>'
             '<pose relative_to="__model__">0 0 0 0 0 0</pose>'
             '<axis><xyz>1 0 0</xyz></axis><axis2><xyz>0 1 0</xyz></axis2></joint>')
    system = kronlag.load_sdf(sdf(tmp_path, SDF_BODY + joint))
    assert [q.name for q in system.coordinates] == ["cardan_1", "cardan_2"]
    model = kronlag.derive(system).numeric(system.robot.values)
    assert np.allclose(model.M([0.0, 0.0]), np.diag([0.1 + 2, 0.2 + 2]), atol=1e-12)
    # tilted by q1 about x the second axis stays normal to the pendulum: M22 = Iyy + m
    assert model.M([0.4, 0.0])[1, 1] == pytest.approx(0.2 + 2, rel=1e-12)


def test_sdf_ball_joint_and_floating_model(tmp_path):
    """A spherical pendulum (ball joint: Euler parameters and their constraint) and a model that no
    joint fixes to the world (a floating base 'root_joint' at the link's pose)."""
    joint = ('<joint name="socket" type="ball"><parent>world</parent><child>bob</child>'
             '<pose relative_to="__model__">0 0 0 0 0 0</pose></joint>')
    system = kronlag.load_sdf(sdf(tmp_path, SDF_BODY + joint))
    assert [q.name for q in system.coordinates] == [f"socket_e{k}" for k in range(4)]
    assert [c.name for c in system.constraints] == ["socket.normalization"]
    assert "Euler-parameter normalizations (floating and ball joints): socket.normalization" in system.describe()
    model = kronlag.derive(system).numeric(system.robot.values)
    angle = 0.3  # turned about x: the bob swings up by 1 - cos(angle); the weight's torque m g sin(angle)
    q = [np.cos(angle / 2), np.sin(angle / 2), 0, 0]
    rates = np.array([[-q[1], q[0], q[3], -q[2]], [-q[2], -q[3], q[0], q[1]], [-q[3], q[2], -q[1], q[0]]])
    qdd = model.forward_dynamics(q, [0, 0, 0, 0]).qdd
    assert (2 * rates @ qdd)[0] == pytest.approx(-2 * 9.81 * np.sin(angle) / (0.1 + 2), rel=1e-10)
    free = kronlag.load_sdf(sdf(tmp_path, SDF_BODY))
    assert [q.name for q in free.coordinates][:3] == ["root_joint_x", "root_joint_y", "root_joint_z"]
    assert [float(x) for x in free.robot.frames["bob"].origin.subs(free.robot.q_reference)] == [0, 0, -1]


# -- against Pinocchio's free flyer --------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("name", ["solo12", "a1", "go2"])
def test_floating_robots_agree_with_pinocchio(name):
    """M, g, C qd and the accelerations against crba, computeGeneralizedGravity, nonLinearEffects and
    aba of Pinocchio's free-flyer model at random states, mapped as documented in
    bench_robots.FloatingReference (the derivation takes 10-60 s; the Python backend skips the C build).
    Go1, ANYmal (B, C) and HyQ are refused as shipped: an inertial violates the triangle inequality."""
    bench = robots_bench()
    path = example_robot(bench.FLOATING[name])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_urdf(path, floating_base=True)
    assert [c.name for c in system.constraints] == ["root_joint.normalization"]
    rng = np.random.default_rng(3)
    values = {**system.robot.values, **{joint.torque: rng.uniform(-1, 1) for joint in system.robot.joints
                                        if joint.torque}}
    model = kronlag.derive(system).numeric(values, backend="python")
    worst = bench.compare_floating(path, system, model, values, states=3)
    assert max(worst.values()) <= 1e-9, worst


def test_mjcf_free_and_ball_joints(tmp_path):
    """MJCF ``freejoint`` and ``ball``: a floating body with a spherical pendulum hung from it; in free
    fall with no spin both keep their pose (the ball joint's accelerations vanish)."""
    path = tmp_path / "model.xml"
    path.write_text('<mujoco><worldbody><body name="torso" pos="0 0 1"><freejoint name="root"/>'
                    '<inertial pos="0 0 0" mass="3" diaginertia="0.1 0.2 0.25"/>'
                    '<body name="arm" pos="0 0 -0.2"><joint name="shoulder" type="ball"/>'
                    '<inertial pos="0 0 -0.3" mass="1" diaginertia="0.02 0.02 0.01"/></body>'
                    '</body></worldbody></mujoco>')
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_mjcf(path)
    names = [q.name for q in system.coordinates]
    assert names[:3] == ["root_x", "root_y", "root_z"] and names[7:] == [f"shoulder_e{k}" for k in range(4)]
    assert [c.name for c in system.constraints] == ["root.normalization", "shoulder.normalization"]
    model = kronlag.derive(system).numeric(system.robot.values, backend="python")
    q = np.array([system.robot.q_reference[name] for name in names])
    qdd = model.forward_dynamics(q, np.zeros(len(q))).qdd
    assert np.allclose(qdd, [0, 0, -9.81] + [0] * 8, atol=1e-12)


@pytest.mark.slow
def test_cassie_loops_close_and_its_mobility_is_counted_right():
    """Cassie (SDF as shipped, a floating pelvis and four ball joints closing the leg loops): the loops
    close at the reference pose; their constraint ranks are 3, 3 (Achilles rods) and 2, 2 (the planar
    foot four-bars: the left one's out-of-plane row is identically zero and dropped, the right one's is
    planar only to ~7e-8 rad, and the rank policy of kronlag.numeric.tolerances counts it dependent);
    the mobility 18 = 29 coordinates - 1 normalization - 10, against m - r = 17."""
    bench = robots_bench()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_sdf(example_robot(bench.CASSIE))
    assert (len(system.bodies), len(system.coordinates)) == (23, 29)
    assert system.robot.redundant == ["left-plantar-foot-joint.z"]
    ranks, mobility, residual = bench.loop_ranks(system)
    assert residual <= 1e-12, residual
    assert ranks == {"root_joint": 1, "left-pitch-rod-joint": 3, "right-pitch-rod-joint": 3,
                     "right-plantar-foot-joint": 2, "left-plantar-foot-joint": 2}
    assert mobility == 18


def test_long_chain_on_a_floating_base_keeps_its_rotations(tmp_path):
    """More than MAX_ROTATION_FACTORS factors: the constant rotations are moved past the joints and
    the Euler-parameter factor (C R(e) = R(e0, C e) C); each body's rotation still equals its link
    frame's, evaluated at a random state."""
    links = '  <link name="world"/>\n' + "".join(BODY.format(name=f"l{k}", c="0.1 0 0") for k in range(6))
    joints = '  <joint name="base" type="floating"><parent link="world"/><child link="l0"/></joint>\n' + "".join(
        f'  <joint name="j{k}" type="revolute"><parent link="l{k - 1}"/><child link="l{k}"/>'
        f'<origin xyz="0.2 0 0" rpy="0.3 -0.4 {0.5 + k / 10}"/><axis xyz="0 1 0"/></joint>\n' for k in range(1, 6))
    path = tmp_path / "chain.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="chain">\n{links}{joints}</robot>\n')
    system = kronlag.load_urdf(path)
    rng = np.random.default_rng(4)
    point = dict(zip(system.coordinates, np.concatenate([rng.normal(size=3), unit(rng), rng.normal(size=5)])))
    for body in system.bodies:
        frame = system.robot.frames[body.name].rotation
        assert np.allclose(np.array(body.rotation.xreplace(point), dtype=float),
                           np.array(frame.xreplace(point), dtype=float), atol=1e-12), body.name
    assert len(system.body("l5").rotation_sequence.factors) <= 16
