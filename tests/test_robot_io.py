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
