"""Robot files, issue 21 (the robotio part): MJCF inertia from geoms against MuJoCo's compiler, mesh
bounds and search paths, the visuals the animation draws, absolute body coordinates, exact
closed-loop MJCF against hand-derived references (and MuJoCo's soft closure), and the bad-input
messages (one located line each)."""

from __future__ import annotations

import re
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag.core.errors import ModelFileError
from kronlag.model.robot_formats import RobotFileWarning
from kronlag.model.robot_formats.meshes import mesh_bounds, resolve_mesh

FILES = Path(__file__).resolve().parent / "robot_files"


def _at_zero(expression, system):
    return np.array(sp.Matrix(expression).subs({q: 0 for q in system.coordinates}).evalf(), dtype=float)


# -- MJCF inertia from geoms -----------------------------------------------------------------------

GEOMS = """<mujoco model="geoms"><compiler angle="degree"/>
<default><default class="light"><geom density="300"/></default></default>
<worldbody>
  <body name="a" pos="0.1 0 0.2"><joint name="j1" axis="0 1 0" pos="0.05 0 0"/>
    <geom type="capsule" fromto="0 0 0 0.4 0.1 -0.05" size="0.03"/>
    <geom type="sphere" pos="0.4 0.1 -0.05" size="0.05" mass="0.7"/>
    <body name="b" pos="0.4 0.1 -0.05" euler="10 20 30"><joint name="j2" axis="1 0 0"/>
      <geom type="box" size="0.1 0.02 0.03" pos="0.1 0 0" quat="0.9 0.1 0.3 0.2" class="light"/>
      <geom type="cylinder" fromto="0 0 0 0 0 -0.3" size="0.02"/>
      <geom type="ellipsoid" size="0.03 0.04 0.05" pos="0 0 -0.3" euler="30 0 45"/>
      <body name="c" pos="0 0 -0.3"><joint name="j3" type="slide" axis="0 0 1"/>
        <geom type="capsule" size="0.02 0.05" pos="0.01 0.02 0.03" axisangle="1 1 0 40"/>
      </body>
    </body>
  </body>
  <body name="d" pos="0 0.5 0"><joint name="j4" axis="0 0 1"/>
    <inertial pos="0.1 0 0" mass="2" diaginertia="0.01 0.02 0.02"/>
    <geom type="box" size="1 1 1"/>
  </body>
</worldbody></mujoco>"""


def test_mjcf_inertia_from_geoms_agrees_with_mujoco(tmp_path):
    """Bodies without <inertial> get MuJoCo's inertia from their geoms (density 1000 or a class's, a
    geom's mass, fromto, every shape); a body with an <inertial> keeps it (inertiafromgeom auto):
    mass, world centre of mass and world inertia tensor at q = 0 agree with the compiled MuJoCo model."""
    mujoco = pytest.importorskip("mujoco")
    path = tmp_path / "geoms.xml"
    path.write_text(GEOMS)
    system = kronlag.load_mjcf(path)
    peer = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(peer)
    mujoco.mj_forward(peer, data)
    for body in system.bodies:
        index = peer.body(body.name).id
        rotation = _at_zero(body.rotation, system)
        assert float(body.mass) == pytest.approx(peer.body_mass[index], rel=1e-12, abs=0)
        assert np.abs(_at_zero(body.position, system).ravel() - data.xipos[index]).max() <= 1e-9
        frame = data.ximat[index].reshape(3, 3)
        theirs = frame @ np.diag(peer.body_inertia[index]) @ frame.T
        ours = rotation @ np.array(body.inertia, dtype=float) @ rotation.T
        assert np.abs(ours - theirs).max() <= 1e-9 * np.abs(theirs).max(), body.name


def test_mjcf_geom_inertia_refusals(tmp_path):
    path = tmp_path / "mesh.xml"
    path.write_text('<mujoco><worldbody><body name="a"><joint name="j" axis="0 1 0"/>'
                    '<geom type="mesh" mesh="part"/></body></worldbody></mujoco>')
    with pytest.raises(ModelFileError, match=r"mesh\.xml:1: <geom>: type 'mesh': kronlag computes inertia"):
        kronlag.load_mjcf(path)


