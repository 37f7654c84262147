"""Recursive M and h in the dynamics kernel of robot trees (kronlag.numeric.codegen.recursive):
which Systems get them (and which keep the flat kernel, with the reason), their values against the
flat kernel of the same equations and against Pinocchio (crba, nonLinearEffects, aba) on
example-robot-data's arms (skipped without pin and example-robot-data)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import example_robot, robots_bench

import kronlag
from kronlag.core.kernels import (
    SCALAR_NAMESPACE,
    cse_kernel,
    python_functions,
    python_source,
)
from kronlag.model.robot_formats import RobotFileWarning
from kronlag.numeric.codegen import LAYOUTS, KernelSource
from kronlag.numeric.codegen.recursive import dynamics_algorithm

#: A tree with what the recursion must take: a general (non-principal) revolute axis, rpy angles that
#: are not multiples of pi/2, a continuous joint, a prismatic joint, links merged by fixed joints (one
#: carrying mass), a massless link between two joints, two branches and a mimic joint.
TREE = """<?xml version="1.0"?>
<robot name="tree">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0.1 0.02 0.3" rpy="0.2 0 0.1"/><mass value="2.0"/>
    <inertia ixx="0.05" ixy="0.001" ixz="0.002" iyy="0.04" iyz="0.003" izz="0.03"/></inertial></link>
  <link name="a_tip"><inertial><origin xyz="0 0 0.05"/><mass value="0.3"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="hub"/>
  <link name="b"><inertial><origin xyz="0.2 -0.01 0"/><mass value="1.2"/>
    <inertia ixx="0.01" ixy="0" ixz="0.001" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <link name="slider"><inertial><origin xyz="0 0.03 0.01"/><mass value="0.4"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.002"/></inertial></link>
  <link name="finger"><inertial><origin xyz="0.01 0 0.02"/><mass value="0.1"/>
    <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.1" rpy="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="tip" type="fixed"><parent link="a"/><child link="a_tip"/><origin xyz="0 0 0.4" rpy="0.4 0 0"/></joint>
  <joint name="j2" type="revolute"><parent link="a_tip"/><child link="hub"/>
    <origin xyz="0 0 0.1" rpy="1.5707963267948966 0 0"/><axis xyz="0.6 0 0.8"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="j3" type="continuous"><parent link="hub"/><child link="b"/>
    <origin xyz="0.05 0 0" rpy="0 0.7 0"/><axis xyz="0 1 0"/></joint>
  <joint name="j4" type="prismatic"><parent link="b"/><child link="slider"/>
    <origin xyz="0.3 0 0" rpy="0.1 0.2 0.3"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="j5" type="prismatic"><parent link="a"/><child link="finger"/>
    <origin xyz="0 0.1 0.2"/><axis xyz="0 0 -1"/><limit lower="-3" upper="3" effort="10" velocity="2"/><mimic joint="j4" multiplier="0.5" offset="0.01"/></joint>
