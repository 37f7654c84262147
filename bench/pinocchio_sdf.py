"""Pinocchio's model of an SDFormat 1.6 model with closed loops, built here from the file: pip's
Pinocchio has no SDF reader, and kronlag's own reader must not be the reference it is tested against.

:func:`build` reads the file with :mod:`xml.etree` (a trusted package file: Cassie of
example-robot-data) as SDFormat 1.6 says: a ``<link>``'s ``<pose>`` is in the model frame, a
``<joint>``'s in its child link's frame, a joint axis in the joint frame, an ``<inertial>``'s pose in
its link's frame.  The first joint naming a link as its child places it in the tree (a
``revolute`` joint: ``JointModelRevoluteUnaligned``; the root link, which no joint fixes to the
world: a free flyer ``"root_joint"`` at its pose; joints added depth first, siblings in file order,
as Pinocchio's algorithms need); a ``ball`` joint whose child is already in the
tree closes a loop: a ``RigidConstraintModel`` of type ``CONTACT_3D`` between the joint's origin
on its parent link and on its child link (the two points stay together).

:func:`constrained_accelerations` calls ``pin.constraintDynamics`` with proximal settings: Cassie's
loops give 12 contact rows of rank 10 at most (the left foot's loop is planar: its out-of-plane row
is identically zero; the right foot's is planar to ~7e-8 rad), which the proximal iterations handle.
:func:`compare_constrained` compares kronlag's numeric model with it at assembled states.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from bench_robots import FloatingReference, relative_difference  # bench/ on the path (a test puts it there)

#: The floating joint's name (Pinocchio's and kronlag's).
ROOT_JOINT = "root_joint"


def pose_matrix(text: str | None) -> np.ndarray:
    """The 4x4 transform of an SDF ``<pose>`` ``x y z roll pitch yaw`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    x, y, z, roll, pitch, yaw = (float(v) for v in (text or "0 0 0 0 0 0").split())
    c, s = np.cos([roll, pitch, yaw]), np.sin([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    result = np.eye(4)
    result[:3, :3], result[:3, 3] = rz @ ry @ rx, (x, y, z)
    return result


@dataclass
class SdfModel:
    """Pinocchio's model, its data, the loop constraints (named after their SDF joints) and theirs,
    and the joint that moves each link (its joint frame is the link's frame in kronlag's reader)."""

    model: object
    data: object
    constraints: list
    constraint_datas: list
    loops: list[str]
    joint_of_link: dict[str, int]


def build(path: Path) -> SdfModel:
    """Pinocchio's model of the first ``<model>`` of the SDFormat 1.6 file ``path`` (see the module
    docstring): revolute tree joints, a free-flyer root, ball-joint loop closures as 3-D contacts."""
    import pinocchio as pin

    element = ElementTree.parse(path).getroot().find("model")
    links = {link.get("name"): link for link in element.findall("link")}
    link_pose = {name: pose_matrix(link.findtext("pose")) for name, link in links.items()}
    tree, loops = {}, []
    for joint in element.findall("joint"):
        child = joint.findtext("child").strip()
        if child in tree:
            if joint.get("type") != "ball":
                raise NotImplementedError(f"loop joint {joint.get('name')}: only ball joints close loops here")
            loops.append(joint)
        else:
            if joint.get("type") != "revolute":
                raise NotImplementedError(f"tree joint {joint.get('name')}: only revolute joints here")
            tree[child] = joint
    (root,) = [name for name in links if name not in tree]
    frame = {root: link_pose[root]}  # each link's joint frame in the model frame
    model = pin.Model()
    joint_id = {root: model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3(frame[root]), ROOT_JOINT)}
    children: dict[str, list[str]] = {name: [] for name in links}
    for child, joint in tree.items():
        children[joint.findtext("parent").strip()].append(child)
    stack = list(reversed(children[root]))
    while stack:  # depth first: Pinocchio's algorithms need each subtree's speeds contiguous
        child = stack.pop()
        joint = tree[child]
        parent = joint.findtext("parent").strip()
        frame[child] = link_pose[child] @ pose_matrix(joint.findtext("pose"))
        axis = np.array([float(v) for v in joint.find("axis").findtext("xyz").split()])
        joint_id[child] = model.addJoint(joint_id[parent], pin.JointModelRevoluteUnaligned(axis / np.linalg.norm(axis)),
                                         pin.SE3(np.linalg.inv(frame[parent]) @ frame[child]), joint.get("name"))
        stack.extend(reversed(children[child]))
    for name, link in links.items():
        inertial = link.find("inertial")
        tensor = inertial.find("inertia")
        xx, xy, xz, yy, yz, zz = (float(tensor.findtext(key, "0")) for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
        placed = np.linalg.inv(frame[name]) @ link_pose[name] @ pose_matrix(inertial.findtext("pose"))
        rotation = placed[:3, :3]
        inertia = rotation @ np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) @ rotation.T
        model.appendBodyToJoint(joint_id[name], pin.Inertia(float(inertial.findtext("mass")), placed[:3, 3], inertia),
                                pin.SE3.Identity())
    constraints = []
    for joint in loops:
        parent, child = joint.findtext("parent").strip(), joint.findtext("child").strip()
        at = link_pose[child] @ pose_matrix(joint.findtext("pose"))
        constraint = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model,
                                              joint_id[parent], pin.SE3(np.linalg.inv(frame[parent]) @ at),
                                              joint_id[child], pin.SE3(np.linalg.inv(frame[child]) @ at),
                                              pin.ReferenceFrame.LOCAL)
        constraint.name = joint.get("name")
        constraints.append(constraint)
    data = model.createData()
    models = pin.StdVec_RigidConstraintModel()
    datas = pin.StdVec_RigidConstraintData()
    for constraint in constraints:
        models.append(constraint)
        datas.append(constraint.createData())
    pin.initConstraintDynamics(model, data, models, datas)
    return SdfModel(model, data, models, datas, [joint.get("name") for joint in loops], joint_id)


def loop_gaps(reference: SdfModel, q: np.ndarray) -> np.ndarray:
    """Each loop's gap (child point - parent point, world frame) at Pinocchio's ``q``, shape (loops, 3)."""
    import pinocchio as pin

    model, data = reference.model, reference.data
    pin.forwardKinematics(model, data, q)
    return np.array([(data.oMi[c.joint2_id] * c.joint2_placement).translation
                     - (data.oMi[c.joint1_id] * c.joint1_placement).translation for c in reference.constraints])


def constrained_accelerations(reference: SdfModel, q: np.ndarray, v: np.ndarray, tau: np.ndarray, *,
                              mu: float = 1e-4, iterations: int = 200, accuracy: float = 1e-13) -> np.ndarray:
    """``pin.constraintDynamics`` at ``(q, v, tau)`` with proximal settings (redundant rows are fine)."""
    import pinocchio as pin

    settings = pin.ProximalSettings(accuracy, mu, iterations)
    return pin.constraintDynamics(reference.model, reference.data, q, v, tau, reference.constraints,
                                  reference.constraint_datas, settings).copy()


def compare_constrained(path: Path, system, model, values: dict, *, states: int = 3, seed: int = 5,
                        held: tuple[str, ...] = (), dependent: tuple[str, ...] = (),
                        spread: float = 0.3) -> list[dict[str, float]]:
    """kronlag's ``model`` of the SDF ``path`` against :func:`build`'s Pinocchio model at ``states``
    random assembled states: the relative differences (:func:`bench_robots.relative_difference`) of
    ``M``, ``g``, ``C qd`` (``crba``, ``computeGeneralizedGravity``, ``nonLinearEffects``, mapped by
    :class:`bench_robots.FloatingReference`), of the accelerations (``constraintDynamics``) and of each
    loop's reaction (``"force <joint>"``: kronlag's multipliers of the loop's rows, components in the
    loop's frame, ``system.robot.loops``, against Pinocchio's ``contact_force`` turned from its contact
    frame to that frame; the force on the parent link), and ``"gap"``, the largest loop gap of
    Pinocchio's model at kronlag's assembled positions (m).  A redundant loop's reaction is unique
    only along its independent rows: the rows ``dependent`` are left out.

    The states: the reference pose with every coordinate moved by up to ``spread`` (a random unit
    quaternion for the base), random speeds, assembled by ``model.assemble`` (positions and speeds
    on the constraints) with the joints ``held`` at the reference pose and at rest.
    """
    peer = build(path)
    reference = FloatingReference(path, system, model=peer.model)
    rng = np.random.default_rng(seed)
    names = [q.name for q in system.coordinates]
    m = len(names)
    q_reference = np.array([system.robot.q_reference[name] for name in names])
    fixed = {system.robot.joint(joint).coordinate: 0.0 for joint in held}
    tau = reference.tau(system, values)
    loops = {loop.joint: loop for loop in system.robot.loops}
    results = []
    for _ in range(states):
        guess = q_reference + rng.uniform(-spread, spread, m)
        guess[reference.base[3:]] = rng.normal(size=4)
        guess[reference.base[3:]] /= np.linalg.norm(guess[reference.base[3:]])
        q, qd = model.assemble(guess, fixed=fixed, qd_guess=rng.uniform(-1, 1, m), qd_fixed=fixed)
        v, pq = reference.v(q, qd), reference.q(q)
        result = dict(reference.compare(model, q, v, None), gap=float(np.abs(loop_gaps(peer, pq)).max()))
        solution = model.forward_dynamics(q, qd)
        result["qdd"] = relative_difference(reference.accelerations(q, v, solution.qdd),
                                            constrained_accelerations(peer, pq, v, tau))
        multipliers = dict(zip(model.constraint_names, solution.lam))
        for constraint, data in zip(peer.constraints, peer.constraint_datas):
            loop = loops[constraint.name]
            frame = peer.data.oMi[peer.joint_of_link[loop.frame]].rotation
            theirs = dict(zip("xyz", frame.T @ data.oMc1.rotation @ data.contact_force.linear))
            rows = [row for row in loop.rows if row not in dependent]
            result[f"force {loop.joint}"] = relative_difference(
                np.array([multipliers[row] for row in rows]), np.array([theirs[row.rsplit(".", 1)[1]] for row in rows]))
        results.append(result)
    return results