# -- absolute body coordinates ---------------------------------------------------------------------

ARM = """<robot name="arm">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0.25 0.01 0" rpy="0.1 0 0"/><mass value="2"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.04"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0.2 0 0.02"/><mass value="1"/>
    <inertia ixx="0.002" ixy="0.0003" ixz="0" iyy="0.02" iyz="0" izz="0.021"/></inertial></link>
  <link name="slider"><inertial><origin xyz="0.01 0 0.0"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.3" rpy="0 0.2 0"/><axis xyz="0 0 1"/></joint>
  <joint name="elbow" type="continuous"><parent link="upper"/><child link="lower"/>
    <origin xyz="0.5 0 0" rpy="0.3 0 0"/><axis xyz="0 0.6 0.8"/></joint>
  <joint name="slide" type="prismatic"><parent link="lower"/><child link="slider"/>
    <origin xyz="0.4 0 0"/><axis xyz="1 0 0"/></joint>
</robot>"""


def _quaternion_rate(e, omega):
    """d/dt of the Euler parameters of R with the world angular velocity omega (R e_body = e_world)."""
    e0, v = e[0], np.asarray(e[1:])
    return np.concatenate([[-0.5 * omega @ v], 0.5 * (e0 * omega + np.cross(omega, v))])


def test_absolute_coordinates_refuse_joints_of_several_coordinates(tmp_path):
    """A floating base has seven coordinates: absolute coordinates (one-coordinate joints as rows)
    refuse it in one located line instead of treating it as a revolute joint."""
    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    with pytest.raises(ModelFileError, match=r"arm\.urdf:.*the floating joint 'root_joint' has 7 coordinates"):
        kronlag.load_urdf(path, coordinates="absolute", floating_base=True)


@pytest.mark.slow
def test_absolute_coordinates_give_the_same_motion(tmp_path):
    """An arm with a tilted revolute, a general-axis revolute and a prismatic joint, actuated: read in
    joint and in absolute body coordinates; at random states (the absolute state mapped from the joint
    state exactly) the absolute forward dynamics, mapped back through the joint values, gives the
    joint coordinates' accelerations."""
    from kronlag.model.rotations import euler_parameters_of

    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    joint = kronlag.load_urdf(path)
    absolute = kronlag.load_urdf(path, coordinates="absolute")
    assert [c.name for c in absolute.constraints][3:8] == ["shoulder.x", "shoulder.y", "shoulder.z",
                                                            "shoulder.axis1", "shoulder.axis2"]
    assert len(absolute.coordinates) == 21 and absolute.robot.joint_values.keys() == {"shoulder", "elbow", "slide"}
    tau = {"tau_shoulder": 0.7, "tau_elbow": -0.4, "tau_slide": 1.3}
    joint_model = kronlag.derive(joint).numeric({**joint.robot.values, **tau}, backend="python")
    absolute_model = kronlag.derive(absolute).numeric({**absolute.robot.values, **tau}, backend="python")
    qs = joint.coordinates
    X = absolute.coordinates
    values = [absolute.robot.joint_values[name] for name in ("shoulder", "elbow", "slide")]
    gradient = sp.lambdify(X, sp.Matrix(values).jacobian(X))
    hessians = [sp.lambdify(X, sp.hessian(value, X)) for value in values]
    rng = np.random.default_rng(21)
    for _ in range(2):
        q, qd = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
        at = dict(zip(qs, q))
        state, rate = [], []
        for body in joint.bodies:
            position = sp.Matrix(body.position)
            rotation = sp.Matrix(body.rotation)
            rotation_rate = sum((rotation.diff(s) * v for s, v in zip(qs, qd)), sp.zeros(3, 3))
            R = np.array(rotation.subs(at).evalf(), dtype=float)
            spin = np.array(rotation_rate.subs(at).evalf(), dtype=float) @ R.T
            omega = np.array([spin[2, 1], spin[0, 2], spin[1, 0]])
            e = euler_parameters_of(R)
            state += [*np.array(position.subs(at).evalf(), dtype=float).ravel(), *e]
            rate += [*np.array(position.jacobian(qs).subs(at).evalf(), dtype=float) @ qd,
                     *_quaternion_rate(e, omega)]
        state, rate = np.array(state), np.array(rate)
        expected = joint_model.forward_dynamics(q, qd).qdd
        accelerations = absolute_model.forward_dynamics(state, rate).qdd
        mapped = gradient(*state) @ accelerations + np.array([rate @ h(*state) @ rate for h in hessians])
        assert np.abs(gradient(*state) @ rate - qd).max() <= 1e-12
        assert np.abs(mapped - expected).max() <= 1e-9 * np.abs(expected).max(), (mapped, expected)