</robot>
"""


def load(path, **options) -> kronlag.System:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotFileWarning)
        return kronlag.load_urdf(path, **options)


@pytest.fixture
def tree(tmp_path) -> Path:
    path = tmp_path / "tree.urdf"
    path.write_text(TREE)
    return path


def flat_and_recursive(equations: kronlag.Equations):
    """The dynamics kernel of ``equations`` as KernelSource makes it and as the flat derivation's
    matrices make it (one symengine.cse over them), both as Python functions of (t, q, qd, p)."""
    source = KernelSource(equations)
    chosen = source.kernel("dynamics")
    names = LAYOUTS["dynamics"]
    assert [block.name for block in chosen.blocks] == list(names)
    flat = cse_kernel("dynamics", chosen.blocks, [source.matrix(name) for name in names], source.convert.constants)
    kernels = {"recursive": chosen, "flat": flat}
    return {key: (kernel, python_functions(python_source(kernel), ["dynamics"], SCALAR_NAMESPACE)["dynamics"])
            for key, kernel in kernels.items()}


def operations(kernel) -> int:
    import symengine as se

    return sum(se.count_ops(expr) for _, expr in kernel.temporaries) + sum(se.count_ops(e) for e in kernel.outputs)


def assert_same_dynamics(equations: kronlag.Equations, *, states: int = 4, seed: int = 0) -> dict:
    functions = flat_and_recursive(equations)
    rng = np.random.default_rng(seed)
    m = equations.shape[0]
    for _ in range(states):
        q, qd = rng.uniform(-1.5, 1.5, m).tolist(), rng.uniform(-2, 2, m).tolist()
        p = rng.uniform(0.5, 10, len(equations.parameters)).tolist()
        t = float(rng.uniform(0, 1))
        ours, theirs = (np.array(functions[key][1](t, q, qd, p)) for key in ("recursive", "flat"))
        assert np.abs(ours - theirs).max() <= 1e-12 * max(1.0, np.abs(theirs).max())
    return {key: kernel for key, (kernel, _) in functions.items()}


# -- which Systems get the recursive kernel ------------------------------------------------------------

def test_a_tree_read_in_joint_coordinates_is_recursive(tree):
    assert dynamics_algorithm(load(tree)) == "recursive"


def test_recursive_kernel_equals_the_flat_one(tree):
    system = load(tree)
    kernels = assert_same_dynamics(kronlag.derive(system))
    assert operations(kernels["recursive"]) < operations(kernels["flat"])


def test_loads_added_after_reading_stay_in_h(tree):
    """A potential (its gradient joins h) and a generalized force added to the System keep the
    recursive kernel; the values stay those of the derivation."""
    system = load(tree)
    system.add_potential(3 * sp.Symbol("j2") ** 2 + sp.cos(sp.Symbol("j3")), name="springs")
    system.add_generalized_force([0, 0, -0.1 * system.speeds[2], 0, 0], name="damper")
    assert dynamics_algorithm(system) == "recursive"
    assert_same_dynamics(kronlag.derive(system))


def test_other_systems_keep_the_flat_kernel(tree):
    """The choice is explicit: anything the recursion does not take keeps the derivation's M and h."""
    assert dynamics_algorithm(load(tree, floating_base=True)).startswith("flat: joints the recursion does not take")
    massive = tree.with_name("massive.urdf")  # absolute coordinates need every moving link to carry mass
    massive.write_text(TREE.replace('<link name="hub"/>', '<link name="hub"><inertial><mass value="0.2"/><inertia '
                                    'ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>'))
    assert dynamics_algorithm(load(massive)) == "recursive"
    assert dynamics_algorithm(load(massive, coordinates="absolute")).startswith("flat: not in the joint coordinates")
    extended = load(tree)
    extended.add_body(kronlag.RigidBody("payload", mass=1.0, inertia=sp.eye(3) * 0.01, position=(0, 0, 0),
                                        rotation=sp.eye(3)))
    assert dynamics_algorithm(extended) == "flat: its bodies are not those the reader made"
    q = sp.Symbol("q")
    hand_built = kronlag.System([q], gravity=(0, 0, -9.81))
    assert dynamics_algorithm(hand_built) == "flat: not read from a robot file"


def test_the_flat_kernel_is_kept_where_the_recursion_does_not_apply(tree):
    """A System that does not qualify gets exactly the flat kernel."""
    system = load(tree)
    system.add_body(kronlag.RigidBody("payload", mass=1.0, inertia=sp.eye(3) * 0.01, position=(0, 0, 0),
                                      rotation=sp.eye(3)))
    kernels = assert_same_dynamics(kronlag.derive(system), states=1)
    assert kernels["recursive"] == kernels["flat"]


# -- the arms of example-robot-data against Pinocchio ---------------------------------------------------

ARMS = ("ur5", "panda", "xarm7", "so100", "z1", "kinova")


