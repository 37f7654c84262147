#!/usr/bin/env python3
"""Robots from example-robot-data read with ``kronlag.load_urdf``: derive + build time, agreement
with Pinocchio and forward-dynamics time against ``pin.aba``, in one run.

Run by hand (needs ``pip install pin example-robot-data``)::

    python3 bench/bench_robots.py                 # every robot of ROBOTS
    python3 bench/bench_robots.py panda ur5       # some of them
    python3 bench/bench_robots.py --quick         # 100 times fewer timed calls
    python3 bench/bench_robots.py --json -        # also write bench/results/bench_robots.json

For each robot: the System is loaded from the URDF as shipped, derived and compiled (times
printed); Pinocchio's model is built from the same file (``buildModelFromUrdf``, mimic joints as
ordinary joints).  At random states (joint values in [-1.5, 1.5], speeds in [-2, 2]) kronlag's
``M``, ``g`` and ``C qd`` are compared with ``crba``, ``computeGeneralizedGravity`` and
``nonLinearEffects - g``, and its forward dynamics with ``aba`` (with a mimic joint: with the
exact solution of ``M qdd + Phi_q^T lambda = tau - nle``, ``Phi_q qdd = 0`` built from
Pinocchio's M and nle).  Continuous joints have Pinocchio coordinates ``(cos q, sin q)``.  The
relative difference is ``max |kronlag - pinocchio| / max(1, max |pinocchio|)`` over the states.

Floating-base robots (``FLOATING``: Solo 12, A1, Go2, Talos) are read with ``floating_base=True``
and compared with Pinocchio's free flyer (:class:`FloatingReference` documents the map of the
coordinates); Cassie's SDF row gives its loops' ranks and mobility at the reference pose and its
constrained dynamics against ``pin.constraintDynamics`` on a Pinocchio model built from the file
(``bench/pinocchio_sdf.py``; FD timed against ``constraintDynamics``, no target).  Cassie's load +
derive + build has the humanoids' target.

With ``pip install mujoco`` two MJCF rows follow (``tests/robot_files``): the spatial arm
``arm.xml`` read with ``kronlag.load_mjcf`` against ``mj_fullM`` and ``qfrc_bias`` (FD timed
against ``mj_forward``, which does more: collisions, sensors), and the four-bar ``four_bar.xml``
closed by a ``connect``: kronlag's exact accelerations against MuJoCo's soft closure (the
difference printed is MuJoCo's error; the tests check kronlag against a hand-built four-bar).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import sys
import time
import timeit
from pathlib import Path

import numpy as np

import kronlag

#: Issues 19 and 21: load + derive + build at most this (s) per robot (Talos-size humanoids: the second);
#: FD at most this fraction of ``aba`` on the arms (the fixed-base robots; floating bases for information).
TARGET_BUILD_S = 5.0
TARGET_BUILD_HUMANOID_S = 20.0
TARGET_RATIO = 0.8
HUMANOIDS = {"talos", "cassie_v2.sdf"}

#: name -> path under example-robot-data's robots folder
ROBOTS = {
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",
    "double_pendulum": "double_pendulum_description/urdf/double_pendulum.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "ur3": "ur_description/urdf/ur3_robot.urdf",
}

#: Floating-base robots: read with ``load_urdf(path, floating_base=True)``, against Pinocchio's
#: ``buildModelFromUrdf(path, JointModelFreeFlyer())`` (:class:`FloatingReference`).
FLOATING = {
    "solo12": "solo_description/robots/solo12.urdf",
    "a1": "a1_description/urdf/a1.urdf",
    "go2": "go2_description/urdf/go2.urdf",
    "talos": "talos_data/robots/talos_reduced.urdf",
}


def robots_folder() -> Path | None:
    """example-robot-data's ``robots`` folder (the pip package installs it under ``cmeel.prefix``), or None."""
    try:
        distribution = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    folder = Path(str(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    return folder if folder.is_dir() else None


class PinocchioReference:
    """Pinocchio's model of a URDF and the map from kronlag's joint coordinates to its q and v."""

    def __init__(self, path: Path, system: kronlag.System):
        import pinocchio as pin

        self.pin = pin
        self.model = pin.buildModelFromUrdf(str(path))
        self.data = self.model.createData()
        self.slots = []  # (q index, v index, nq) per kronlag coordinate
        by_coordinate = {joint.coordinate: joint.name for joint in system.robot.joints if joint.coordinate}
        for coordinate in system.coordinates:
            joint = self.model.joints[self.model.getJointId(by_coordinate[coordinate.name])]
            self.slots.append((joint.idx_q, joint.idx_v, joint.nq))
        if sorted(slot[1] for slot in self.slots) != list(range(self.model.nv)):
            raise RuntimeError(f"{path}: the joints of kronlag and Pinocchio do not match")

    def q(self, q: np.ndarray) -> np.ndarray:
        result = np.zeros(self.model.nq)
        for value, (iq, _, nq) in zip(q, self.slots):
            result[iq:iq + nq] = (np.cos(value), np.sin(value)) if nq == 2 else value
        return result

    def v(self, qd: np.ndarray) -> np.ndarray:
        result = np.zeros(self.model.nv)
        result[[slot[1] for slot in self.slots]] = qd
        return result

    def back(self, vector: np.ndarray) -> np.ndarray:
        """A v-indexed vector (or matrix) in kronlag's coordinate order."""
        index = [slot[1] for slot in self.slots]
        return vector[np.ix_(index, index)] if vector.ndim == 2 else vector[index]

    def terms(self, q, qd, tau) -> dict[str, np.ndarray]:
        pin, model, data = self.pin, self.model, self.data
        pq, pv, ptau = self.q(q), self.v(qd), self.v(tau)
        mass = pin.crba(model, data, pq)
        mass = np.triu(mass) + np.triu(mass, 1).T
        gravity = pin.computeGeneralizedGravity(model, data, pq).copy()
        bias = pin.nonLinearEffects(model, data, pq, pv).copy()
        return {"M": self.back(mass), "g": self.back(gravity), "Cqd": self.back(bias - gravity),
                "aba": self.back(pin.aba(model, data, pq, pv, ptau).copy())}


class FloatingReference:
    """Pinocchio's free-flyer model of a URDF (or ``model``, built otherwise: the SDF of
    :mod:`pinocchio_sdf`) and the map from kronlag's coordinates to its q and v.

    kronlag's floating base has the coordinates ``p`` (the root link's origin in the world) and the
    Euler parameters ``e = (e0, e1, e2, e3)``; Pinocchio's free flyer ``q = (p, x y z w)`` with the
    quaternion ``(e1, e2, e3, e0)`` and ``v = (R^T pd, omega)``, both in the base frame, where
    ``omega = 2 G(e) ed`` (:func:`kronlag.model.rotations.euler_parameter_rates`).  On the constraint
    manifold (``|e| = 1``, ``e . ed = 0``) kronlag's speeds are ``qd = S v`` with
    ``S = diag(R, G^T / 2, I)`` (``G G^T = I``), so the kinetic energy gives ``M_pin = S^T M S``, the
    generalized forces ``g_pin = S^T g`` and ``C_pin v = S^T (M Sd v + C qd)`` with ``Sd v =
    (R [omega]x v_lin, G(ed)^T omega / 2, 0)``; the accelerations map back as ``a_lin = R^T pdd -
    omega x v_lin``, ``omega_d = 2 G(e) edd`` (``G(ed) ed = 0``).  The rows of kronlag's ``S^T``
    annihilate the normalization constraint's gradient ``2 e``, so its multiplier does not enter.
    """

    def __init__(self, path: Path, system: kronlag.System, model=None):
        import pinocchio as pin

        self.pin = pin
        self.model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if model is None else model
        self.data = self.model.createData()
        base = system.robot.joint("root_joint").coordinates
        index = {q.name: k for k, q in enumerate(system.coordinates)}
        self.base = [index[name] for name in base]
        self.slots = []  # (kronlag index, pinocchio q index, v index, nq) per joint coordinate
        for joint in system.robot.joints:
            if joint.coordinate and joint.name != "root_joint":
                peer = self.model.joints[self.model.getJointId(joint.name)]
                self.slots.append((index[joint.coordinate], peer.idx_q, peer.idx_v, peer.nq))
        if sorted(slot[2] for slot in self.slots) != list(range(6, self.model.nv)):
            raise RuntimeError(f"{path}: the joints of kronlag and Pinocchio do not match")

    def random_state(self, rng, m: int) -> tuple[np.ndarray, np.ndarray]:
        """kronlag's ``q`` (a random unit e) and Pinocchio's ``v`` (random)."""
        q = rng.uniform(-1.5, 1.5, m)
        e = rng.normal(size=4)
        q[self.base[3:]] = e / np.linalg.norm(e)
        return q, rng.uniform(-2, 2, self.model.nv)

    def _rotation(self, q):
        e0, e1, e2, e3 = q[self.base[3:]]
        rates = np.array([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])
        vector = np.array([e1, e2, e3])
        skew = np.array([[0, -e3, e2], [e3, 0, -e1], [-e2, e1, 0]])
        return (e0 ** 2 - vector @ vector) * np.eye(3) + 2 * (np.outer(vector, vector) + e0 * skew), rates

    def S(self, q) -> np.ndarray:
        """``qd = S v`` (kronlag speeds of Pinocchio's v), shape (m, nv)."""
        rotation, rates = self._rotation(q)
        result = np.zeros((len(q), self.model.nv))
        result[np.ix_(self.base[:3], range(3))] = rotation
        result[np.ix_(self.base[3:], range(3, 6))] = rates.T / 2
        for k, _, iv, _ in self.slots:
            result[k, iv] = 1.0
        return result

    def q(self, q: np.ndarray) -> np.ndarray:
        result = np.zeros(self.model.nq)
        e0, e1, e2, e3 = q[self.base[3:]]
        result[:7] = (*q[self.base[:3]], e1, e2, e3, e0)
        for k, iq, _, nq in self.slots:
            result[iq:iq + nq] = (np.cos(q[k]), np.sin(q[k])) if nq == 2 else q[k]
        return result

    def tau(self, system: kronlag.System, values: dict) -> np.ndarray:
        """Pinocchio's joint torques of kronlag's parameter values (the base is not actuated)."""
        result = np.zeros(self.model.nv)
        for joint in system.robot.joints:
            if joint.torque:
                result[next(iv for k, _, iv, _ in self.slots if system.coordinates[k].name == joint.coordinate)] = \
                    values[joint.torque]
        return result

    def compare(self, model, q: np.ndarray, v: np.ndarray, tau: np.ndarray | None) -> dict[str, float]:
        """The relative differences of M, g, C qd and (unless ``tau`` is None: a system with
        constraints besides the normalization) the accelerations against ``aba`` at ``(q, v)``."""
        pin, peer, data = self.pin, self.model, self.data
        S, rotation = self.S(q), self._rotation(q)[0]
        qd = S @ v
        rates_dot = self._rotation(np.where(np.isin(np.arange(len(q)), self.base[3:]), qd, 0.0))[1]
        S_dot_v = np.zeros(len(q))
        S_dot_v[self.base[:3]] = rotation @ np.cross(v[3:6], v[:3])
        S_dot_v[self.base[3:]] = rates_dot.T @ v[3:6] / 2
        pq = self.q(q)
        mass = pin.crba(peer, data, pq)
        mass = np.triu(mass) + np.triu(mass, 1).T
        gravity = pin.computeGeneralizedGravity(peer, data, pq).copy()
        bias = pin.nonLinearEffects(peer, data, pq, v).copy() - gravity
        # M and C qd = f_Q - g - h from the dynamics kernel, built with the model (the M and C qd
        # accessors are compiled on first use: for Cassie, another 25 s)
        terms = model.dynamics_terms(q, qd)
        ours_mass, ours_gravity = terms["M"], model.g(q)
        ours_bias = model.f_Q(q, qd) - ours_gravity - terms["h"]
        pairs = {"M": (S.T @ ours_mass @ S, mass), "g": (S.T @ ours_gravity, gravity),
                 "Cqd": (S.T @ (ours_mass @ S_dot_v + ours_bias), bias)}
        if tau is not None:
            pairs["qdd"] = (self.accelerations(q, v, model.forward_dynamics(q, qd).qdd),
                            pin.aba(peer, data, pq, v, tau).copy())
        return {key: relative_difference(ours, theirs) for key, (ours, theirs) in pairs.items()}

    def v(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Pinocchio's ``v`` of kronlag's speeds ``qd`` (on the constraint manifold: ``qd = S v``)."""
        return np.linalg.lstsq(self.S(q), qd, rcond=None)[0]

    def accelerations(self, q: np.ndarray, v: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Pinocchio's accelerations of kronlag's ``qdd`` at ``(q, v)`` (see the class docstring)."""
        rotation, rates = self._rotation(q)
        result = np.zeros(self.model.nv)
        result[:3] = rotation.T @ qdd[self.base[:3]] - np.cross(v[3:6], v[:3])
        result[3:6] = 2 * rates @ qdd[self.base[3:]]
        for k, _, iv, _ in self.slots:
            result[iv] = qdd[k]
        return result


def relative_difference(ours: np.ndarray, theirs: np.ndarray) -> float:
    """``max |ours - theirs| / max(1, max |theirs|)``."""
    return float(np.abs(ours - theirs).max()) / max(1.0, float(np.abs(theirs).max()))


def compare_floating(path: Path, system: kronlag.System, model, values: dict, *, states: int = 5,
                     seed: int = 1) -> dict[str, float]:
    """The largest relative differences to Pinocchio's free-flyer model at random states."""
    reference = FloatingReference(path, system)
    rng = np.random.default_rng(seed)
    tau = reference.tau(system, values)
    worst = {"M": 0.0, "g": 0.0, "Cqd": 0.0, "qdd": 0.0}
    for _ in range(states):
        q, v = reference.random_state(rng, len(system.coordinates))
        for key, value in reference.compare(model, q, v, tau).items():
            worst[key] = max(worst[key], value)
    return worst


def constrained_accelerations(mass, rhs, jacobian) -> np.ndarray:
    """``qdd`` of ``M qdd + J^T lambda = rhs``, ``J qdd = 0`` (constant-coefficient constraints)."""
    m, r = mass.shape[0], jacobian.shape[0]
    matrix = np.block([[mass, jacobian.T], [jacobian, np.zeros((r, r))]])
    return np.linalg.solve(matrix, np.concatenate([rhs, np.zeros(r)]))[:m]


def on_mimics(system: kronlag.System, values: np.ndarray, *, speeds: bool = False) -> np.ndarray:
    """Coordinates (or speeds) with each mimic joint's set from its leader: ``multiplier * q + offset``."""
    index = {q.name: k for k, q in enumerate(system.coordinates)}
    result = np.array(values, dtype=float)
    for joint in system.robot.joints:
        if joint.mimic is not None:
            leader = system.robot.joint(joint.mimic[0]).coordinate
            result[index[joint.coordinate]] = joint.mimic[1] * result[index[leader]] + (0 if speeds else joint.mimic[2])
    return result


def compare(path: Path, system: kronlag.System, model, tau: np.ndarray, *, states: int = 5,
            seed: int = 1) -> dict[str, float]:
    """The largest relative difference of M, g, C qd and the accelerations to Pinocchio at random states."""
    reference = PinocchioReference(path, system)
    rng = np.random.default_rng(seed)
    worst = {"M": 0.0, "g": 0.0, "Cqd": 0.0, "qdd": 0.0}
    m = len(system.coordinates)
    for _ in range(states):
        q, qd = rng.uniform(-1.5, 1.5, m), rng.uniform(-2, 2, m)
        q, qd = on_mimics(system, q), on_mimics(system, qd, speeds=True)
        ours = {"M": model.M(q), "g": model.g(q), "Cqd": model.Cqd(q, qd)}
        theirs = reference.terms(q, qd, tau)
        accelerations = model.forward_dynamics(q, qd).qdd
        expected = theirs["aba"] if not system.constraints else constrained_accelerations(
            theirs["M"], tau - theirs["g"] - theirs["Cqd"], model.Phi_q(q))
        ours["qdd"], theirs["qdd"] = accelerations, expected
        for key in worst:
            scale = max(1.0, float(np.abs(theirs[key]).max()))
            worst[key] = max(worst[key], float(np.abs(ours[key] - theirs[key]).max()) / scale)
    return worst


def run_floating(name: str, path: Path, *, quick: bool, backend: str = "auto") -> dict:
    """A floating-base row: ``load_urdf(path, floating_base=True)`` against Pinocchio's free flyer
    (:func:`compare_floating`); FD timed against ``aba`` at a random state."""
    start = time.perf_counter()
    system = kronlag.load_urdf(path, floating_base=True)
    loaded = time.perf_counter()
    equations = kronlag.derive(system)
    derived = time.perf_counter()
    rng = np.random.default_rng(7)
    values = {**system.robot.values, **{joint.torque: rng.uniform(-1, 1) for joint in system.robot.joints
                                        if joint.torque}}
    model = equations.numeric(values, backend=backend)
    built = time.perf_counter()
    worst = compare_floating(path, system, model, values)
    reference = FloatingReference(path, system)
    q, v = reference.random_state(rng, len(system.coordinates))
    qd, pq, ptau = reference.S(q) @ v, reference.q(q), reference.tau(system, values)
    number = 200 if quick else 20000
    timing = timed_pair(lambda: model.forward_dynamics(q, qd),
                        lambda: reference.pin.aba(reference.model, reference.data, pq, v, ptau), number=number)
    return {"robot": name, "bodies": len(system.bodies), "coordinates": len(system.coordinates),
            "constraints": len(system.constraints), "mobility": model.mobility(q), "load_s": loaded - start,
            "derive_s": derived - loaded, "build_s": built - derived, "max_rel": max(worst.values()),
            "worst": max(worst, key=worst.get), **timing}


#: Cassie's closed-loop SDF (floating pelvis, four ball-joint loops).
CASSIE = "cassie_description/robots/cassie_v2.sdf"


def loop_ranks(system: kronlag.System) -> tuple[dict[str, int], int, float]:
    """The rank of each loop-closing joint's rows, the mobility (the rank policy of
    ``kronlag.numeric.tolerances``) and the largest residual, from ``Phi`` and ``Phi_q`` at the file's
    reference pose, without deriving the dynamics."""
    import sympy as sp

    from kronlag.numeric.tolerances import RANK_RTOL, matrix_rank

    reference = {q: system.robot.q_reference.get(q.name, 0.0) for q in system.coordinates}
    rows = sp.Matrix([constraint.expression for constraint in system.constraints])
    residual = float(np.abs(np.array(rows.xreplace(reference), dtype=float)).max())
    jacobian = np.array(rows.jacobian(list(system.coordinates)).xreplace(reference), dtype=float)
    loops: dict[str, list[int]] = {}
    for index, constraint in enumerate(system.constraints):
        loops.setdefault(constraint.name.rsplit(".", 1)[0], []).append(index)
    ranks = {loop: matrix_rank(jacobian[rows_of], RANK_RTOL) for loop, rows_of in loops.items()}
    return ranks, len(system.coordinates) - matrix_rank(jacobian, RANK_RTOL), residual


def run_cassie(folder: Path, *, quick: bool) -> dict:
    """Cassie's row: load, derive and build (the C backend; against :data:`TARGET_BUILD_HUMANOID_S`), the
    loops' ranks and the mobility at the reference pose (after the timed stages), and the
    constrained dynamics against Pinocchio's model of the same file (:mod:`pinocchio_sdf`), with the
    right foot's loop held at the reference pose (see ``tests/test_cassie_dynamics.py``); FD timed
    against ``pin.constraintDynamics``."""
    import pinocchio_sdf  # bench/ is on the path when this file runs as a script

    start = time.perf_counter()
    system = kronlag.load_sdf(folder / CASSIE)
    loaded = time.perf_counter()
    equations = kronlag.derive(system)
    derived = time.perf_counter()
    rng = np.random.default_rng(7)
    values = {**system.robot.values, **{joint.torque: rng.uniform(-5, 5) for joint in system.robot.joints
                                        if joint.torque}}
    model = equations.numeric(values)
    built = time.perf_counter()
    ranks, mobility, residual = loop_ranks(system)
    print(f"cassie loops: {ranks}, residual at the reference {residual:.2e}")
    results = pinocchio_sdf.compare_constrained(
        folder / CASSIE, system, model, values, held=("right-tarsus-crank-joint", "right-crank-rod-joint", "right-foot-op"),
        dependent=("right-plantar-foot-joint.z",))
    worst = {key: max(result[key] for result in results) for key in results[0] if key != "gap"}
    print("cassie vs Pinocchio, max relative difference over the states: "
          + ", ".join(f"{key} {value:.1e}" for key, value in worst.items()))
    peer = pinocchio_sdf.build(folder / CASSIE)
    reference = FloatingReference(folder / CASSIE, system, model=peer.model)
    q = np.array([system.robot.q_reference[x.name] for x in system.coordinates])
    qd, pq, tau = np.zeros(len(q)), reference.q(q), reference.tau(system, values)
    number = 20 if quick else 2000
    timing = timed_pair(lambda: model.forward_dynamics(q, qd),
                        lambda: pinocchio_sdf.constrained_accelerations(peer, pq, np.zeros(peer.model.nv), tau),
                        number=number)
    return {"robot": "cassie_v2.sdf", "bodies": len(system.bodies), "coordinates": len(system.coordinates),
            "constraints": len(system.constraints), "mobility": mobility, "load_s": loaded - start,
            "derive_s": derived - loaded, "build_s": built - derived, "max_rel": max(worst.values()),
            "worst": max(worst, key=worst.get), **timing}


#: Interleaved blocks of each forward-dynamics timing (medians taken).
BLOCKS = 9


def timed_pair(ours, peer, *, number: int) -> dict[str, float]:
    """``fd_us`` and ``aba_us``, the µs per call of ``ours`` and ``peer`` (medians over :data:`BLOCKS` blocks of
    ``number`` calls each, interleaved in this process: a loaded machine slows both alike), ``ratio``, the
    median of the blocks' ratios, and ``load``, the load average when they were taken."""
    from common import interleaved, machine_load, ratio  # bench/ is on the path when this file runs as a script

    timings = interleaved({"ours": lambda: timeit.timeit(ours, number=number),
                           "peer": lambda: timeit.timeit(peer, number=number)}, blocks=BLOCKS)
    return {"fd_us": timings["ours"].median / number * 1e6, "aba_us": timings["peer"].median / number * 1e6,
            "ratio": ratio(timings, "ours", "peer"), "load": machine_load()}


def run(name: str, path: Path, *, quick: bool) -> dict:
    start = time.perf_counter()
    system = kronlag.load_urdf(path)
    loaded = time.perf_counter()
    equations = kronlag.derive(system)
    derived = time.perf_counter()
    rng = np.random.default_rng(7)
    tau = np.array([rng.uniform(-1, 1) if symbol else 0.0 for symbol in
                    (joint.torque for joint in system.robot.joints if joint.coordinate)])
    values = {**system.robot.values, **{joint.torque: float(value) for joint, value in
                                        zip([j for j in system.robot.joints if j.coordinate], tau) if joint.torque}}
    model = equations.numeric(values)
    built = time.perf_counter()
    worst = compare(path, system, model, tau)
    reference = PinocchioReference(path, system)
    q, qd = rng.uniform(-1, 1, len(system.coordinates)), rng.uniform(-1, 1, len(system.coordinates))
    pq, pv, ptau = reference.q(q), reference.v(qd), reference.v(tau)
    number = 200 if quick else 20000
    timing = timed_pair(lambda: model.forward_dynamics(q, qd),
                        lambda: reference.pin.aba(reference.model, reference.data, pq, pv, ptau), number=number)
    m = len(system.coordinates)
    return {"robot": name, "bodies": len(system.bodies), "coordinates": m, "constraints": len(system.constraints),
            "mobility": model.mobility(on_mimics(system, np.zeros(m))),
            "load_s": loaded - start, "derive_s": derived - loaded, "build_s": built - derived,
            "max_rel": max(worst.values()), "worst": max(worst, key=worst.get), **timing,
            **dynamics_kernel(equations)}


def dynamics_kernel(equations: kronlag.Equations) -> dict:
    """How the ``"dynamics"`` kernel computes M and h (``recursive`` or ``flat``,
    :func:`kronlag.numeric.codegen.recursive.dynamics_algorithm`) and its size: the operations of its
    temporaries and outputs after common-subexpression elimination (SymEngine's ``count_ops``)."""
    import symengine

    from kronlag.numeric.codegen import KernelSource
    from kronlag.numeric.codegen.recursive import dynamics_algorithm

    kernel = KernelSource(equations).kernel("dynamics")
    operations = sum(symengine.count_ops(expr) for _, expr in kernel.temporaries) + sum(
        symengine.count_ops(expr) for expr in kernel.outputs)
    return {"algorithm": dynamics_algorithm(equations.system).split(":")[0], "operations": operations}


FILES = Path(__file__).resolve().parents[1] / "tests" / "robot_files"


def run_mjcf(name: str, *, quick: bool) -> dict:
    """An MJCF row: ``arm`` (tree, M and C qd + g against MuJoCo) or ``four_bar`` (closed loop: the
    accelerations against MuJoCo's soft closure at an assembled state)."""
    import mujoco

    path = FILES / f"{name}.xml"
    start = time.perf_counter()
    system = kronlag.load_mjcf(path)
    loaded = time.perf_counter()
    equations = kronlag.derive(system)
    derived = time.perf_counter()
    model = equations.numeric(system.robot.values)
    built = time.perf_counter()
    peer = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(peer)
    names = [joint.name for joint in system.robot.joints if joint.coordinate]
    qpos, dof = [peer.joint(n).qposadr[0] for n in names], [peer.joint(n).dofadr[0] for n in names]
    m = len(names)
    rng = np.random.default_rng(11)
    worst = 0.0
    if system.constraints:
        q, qd = model.assemble([0.3] + [0.0] * (m - 1), fixed={names[0]: 0.3}, qd_guess=[1.0] + [0.0] * (m - 1),
                               qd_fixed={names[0]: 1.0})
        data.qpos[qpos], data.qvel[dof] = q, qd
        mujoco.mj_forward(peer, data)
        ours = model.forward_dynamics(q, qd).qdd
        worst, what = float(np.abs(data.qacc[dof] - ours).max() / np.abs(ours).max()), "soft"
    else:
        what = "M,bias"
        for _ in range(5):
            q, qd = rng.uniform(-1, 1, m), rng.uniform(-1, 1, m)
            data.qpos[qpos], data.qvel[dof] = q, qd
            mujoco.mj_forward(peer, data)
            mass = np.zeros((peer.nv, peer.nv))
            mujoco.mj_fullM(peer, data, mass)
            mass, bias = mass[np.ix_(dof, dof)], data.qfrc_bias[dof]
            worst = max(worst, float(np.abs(model.M(q) - mass).max() / np.abs(mass).max()),
                        float(np.abs(model.Cqd(q, qd) + model.g(q) - bias).max() / max(1.0, np.abs(bias).max())))
    number = 200 if quick else 20000
    timing = timed_pair(lambda: model.forward_dynamics(q, qd), lambda: mujoco.mj_forward(peer, data), number=number)
    return {"robot": f"{name}.xml", "bodies": len(system.bodies), "coordinates": m,
            "constraints": len(system.constraints), "mobility": model.mobility(q), "load_s": loaded - start,
            "derive_s": derived - loaded, "build_s": built - derived, "max_rel": worst, "worst": what,
            **timing}


def main(argv=None) -> int:
    from common import Record, add_arguments  # here: the tests load this file as a module, without bench/ on the path

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    known = [*ROBOTS, *FLOATING, "cassie", "arm", "four_bar"]
    parser.add_argument("robots", nargs="*", help=f"some of {', '.join(known)} (default: all)")
    parser.add_argument("--quick", action="store_true")
    add_arguments(parser)
    arguments = parser.parse_args(argv)
    record = Record("bench_robots", arguments)
    unknown = [name for name in arguments.robots if name not in known]
    if unknown:
        parser.error(f"unknown robot(s) {', '.join(unknown)}; known: {', '.join(known)}")
    arguments.robots = arguments.robots or known
    folder = robots_folder()
    if folder is None:
        print("example-robot-data is not installed (pip install example-robot-data)")
        return 1
    print(f"{'robot':<16}{'bodies':>7}{'coords':>7}{'constr':>7}{'mob':>5}{'load s':>8}{'derive s':>10}"
          f"{'build s':>9}{'max rel diff':>14}{'(in)':>8}{'FD us':>9}{'peer us':>8}{'ratio':>8}{'load':>6}")
    print("peer: Pinocchio (crba, gravity, nonLinearEffects, aba) for URDF; MuJoCo (mj_fullM, qfrc_bias, mj_forward) "
          "for .xml; 'soft' = MuJoCo's soft loop closure against kronlag's exact one")
    failed = False
    for name in arguments.robots:
        if name in ROBOTS:
            row = run(name, folder / ROBOTS[name], quick=arguments.quick)
        elif name in FLOATING:
            row = run_floating(name, folder / FLOATING[name], quick=arguments.quick)
        elif name == "cassie":
            row = run_cassie(folder, quick=arguments.quick)
        elif importlib.util.find_spec("mujoco") is None:
            print(f"{name}: skipped (pip install mujoco)")
            continue
        else:
            row = run_mjcf(name, quick=arguments.quick)
        failed |= row["max_rel"] > 1e-9 and row["worst"] != "soft"
        print(f"{row['robot']:<16}{row['bodies']:>7}{row['coordinates']:>7}{row['constraints']:>7}{row['mobility']:>5}"
              f"{row['load_s']:>8.2f}{row['derive_s']:>10.2f}{row['build_s']:>9.2f}{row['max_rel']:>14.2e}"
              f"{row['worst']:>8}{row['fd_us']:>9.2f}{row['aba_us']:>8.2f}{row['ratio']:>8.2f}{row['load']:>6.1f}",
              flush=True)
        if "operations" in row:
            print(f"{row['robot']}: {row['algorithm']} dynamics kernel, {row['operations']} operations")
        record_row(record, row, quick=arguments.quick)
    if failed:
        print("MISMATCH: a difference above 1e-9")
    record.finish()
    return 1 if failed else 0


def record_row(record, row: dict, *, quick: bool) -> None:
    """A row's figures: load + derive + build against its target, FD against the peer (a target against
    Pinocchio's ``aba``; MuJoCo's ``mj_forward`` does more, so its ratio is for information)."""
    record.figure(f"{row['robot']}: load + derive + build", row["load_s"] + row["derive_s"] + row["build_s"],
                  unit=" s", target=TARGET_BUILD_HUMANOID_S if row["robot"] in HUMANOIDS else TARGET_BUILD_S,
                  better="lower",
                  detail=f"derive {row['derive_s']:.2f} s, build {row['build_s']:.2f} s")
    mujoco, cassie = row["robot"].endswith(".xml"), row["robot"] == Path(CASSIE).name
    peer = "MuJoCo mj_forward" if mujoco else "Pinocchio constraintDynamics" if cassie else "Pinocchio aba"
    record.figure(f"{row['robot']}: forward dynamics / {peer}",
                  row["ratio"], unit="x", target=None if mujoco or cassie or row["robot"] in FLOATING else TARGET_RATIO,
                  better="lower",
                  detail=f"{row['fd_us']:.2f} µs vs {row['aba_us']:.2f} µs, medians of {BLOCKS} interleaved blocks of "
                  f"{200 if quick else 20000} calls, load {row['load']:.1f}"
                  + (f"; {row['algorithm']} dynamics kernel of {row['operations']} operations" if "operations" in row
                     else ""))


if __name__ == "__main__":
    sys.exit(main())