# -- meshes: bounds, search paths, missing meshes, the drawing -------------------------------------

TRIANGLES = np.array([[[0, 0, 0], [1, 0, 0], [0, 2, 0]], [[0, 0, -1], [1, 2, 3], [0.5, -0.5, 0]]], dtype=float)


def _binary_stl(path):
    with open(path, "wb") as file:
        file.write(b"\0" * 80 + struct.pack("<I", len(TRIANGLES)))
        file.writelines(struct.pack("<3f", 0, 0, 1) + struct.pack("<9f", *triangle.ravel()) + b"\0\0" for triangle in TRIANGLES)


def _ascii_stl(path):
    facets = "".join("facet normal 0 0 1\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in t)
                     + "endloop\nendfacet\n" for t in TRIANGLES)
    path.write_text(f"solid part\n{facets}endsolid part\n")


def _obj(path):
    path.write_text("# part\n" + "".join(f"v {x} {y} {z}\n" for x, y, z in TRIANGLES.reshape(-1, 3)) + "f 1 2 3\n")


def _dae(path):
    vertices = " ".join(str(x) for x in TRIANGLES.ravel())
    path.write_text(f"""<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><unit meter="0.5"/><up_axis>Z_UP</up_axis></asset>
<library_geometries><geometry id="g"><mesh>
  <source id="p"><float_array id="pa" count="18">{vertices}</float_array></source>
  <vertices id="v"><input semantic="POSITION" source="#p"/></vertices></mesh></geometry></library_geometries>
<library_visual_scenes><visual_scene id="s"><node id="n"><translate>1 0 0</translate>
  <instance_geometry url="#g"/></node></visual_scene></library_visual_scenes></COLLADA>""")


@pytest.mark.parametrize("write, suffix, expected", [
    (_binary_stl, ".stl", ([0, -0.5, -1], [1, 2, 3])),
    (_ascii_stl, ".stl", ([0, -0.5, -1], [1, 2, 3])),
    (_obj, ".obj", ([0, -0.5, -1], [1, 2, 3])),
    (_dae, ".dae", ([0.5, -0.25, -0.5], [1, 1, 1.5])),  # translated by 1 (node), then halved (unit)
])
def test_mesh_bounds(tmp_path, write, suffix, expected):
    path = tmp_path / f"part{suffix}"
    write(path)
    low, high = mesh_bounds(path)
    assert np.allclose(low, expected[0]) and np.allclose(high, expected[1])


def test_mesh_search_paths(tmp_path, monkeypatch):
    """package:// (and SDF's model://) against package_paths=, ROS_PACKAGE_PATH and the file's parents;
    relative paths against the file's directory."""
    robot = tmp_path / "share" / "my_robot" / "urdf" / "r.urdf"
    mesh = tmp_path / "share" / "my_robot" / "meshes" / "a.stl"
    mesh.parent.mkdir(parents=True)
    robot.parent.mkdir(parents=True)
    _binary_stl(mesh)
    assert resolve_mesh("package://my_robot/meshes/a.stl", robot) == mesh  # a parent is named my_robot
    assert resolve_mesh("../meshes/a.stl", robot).resolve() == mesh
    elsewhere = tmp_path / "elsewhere" / "r.urdf"
    assert resolve_mesh("package://my_robot/meshes/a.stl", elsewhere) is None
    assert resolve_mesh("package://my_robot/meshes/a.stl", elsewhere, [tmp_path / "share"]) == mesh
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "share"))
    assert resolve_mesh("package://my_robot/meshes/a.stl", elsewhere) == mesh
    # SDF's model:// as package:// (example-robot-data's Cassie: model://example-robot-data/robots/...)
    assert resolve_mesh("model://my_robot/meshes/a.stl", robot) == mesh


