"""Cassie's constrained forward dynamics against Pinocchio (issue 21, item 5): example-robot-data's
``cassie_v2.sdf`` read by ``kronlag.load_sdf`` and by an SDF 1.6 builder of Pinocchio's model written
for the test (``bench/pinocchio_sdf.py``: revolute tree joints, a free-flyer pelvis, the four
ball-joint loop closures as 3-D contact constraints).  Skipped without pin and example-robot-data."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import kronlag
from kronlag.model.robot_formats import RobotFileWarning

BENCH = Path(__file__).resolve().parents[1] / "bench"

#: The right foot's loop is planar only to ~7e-8 rad: its out-of-plane row is nearly dependent, and
#: the rank policy counts it dependent (mobility 18).  Away from the file's pose its out-of-plane
#: residual could only be closed exactly by locking the foot, so the states keep that loop's three
#: joints at the reference pose (assembled, at rest) while everything else moves.
RIGHT_FOOT_LOOP = ("right-tarsus-crank-joint", "right-crank-rod-joint", "right-foot-op")


@pytest.fixture
def peers(monkeypatch):
    pytest.importorskip("pinocchio")
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_robots
    import pinocchio_sdf

    folder = bench_robots.robots_folder()
    if folder is None:
        pytest.skip("example-robot-data is not installed")
    return bench_robots, pinocchio_sdf, folder / bench_robots.CASSIE


def test_pinocchio_model_of_the_sdf_closes_the_loops(peers):
    """The builder's model (independent of kronlag's reader): 29 q, 28 v, four 3-D loop contacts
    whose points coincide at the file's pose; free fall with no torque."""
    _, pinocchio_sdf, path = peers
    import pinocchio as pin

    peer = pinocchio_sdf.build(path)
    assert (peer.model.nq, peer.model.nv) == (29, 28)
    assert peer.loops == ["left-pitch-rod-joint", "right-pitch-rod-joint", "right-plantar-foot-joint",
                          "left-plantar-foot-joint"]
    q = pin.neutral(peer.model)
    assert np.abs(pinocchio_sdf.loop_gaps(peer, q)).max() < 1e-15
    a = pinocchio_sdf.constrained_accelerations(peer, q, np.zeros(28), np.zeros(28))
    assert np.allclose(a[:6], [0, 0, -9.81, 0, 0, 0], atol=1e-12)


@pytest.mark.slow
def test_cassie_constrained_dynamics_agree_with_pinocchio(peers):
    """At three random assembled states (every joint but the right foot's loop moved up to 0.3 rad,
    a random base orientation, random speeds on the constraints, random joint torques): kronlag's
    loops close Pinocchio's (gap <= 1e-12 m); M, g and C qd agree with crba, computeGeneralizedGravity
    and nonLinearEffects, kronlag's forward dynamics with constraintDynamics (proximal, mu = 1e-4),
    and the loop reactions (kronlag's named multipliers, components in each loop's frame) with
    Pinocchio's contact forces, all to <= 1e-9 relative (measured: ~1e-11).  A redundant loop's
    reaction is unique only along its independent rows: the feet's out-of-plane components are not
    compared (the left foot's row is dropped, the right foot's counted dependent).  The build takes
    ~20 s of CPU (the Python backend: load ~6 s, derive ~2 s, kernels ~8 s)."""
    bench_robots, pinocchio_sdf, path = peers
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        system = kronlag.load_sdf(path)
    assert [(loop.joint, loop.frame, len(loop.rows)) for loop in system.robot.loops] == [
        ("left-pitch-rod-joint", "left-hip-pitch", 3), ("right-pitch-rod-joint", "right-hip-pitch", 3),
        ("right-plantar-foot-joint", "right-tarsus", 3), ("left-plantar-foot-joint", "left-tarsus", 2)]
    rng = np.random.default_rng(21)
    values = {**system.robot.values, **{joint.torque: rng.uniform(-5, 5) for joint in system.robot.joints
                                        if joint.torque}}
    model = kronlag.derive(system).numeric(values, backend="python")
    with pytest.warns(kronlag.RedundantConstraintsWarning, match="rank 11 < 12"):
        results = pinocchio_sdf.compare_constrained(path, system, model, values, held=RIGHT_FOOT_LOOP,
                                                    dependent=("right-plantar-foot-joint.z",))
    for result in results:
        assert result.pop("gap") <= 1e-12, result
        assert max(result.values()) <= 1e-9, result
