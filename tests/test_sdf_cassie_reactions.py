"""Cassie's named loop reactions (issue 21, item 7; docs/sdf.md): the model of
``docs/figures/cassie_loop_reactions.py`` (pelvis on a stand, motors held, the file's leaf springs,
the foot pushed up) at rest, its Achilles rod's reactions checked against statics computed here from
the file's geometry and masses alone: about each leaf spring's axis, the moment of the loop's force,
of the weights of the parts beyond the spring and of the push balances the spring's torque
``k theta``; about the rod's own hinge, the loop force balances the rod's weight.  Skipped without example-robot-data."""

from __future__ import annotations

import runpy
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import kronlag

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "cassie_loop_reactions.py"
#: The links beyond each joint of a leg (names without the side), whose weights load it.
BEYOND = {"tarsus-spring-joint": ("heel-spring", "achilles-rod"),
          "knee-shin-joint": ("shin", "tarsus", "heel-spring", "achilles-rod", "foot-crank", "plantar-rod", "foot"),
          "achilles-spring-joint": ("achilles-rod",)}


@pytest.fixture(scope="module")
def figure():
    script = runpy.run_path(str(SCRIPT))
    if script["cassie_file"]() is None:
        pytest.skip("example-robot-data is not installed")
    return script


@pytest.mark.slow
def test_cassie_on_stand_names_its_loops_and_plots_them(figure, tmp_path):
    """The stand holds the pelvis (no floating joint), the ten motors are drives named after their
    joints, the springs are potentials, the right foot's dependent row is gone: one free mode per leg.
    The figure's plot takes the multipliers by these names (~15 s: loading Cassie)."""
    system = figure["cassie_on_stand"](figure["cassie_file"]())
    assert len(system.coordinates) == 22 and not any(q.name.startswith("root_joint") for q in system.coordinates)
    assert system.drives == [f"{side}-{motor}" for side in ("left", "right") for motor in figure["MOTORS"]]
    assert [load.name for load in system.potentials] == [
        f"{side}-{joint} spring" for side in ("left", "right") for joint in ("knee-shin-joint", "tarsus-spring-joint")]
    assert figure["loop_rows"](system) == {
        "left-pitch-rod-joint": ["left-pitch-rod-joint.x", "left-pitch-rod-joint.y", "left-pitch-rod-joint.z"],
        "left-plantar-foot-joint": ["left-plantar-foot-joint.x", "left-plantar-foot-joint.y"],
        "right-pitch-rod-joint": ["right-pitch-rod-joint.x", "right-pitch-rod-joint.y", "right-pitch-rod-joint.z"],
        "right-plantar-foot-joint": ["right-plantar-foot-joint.x", "right-plantar-foot-joint.y"]}
    assert system.degrees_of_freedom == 22 - 20 == 2
    names = [row.name for row in system.constraints]
    t = np.linspace(0, 0.1, 5)
    figure["plot"](t, {name: np.full(t.size, float(k)) for k, name in enumerate(names)}, system,
                   tmp_path / "loops.png", xlabel="time [s]", title="test")
    assert (tmp_path / "loops.png").stat().st_size > 10_000