@pytest.mark.slow
@pytest.mark.parametrize("name", ARMS)
def test_arms_recursive_kernel_agrees_with_flat_and_pinocchio(name):
    """M and h of the dynamics kernel (Python backend) against the flat kernel to 1e-12 and against
    Pinocchio's crba and nonLinearEffects (M, tau - nle) and the accelerations against aba (the
    Panda's mimic finger: the exact constrained solution from Pinocchio's M and nle) to 1e-9."""
    bench = robots_bench()
    path = example_robot(bench.ROBOTS[name])
    system = load(path)
    assert dynamics_algorithm(system) == "recursive"
    equations = kronlag.derive(system)
    assert_same_dynamics(equations, states=2)
    rng = np.random.default_rng(5)
    moving = [joint for joint in system.robot.joints if joint.coordinate]
    tau = np.array([rng.uniform(-1, 1) if joint.torque else 0.0 for joint in moving])
    values = {**system.robot.values, **{joint.torque: value for joint, value in zip(moving, tau) if joint.torque}}
    model = equations.numeric(values, backend="python")
    reference = bench.PinocchioReference(path, system)
    m = len(system.coordinates)
    for _ in range(3):
        q = bench.on_mimics(system, rng.uniform(-1.5, 1.5, m))
        qd = bench.on_mimics(system, rng.uniform(-2, 2, m), speeds=True)
        terms, theirs = model.dynamics_terms(q, qd), reference.terms(q, qd, tau)
        expected_h = tau - theirs["g"] - theirs["Cqd"]
        for ours, expected in ((terms["M"], theirs["M"]), (terms["h"], expected_h)):
            assert np.abs(ours - expected).max() <= 1e-9 * max(1.0, np.abs(expected).max())
        qdd = model.forward_dynamics(q, qd).qdd
        expected_qdd = theirs["aba"] if not system.constraints else bench.constrained_accelerations(
            theirs["M"], expected_h, model.Phi_q(q))
        assert np.abs(qdd - expected_qdd).max() <= 1e-9 * max(1.0, np.abs(expected_qdd).max())


@pytest.mark.slow
def test_c_backend_runs_the_recursive_kernel():
    """The C library of a robot (UR5) prints the recursive kernel unchanged: same values as Python."""
    system = load(example_robot(robots_bench().ROBOTS["ur5"]))
    equations = kronlag.derive(system)
    values = dict(system.robot.values)
    compiled, interpreted = (equations.numeric(values, backend=backend) for backend in ("c", "python"))
    rng = np.random.default_rng(2)
    for _ in range(3):
        q, qd = rng.uniform(-1.5, 1.5, 6), rng.uniform(-2, 2, 6)
        ours, theirs = compiled.dynamics_terms(q, qd), interpreted.dynamics_terms(q, qd)
        for key in ("M", "h"):
            assert np.allclose(ours[key], theirs[key], rtol=1e-13, atol=1e-13)


def test_tree_agrees_with_pinocchio(tree):
    """The tree's M and h (general axis, prismatic and mimic joints, merged and massless links) against
    Pinocchio's crba and nonLinearEffects on the same file."""
    pytest.importorskip("pinocchio")
    bench = robots_bench()
    system = load(tree)
    moving = [joint for joint in system.robot.joints if joint.coordinate]
    rng = np.random.default_rng(8)
    tau = np.array([rng.uniform(-1, 1) if joint.torque else 0.0 for joint in moving])
    values = {**system.robot.values, **{joint.torque: value for joint, value in zip(moving, tau) if joint.torque}}
    model = kronlag.derive(system).numeric(values, backend="python")
    reference = bench.PinocchioReference(tree, system)
    for _ in range(3):
        q = bench.on_mimics(system, rng.uniform(-1.5, 1.5, len(moving)))
        qd = bench.on_mimics(system, rng.uniform(-2, 2, len(moving)), speeds=True)
        terms, theirs = model.dynamics_terms(q, qd), reference.terms(q, qd, tau)
        for ours, expected in ((terms["M"], theirs["M"]), (terms["h"], tau - theirs["g"] - theirs["Cqd"])):
            assert np.abs(ours - expected).max() <= 1e-9 * max(1.0, np.abs(expected).max())