BOXED = """<robot name="boxed">
  <link name="base"><visual><geometry><box size="0.2 0.2 0.1"/></geometry></visual></link>
  <link name="arm"><inertial><origin xyz="0.25 0 0"/><mass value="1"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
    <visual><origin xyz="0.25 0 0" rpy="0 1.5707963267948966 0"/>
      <geometry><cylinder radius="0.03" length="0.5"/></geometry></visual>
    <visual><geometry><mesh filename="package://my_robot/meshes/a.stl" scale="0.1 0.1 0.1"/></geometry></visual>
    <visual><geometry><mesh filename="package://nowhere/b.stl"/></geometry></visual></link>
  <joint name="hinge" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/></joint>
</robot>"""


def test_visuals_meshes_and_missing_mesh(tmp_path):
    """A mesh found by package_paths= becomes a box of its scaled bounds; a missing one is a warning
    (the file still loads) and stays a named placeholder."""
    mesh = tmp_path / "share" / "my_robot" / "meshes" / "a.stl"
    mesh.parent.mkdir(parents=True)
    _binary_stl(mesh)
    path = tmp_path / "boxed.urdf"
    path.write_text(BOXED)
    with pytest.warns(RobotFileWarning, match=r"boxed\.urdf: meshes drawn as placeholders: package://nowhere/b\.stl "
                                              r"\(not found\)"):
        system = kronlag.load_urdf(path, package_paths=[tmp_path / "share"])
    shapes = [(v.link, v.shape, v.size, v.filename) for v in system.robot.visuals]
    assert shapes[:2] == [("base", "box", (0.2, 0.2, 0.1), None), ("arm", "cylinder", (0.03, 0.5), None)]
    assert shapes[2][:2] == ("arm", "box") and np.allclose(shapes[2][2], [0.1, 0.25, 0.4])
    assert np.allclose(system.robot.visuals[2].pose[:3, 3], [0.05, 0.075, 0.1])  # the box's centre
    assert shapes[3] == ("arm", "mesh", (1.0, 1.0, 1.0), "package://nowhere/b.stl")


@pytest.mark.slow
def test_animation_draws_the_visuals(tmp_path):
    """The frame of a robot with visuals has the solids' fill colours; the same robot without
    visuals has only the stick figure."""
    from kronlag.views.animation import render_frame

    counts = []
    for text in (BOXED, re.sub(r"<visual>.*?</visual>", "", BOXED, flags=re.DOTALL)):
        path = tmp_path / "boxed.urdf"
        path.write_text(text)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RobotFileWarning)
            system = kronlag.load_urdf(path)
        model = kronlag.derive(system).numeric(system.robot.values, backend="python")
        trajectory = kronlag.simulate(model, (0, 0.2), [0.3], [0.0], t_eval=np.linspace(0, 0.2, 3))
        image = render_frame(trajectory, -1, tmp_path / "frame.png").convert("RGB")
        colors = np.array(image).reshape(-1, 3)
        pale_blue = np.array([143, 187, 217])  # the first solid's fill: tab:blue mixed with white
        counts.append(int((np.abs(colors - pale_blue).sum(axis=1) == 0).sum()))
    assert counts[0] > 500 and counts[1] == 0


def test_mjcf_mesh_asset_is_drawn_by_its_bounds(tmp_path):
    (tmp_path / "parts").mkdir()
    _binary_stl(tmp_path / "parts" / "link.stl")
    path = tmp_path / "meshy.xml"
    path.write_text('<mujoco><compiler meshdir="parts"/><asset><mesh file="link.stl" scale="2 2 2"/><texture/></asset>'
                    '<worldbody><body name="a"><joint name="j" axis="0 1 0"/>'
                    '<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/><geom type="mesh" mesh="link"/></body>'
                    '</worldbody></mujoco>')
    with pytest.warns(RobotFileWarning, match="asset/texture"):
        system = kronlag.load_mjcf(path)
    (visual,) = system.robot.visuals
    assert visual.shape == "box" and np.allclose(visual.size, [2, 5, 8]) and np.allclose(visual.pose[:3, 3], [1, 1.5, 2])