def spring_balances(figure, model, q, lam, foot_force=0.0):
    """For each leg and each joint of :data:`BEYOND`: ``(leg, joint, moment, spring, scale)``, the moment
    about the joint's axis of the loop's force on the Achilles rod (``lam`` by ``constraint_names``,
    components in the loop's frame), of the weights of the links beyond the joint and of an upward
    ``foot_force`` (N) at the foot's centre of mass if the foot is beyond, the spring's torque
    ``k theta`` there (0: no spring), and the size of the loop force's moment."""
    system, constraint_names = model.equations.system, list(model.constraint_names)
    robot = system.robot
    sdf = ET.parse(figure["cassie_file"]()).getroot().find("model")
    joints = {joint.name: joint for joint in robot.joints}
    coordinates = [x.name for x in system.coordinates]
    gravity = np.array([0.0, 0.0, -robot.values["g"]])
    loops = {side: next(loop for loop in robot.loops if loop.joint == f"{side}-pitch-rod-joint")
             for side in figure["legs_of"](system)}
    expressions = {}
    for side, loop in loops.items():
        hip = robot.frames[loop.frame]
        pose = sdf.find(f"joint[@name='{loop.joint}']/pose")  # SDFormat 1.6: in the child link's (hip pitch) frame
        expressions[f"{side} ball"] = hip.point([float(x) for x in pose.text.split()[:3]])
        expressions[f"{side} hip"] = hip.rotation
        for joint in BEYOND:
            frame = robot.frames[joints[f"{side}-{joint}"].child]
            expressions[f"{side}-{joint} origin"], expressions[f"{side}-{joint} rotation"] = frame.origin, frame.rotation
        for link in {link for beyond in BEYOND.values() for link in beyond}:
            expressions[f"{side}-{link}"] = system.body(f"{side}-{link}").position
    at = model.evaluate_expressions("spring balances", lambda: {name: sp.Matrix(value) for name, value in
                                                               expressions.items()}, q)
    balances = []
    for side, loop in loops.items():
        ball = at[f"{side} ball"].ravel()
        force = at[f"{side} hip"] @ np.array([lam[constraint_names.index(row)] for row in loop.rows])
        for joint, beyond in BEYOND.items():
            spec = joints[f"{side}-{joint}"]
            pivot = at[f"{side}-{joint} origin"].ravel()
            axis = at[f"{side}-{joint} rotation"] @ np.array(spec.axis)
            moment = np.cross(ball - pivot, force)
            scale = float(np.linalg.norm(moment))
            for link in beyond:
                mass = float(system.body(f"{side}-{link}").mass)
                load = mass * gravity + (np.array([0.0, 0.0, foot_force]) if link == "foot" else 0.0)
                moment += np.cross(at[f"{side}-{link}"].ravel() - pivot, load)
            spring = figure["SPRINGS"].get(joint, 0.0) * q[coordinates.index(spec.coordinate)]
            balances.append((side, joint, float(axis @ moment), spring, scale))
    return balances


@pytest.mark.slow
def test_achilles_rod_reactions_hold_the_springs_at_rest(figure):
    """The figure's model (the left leg pushed up at the foot by ``FOOT_LOAD * t``; ~1 min: derive and C
    build), at rest on its springs at t = 0 (no push) and t = 1 (the full push, 300 N): the loop force
    on the Achilles rod (the multipliers ``left-pitch-rod-joint.x .y .z``, components in the hip-pitch
    link's frame), with the weights of the links beyond and the push, gives about the heel spring's
    and the knee spring's axes the moment ``k theta`` of the spring (file stiffness, deflection at
    rest), and none about the rod's own hinge; to 1e-8 of the loop force's moment."""
    system = figure["cassie_on_stand"](figure["cassie_file"](), legs=figure["FIGURE_LEGS"],
                                       foot_load=figure["FOOT_LOAD"])
    model = kronlag.derive(system).numeric(system.robot.values)
    q = None
    for t in (0.0, 1.0):
        q, rest = figure["static_equilibrium"](model, system, t=t, guess=q)
        assert np.max(np.abs(rest.qdd)) < 1e-8
        balances = spring_balances(figure, model, q, rest.lam, foot_force=figure["FOOT_LOAD"] * t)
        assert [(side, joint) for side, joint, *_ in balances] == [("left", joint) for joint in BEYOND]
        for side, joint, moment, spring, scale in balances:
            assert moment == pytest.approx(spring, abs=1e-8 * scale), (t, joint)
            if joint in figure["SPRINGS"]:
                assert abs(spring) > 1.0, (t, joint)  # N m: the spring is loaded, the check is not 0 = 0
