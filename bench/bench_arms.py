#!/usr/bin/env python3
"""Spatial serial arms per call: kronlag's forward dynamics and accessors against Pinocchio's
``aba``, ``crba``, ``computeGeneralizedGravity`` and ``nonLinearEffects``.

Run by hand (not a pytest test; needs ``pip install pin``)::

    python3 bench/bench_arms.py            # UR5 and Panda
    python3 bench/bench_arms.py --quick    # smoke test: 100 times fewer calls
    python3 bench/bench_arms.py --json -   # also write bench/results/bench_arms.json

The arms are ``kronlag.models.ur5()`` (6 joints, standard DH) and ``panda()`` (7 joints,
modified DH).  The Pinocchio model is built from the kronlag model's bodies, not from the DH
tables, so that both describe the same arm: for body ``i`` at ``q = 0`` its rotation ``R_i``,
its centre of mass ``c_i``, the world axis ``a_i = vee(dR_i/dq_i R_i^T)`` of joint ``i`` and a
point ``p_i = c_i + a_i x dc_i/dq_i`` on that axis give a ``JointModelRZ`` whose frame has its z
axis along ``a_i`` at ``p_i``, and the body's mass and central inertia placed at ``(R_i, c_i)``
in it.  Gravity ``g = 9.81`` along -z in both, the same joint torques.

Timed per call from Python, best of several repeats:

* kronlag, C backend: ``model.forward_dynamics(q, qd)`` (``qdd`` in a result object),
  ``model.M(q)``, ``model.g(q)``, ``model.Cqd(q, qd)``;
* Pinocchio: ``aba(model, data, q, v, tau)``, ``crba``, ``computeGeneralizedGravity`` and
  ``nonLinearEffects`` (``C qd + g``: a little more than kronlag's ``Cqd``).

Before timing, M, the accelerations, g and ``C qd + g`` are checked against each other at a
random state (relative differences printed; the run stops if they exceed 1e-9).
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
import timeit

import numpy as np
import sympy as sp

import kronlag
from kronlag import models

from common import Record, add_arguments

QUICK = False
ARMS = ("ur5", "panda")
#: Issue 19/21: forward dynamics at most this fraction of ``aba``; derive + C build at most this (s).
TARGET_RATIO = 0.8
TARGET_BUILD_S = 5.0
#: Interleaved blocks of each ratio (median taken).
BLOCKS = 9


def interleaved_ratio(ours, peer, *, number: int = 5000) -> float:
    """Median over :data:`BLOCKS` blocks of (our time / the peer's), both timed back to back in each
    block, in alternating order (a loaded machine slows both alike)."""
    number = max(1, number // 100) if QUICK else number
    ratios = []
    for block in range(BLOCKS):
        pair = (ours, peer) if block % 2 == 0 else (peer, ours)
        first, second = (timeit.timeit(function, number=number) for function in pair)
        ratios.append(first / second if block % 2 == 0 else second / first)
    return float(np.median(ratios))


def per_call(function, *, number: int = 20000, repeat: int = 7) -> float:
    """Best time per call in microseconds (``number`` divided by 100 with ``--quick``)."""
    number = max(1, number // 100) if QUICK else number
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number * 1e6


def _frame_along(axis: np.ndarray, point: np.ndarray):
    """An SE3 at ``point`` whose z axis is the unit vector ``axis``."""
    import pinocchio as pin

    helper = np.eye(3)[np.argmin(np.abs(axis))]
    x = np.cross(helper, axis)
    x /= np.linalg.norm(x)
    return pin.SE3(np.column_stack([x, np.cross(axis, x), axis]), point)


def pinocchio_arm(system: kronlag.System):
    """The serial arm of revolute joints ``system`` (body i moved by q_1..q_i) as a Pinocchio model."""
    import pinocchio as pin

    zero = {coordinate: 0 for coordinate in system.coordinates}
    model = pin.Model()
    parent, parent_frame = 0, pin.SE3.Identity()
    for i, (coordinate, body) in enumerate(zip(system.coordinates, system.bodies)):
        rotation = np.array(body.rotation.subs(zero), dtype=float)
        centre = np.array(body.position.subs(zero), dtype=float).ravel()
        spin = np.array(body.rotation.diff(coordinate).subs(zero), dtype=float) @ rotation.T
        axis = np.array([spin[2, 1], spin[0, 2], spin[1, 0]])
        velocity = np.array(body.position.diff(coordinate).subs(zero), dtype=float).ravel()
        frame = _frame_along(axis, centre + np.cross(axis, velocity))
        joint = model.addJoint(parent, pin.JointModelRZ(), parent_frame.inverse() * frame, f"joint{i + 1}")
        inertia = pin.Inertia(float(body.mass), np.zeros(3), np.array(body.inertia, dtype=float))
        model.appendBodyToJoint(joint, inertia, frame.inverse() * pin.SE3(rotation, centre))
        parent, parent_frame = joint, frame
    model.gravity.linear = np.array([0.0, 0.0, -9.81])
    return model


def bench(name: str) -> dict[str, float]:
    import pinocchio as pin

    system = getattr(models, name)()
    rng = np.random.default_rng(3)
    torques = rng.uniform(-2, 2, len(system.coordinates))
    values = {"g": 9.81, **{f"tau{i + 1}": torque for i, torque in enumerate(torques)}}
    with tempfile.TemporaryDirectory() as cache:  # an empty cache: the build a new user waits for
        previous, os.environ["KRONLAG_CACHE"] = os.environ.get("KRONLAG_CACHE"), cache
        start = time.perf_counter()
        eom = kronlag.derive(system)
        model = eom.numeric(values, backend="c")
        build_seconds = time.perf_counter() - start
        if previous is None:
            del os.environ["KRONLAG_CACHE"]
        else:
            os.environ["KRONLAG_CACHE"] = previous
    arm = pinocchio_arm(system)
    data = arm.createData()
    q, qd = rng.uniform(-np.pi, np.pi, model.m), rng.uniform(-1, 1, model.m)

    mass_difference = np.max(np.abs(model.M(q) - pin.crba(arm, data, q))) / np.max(np.abs(model.M(q)))
    qdd = model.forward_dynamics(q, qd).qdd
    qdd_difference = np.max(np.abs(qdd - pin.aba(arm, data, q, qd, torques))) / np.max(np.abs(qdd))
    gravity = model.g(q)
    gravity_difference = np.max(np.abs(gravity - pin.computeGeneralizedGravity(arm, data, q))) / np.max(np.abs(gravity))
    effects = model.Cqd(q, qd) + gravity
    effects_difference = np.max(np.abs(effects - pin.nonLinearEffects(arm, data, q, qd))) / np.max(np.abs(effects))
    differences = (mass_difference, qdd_difference, gravity_difference, effects_difference)
    assert max(differences) < 1e-9, differences
    # (kronlag call, Pinocchio's corresponding call): nonLinearEffects is C qd + g, kronlag's Cqd is C qd
    pairs = {
        ("kronlag C forward_dynamics", "pinocchio aba"): (lambda: model.forward_dynamics(q, qd),
                                                          lambda: pin.aba(arm, data, q, qd, torques)),
        ("kronlag C M", "pinocchio crba"): (lambda: model.M(q), lambda: pin.crba(arm, data, q)),
        ("kronlag C g", "pinocchio computeGeneralizedGravity"): (lambda: model.g(q),
                                                                 lambda: pin.computeGeneralizedGravity(arm, data, q)),
        ("kronlag C Cqd", "pinocchio nonLinearEffects"): (lambda: model.Cqd(q, qd),
                                                          lambda: pin.nonLinearEffects(arm, data, q, qd)),
    }
    times = {key: per_call(call) for labels, calls in pairs.items() for key, call in zip(labels, calls)}
    times["ratios"] = {labels: interleaved_ratio(*calls) for labels, calls in pairs.items()}
    times["build"] = build_seconds
    print(f"\n{name}: m = {model.m}; pinocchio {pin.__version__}; derive + C build {build_seconds:.2f} s "
          f"(target {TARGET_BUILD_S:.0f} s), load average {os.getloadavg()[0]:.1f}")
    print("  check (relative): M {:.1e}, qdd {:.1e}, g {:.1e}, C qd + g {:.1e}".format(*differences))
    for label, reference in pairs:
        for key in (label, reference):
            print(f"  {key:36s} {times[key]:8.2f} us   ratio to {reference} {times[key] / times[reference]:6.2f}")
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    parser.add_argument("--quick", action="store_true", help="smoke test: 100 times fewer calls")
    add_arguments(parser)
    arguments = parser.parse_args()
    record = Record("bench_arms", arguments)
    global QUICK
    QUICK = arguments.quick
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
          f"numpy {np.__version__}, sympy {sp.__version__}")
    summary = {name: bench(name) for name in arguments.arms}
    print(f"\nsummary: kronlag / pinocchio per call, interleaved medians of {BLOCKS} blocks (load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPU(s): a shared machine)")
    for name, times in summary.items():
        print(f"  {name:6s} derive + C build  {times['build']:5.2f} s  "
              f"{'ok' if times['build'] <= TARGET_BUILD_S else 'OVER'} (target {TARGET_BUILD_S:.0f} s)")
        for label, reference, target in (("kronlag C forward_dynamics", "pinocchio aba", TARGET_RATIO),
                                         ("kronlag C M", "pinocchio crba", 1.5),
                                         ("kronlag C g", "pinocchio computeGeneralizedGravity", 1.5),
                                         ("kronlag C Cqd", "pinocchio nonLinearEffects", 1.5)):
            ratio = times["ratios"][(label, reference)]
            print(f"  {name:6s} {label[10:]:17s} {ratio:5.2f}  {'ok' if ratio <= target else 'OVER'} (target {target})")
            record.figure(f"{name}: {label} / {reference}", ratio, unit="x", target=target, better="lower",
                          detail=f"median of {BLOCKS} interleaved blocks")
        record.figure(f"{name}: derive + C build (empty cache)", times["build"], unit=" s", target=TARGET_BUILD_S,
                      better="lower")
    print(f"\ntargets: forward dynamics at most {TARGET_RATIO}x aba and derive + C build at most {TARGET_BUILD_S:.0f} s "
          "(issues 19 and 21); the accessors M, g, Cqd at most 1.5x crba, computeGeneralizedGravity, nonLinearEffects")
    record.finish()


if __name__ == "__main__":
    main()
