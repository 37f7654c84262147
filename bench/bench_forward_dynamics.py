#!/usr/bin/env python3
"""Forward dynamics with multipliers per call: kronlag against Pinocchio's constrained dynamics.

Run by hand (not a pytest test; needs ``pip install pin``)::

    python3 bench/bench_forward_dynamics.py            # n = 4, 12, 20, 30, 40, 60, 80, both conventions
    python3 bench/bench_forward_dynamics.py --n 4 8 --angles relative
    python3 bench/bench_forward_dynamics.py --quick         # smoke test: n = 4, 12, 100 times fewer calls
    python3 bench/bench_forward_dynamics.py --json -        # also write bench/results/bench_forward_dynamics.json

The mechanism is ``kronlag.models.closed_chain(n, angles)``: ``n`` uniform
links in the x-y plane (lengths ``l_i``, masses ``m_i``, central inertias
``I_i``), link 1 pinned at the origin, the tip of link ``n`` pinned at the
ground point ``(xg, yg)``, gravity ``g`` along -y.  With ``angles="relative"``
``q_i`` are the joint angles relative to the previous link, which is what a
Pinocchio chain of revolute joints uses (``q`` maps one to one); with
``angles="absolute"`` they are the links' angles to the x axis,
``q_abs = T q_rel`` with ``T`` the lower triangle of ones, so speeds and
accelerations map by ``T`` and generalized forces by ``T^T``
(``f_rel = T^T f_abs``).  In Pinocchio: ``n`` ``JointModelRZ``
joints, each link a body with its centre of mass at ``(l_i / 2, 0, 0)`` and
rotational inertia ``I_i`` about z, ``model.gravity.linear = (0, -g, 0)``, and
the loop closed by a ``RigidConstraintModel`` of type ``CONTACT_3D`` between
the tip of link ``n`` and the ground point (its z row is structurally zero in
a planar chain, so the constraint is rank deficient and the proximal solver
of ``constraintDynamics`` is what makes it work).

Timed per call from Python (best of several repeats of many calls):

* kronlag, C backend: ``model.forward_dynamics(q, qd)`` (``qdd``, ``lambda``,
  ``mu`` in a result object);
* kronlag, C kernel alone: the packed ctypes entry point that
  ``forward_dynamics`` calls (no Python-side copies or result object);
* kronlag, Python backend (no compiler), for information, up to ``n = PYTHON_BACKEND_MAX_N``;
* Pinocchio: ``pinocchio.constraintDynamics(model, data, q, v, tau,
  constraint_models, constraint_datas, prox_settings)`` (``ddq``; the contact
  forces are left in ``data.lambda_c``).

Before timing, both are checked at a consistent state: the same ``qdd`` and
the same generalized constraint forces (``-Phi_q^T lambda`` from kronlag
against ``rnea(q, v, ddq) = J^T f`` from Pinocchio).
"""

from __future__ import annotations

import argparse
import os
import platform
import timeit

import numpy as np

import kronlag
from kronlag import models
from kronlag.numeric.codegen.recursive import dynamics_algorithm

from common import Record, add_arguments

#: Smoke-test mode (``--quick``): far fewer timed calls.
QUICK = False
#: The Python backend is timed (and checked against C) up to this many links only: beyond, its
#: kernels take longer to build than the whole C comparison.
PYTHON_BACKEND_MAX_N = 12


def chain_parameters(n: int, seed: int = 0) -> tuple[dict[str, float], np.ndarray]:
    """Link data of a closed chain and a configuration ``q_ref`` it closes at."""
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.5, 1.5, n)
    masses = rng.uniform(0.5, 2.0, n)
    inertias = masses * lengths ** 2 / 12
    q_ref = rng.uniform(-0.6, 0.6, n) + np.r_[0.3, np.zeros(n - 1)]
    angles = np.cumsum(q_ref)
    tip = np.array([np.sum(lengths * np.cos(angles)), np.sum(lengths * np.sin(angles))])
    values = {f"l{i + 1}": lengths[i] for i in range(n)}
    values.update({f"m{i + 1}": masses[i] for i in range(n)})
    values.update({f"I{i + 1}": inertias[i] for i in range(n)})
    values.update(xg=tip[0], yg=tip[1], g=9.81)
    return values, q_ref


def pinocchio_links(n: int, values: dict[str, float]):
    """The open chain of ``n`` links as a Pinocchio model: ``(model, tip joint, tip placement in it)``."""
    import pinocchio as pin

    model = pin.Model()
    parent, placement = 0, pin.SE3.Identity()
    for i in range(1, n + 1):
        length, mass, inertia = values[f"l{i}"], values[f"m{i}"], values[f"I{i}"]
        joint = model.addJoint(parent, pin.JointModelRZ(), placement, f"joint{i}")
        model.appendBodyToJoint(joint, pin.Inertia(mass, np.array([length / 2, 0.0, 0.0]),
                                                   np.diag([inertia, inertia, inertia])), pin.SE3.Identity())
        parent, placement = joint, pin.SE3(np.eye(3), np.array([length, 0.0, 0.0]))
    model.gravity.linear = np.array([0.0, -values["g"], 0.0])
    return model, parent, placement


def pinocchio_chain(n: int, values: dict[str, float]):
    """The same chain as a Pinocchio model with a tip-to-ground CONTACT_3D constraint."""
    import pinocchio as pin

    model, parent, placement = pinocchio_links(n, values)
    constraint = pin.RigidConstraintModel(
        pin.ContactType.CONTACT_3D, model, parent, placement, 0,
        pin.SE3(np.eye(3), np.array([values["xg"], values["yg"], 0.0])), pin.ReferenceFrame.LOCAL)
    constraint_models = pin.StdVec_RigidConstraintModel()
    constraint_models.append(constraint)
    constraint_datas = pin.StdVec_RigidConstraintData()
    constraint_datas.append(constraint.createData())
    data = model.createData()
    pin.initConstraintDynamics(model, data, constraint_models, constraint_datas)
    settings = pin.ProximalSettings(1e-13, 1e-12, 1e-10, 50)

    def forward(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return pin.constraintDynamics(model, data, q, v, np.zeros(n), constraint_models, constraint_datas,
                                      settings)

    def generalized_constraint_force(q: np.ndarray, v: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        return pin.rnea(model, model.createData(), q, v, ddq)  # M ddq + b = tau + J^T f, tau = 0

    return forward, generalized_constraint_force


def per_call(function, *, number: int, repeat: int = 7) -> float:
    """Best time per call in microseconds (``number`` divided by 100 with ``--quick``)."""
    number = max(1, number // 100) if QUICK else number
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number * 1e6


#: Issue 19: kronlag's forward dynamics at most this fraction of Pinocchio's, at every size.
TARGET_RATIO = 0.8
#: Interleaved blocks of the ratio measurement (median taken).
BLOCKS = 9


def interleaved_ratio(ours, peer, *, number: int) -> tuple[float, float, float]:
    """Median over :data:`BLOCKS` blocks of (our time / the peer's) per call, each block timing both
    back to back in alternating order (a loaded machine slows both alike); also the medians of the
    two times in microseconds."""
    number = max(1, number // 100) if QUICK else number
    ratios, mine, theirs = [], [], []
    for block in range(BLOCKS):
        pair = (ours, peer) if block % 2 == 0 else (peer, ours)
        first, second = (timeit.timeit(function, number=number) / number * 1e6 for function in pair)
        ours_us, peer_us = (first, second) if block % 2 == 0 else (second, first)
        ratios.append(ours_us / peer_us)
        mine.append(ours_us)
        theirs.append(peer_us)
    return float(np.median(ratios)), float(np.median(mine)), float(np.median(theirs))


def bench(n: int, angles: str) -> dict[str, float]:
    import pinocchio as pin

    values, q_ref = chain_parameters(n)
    eom = kronlag.derive(models.closed_chain(n, angles))
    c_model = eom.numeric(values, backend="c")
    numpy_model = eom.numeric(values, backend="python") if n <= PYTHON_BACKEND_MAX_N else None
    # kronlag coordinates from Pinocchio's (relative) ones: q = T q_rel, T = identity or lower ones
    T = np.eye(n) if angles == "relative" else np.tril(np.ones((n, n)))
    q_guess = T @ q_ref + 0.05
    rng = np.random.default_rng(1)
    q, qd = c_model.assemble(q_guess, fixed={"q1": q_guess[0]}, qd_guess=rng.uniform(-1, 1, n),
                             qd_fixed={"q1": 0.8})
    q_rel, qd_rel = np.linalg.solve(T, q), np.linalg.solve(T, qd)
    forward, constraint_force = pinocchio_chain(n, values)

    result = c_model.forward_dynamics(q, qd)
    ddq = T @ forward(q_rel, qd_rel)
    scale = np.max(np.abs(result.qdd))
    qdd_difference = np.max(np.abs(result.qdd - ddq)) / scale
    force = T.T @ (-c_model.Phi_q(q).T @ result.lam)
    force_difference = (np.max(np.abs(force - constraint_force(q_rel, qd_rel, np.linalg.solve(T, ddq))))
                        / np.max(np.abs(force)))
    numpy_difference = (np.max(np.abs(numpy_model.forward_dynamics(q, qd).qdd - result.qdd)) / scale
                        if numpy_model else 0.0)
    assert qdd_difference < 1e-8, f"qdd differ by {qdd_difference:.2e} (relative)"
    assert force_difference < 1e-6, f"constraint forces differ by {force_difference:.2e} (relative)"
    assert numpy_difference < 1e-10

    packed = c_model._dynamics._packed  # the compiled entry point, through ctypes
    packed_in, packed_out = np.r_[0.0, 0.0, 0.0, q, qd, c_model.parameter_vector()], np.zeros(n + 2)
    pointers = (packed_in.ctypes.data, packed_out.ctypes.data)
    times = {
        "kronlag C forward_dynamics": per_call(lambda: c_model.forward_dynamics(q, qd), number=20000),
        "kronlag C kernel (ctypes call)": per_call(lambda: packed(*pointers), number=20000),
        "pinocchio constraintDynamics": per_call(lambda: forward(q_rel, qd_rel), number=20000),
    }
    if numpy_model:
        times["kronlag Python forward_dynamics"] = per_call(lambda: numpy_model.forward_dynamics(q, qd), number=300)
    ratio, ours, peer = interleaved_ratio(lambda: c_model.forward_dynamics(q, qd), lambda: forward(q_rel, qd_rel),
                                          number=5000)
    times["interleaved ratio"] = ratio
    print(f"\nclosed_chain({n}, {angles!r}): m = {n}, r = 2; pinocchio {pin.__version__}; "
          f"M and h: {dynamics_algorithm(eom.system)}")
    print(f"  check: |qdd_kronlag - ddq_pinocchio| / |qdd| = {qdd_difference:.1e}, "
          f"constraint forces {force_difference:.1e}, Python vs C {numpy_difference:.1e}")
    reference = times["pinocchio constraintDynamics"]
    for name, value in times.items():
        if name != "interleaved ratio":
            print(f"  {name:34s} {value:9.2f} us   ratio to pinocchio {value / reference:6.2f}")
    print(f"  interleaved, median of {BLOCKS} blocks: kronlag {ours:.2f} us, pinocchio {peer:.2f} us, "
          f"ratio {ratio:.2f} (target <= {TARGET_RATIO}); load average {os.getloadavg()[0]:.1f}")
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", help="numbers of links (default: 4 12 20 30 40 60 80; with "
                        "--quick: 4 12)")
    parser.add_argument("--angles", nargs="+", choices=("relative", "absolute"), default=["relative", "absolute"],
                        help="angle conventions of closed_chain")
    parser.add_argument("--quick", action="store_true", help="smoke test: 100 times fewer calls")
    add_arguments(parser)
    arguments = parser.parse_args()
    record = Record("bench_forward_dynamics", arguments)
    global QUICK
    QUICK = arguments.quick
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
          f"numpy {np.__version__}")
    summary = []
    for n in arguments.n or ([4, 12] if QUICK else [4, 12, 20, 30, 40, 60, 80]):
        for angles in arguments.angles:
            times = bench(n, angles)
            summary.append((n, angles, times["interleaved ratio"]))
    print(f"\nsummary: kronlag C forward_dynamics / pinocchio constraintDynamics, interleaved medians "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPU(s): a shared machine)")
    for n, angles, ratio in summary:
        print(f"  closed_chain({n:2d}, {angles!r:10s})  {ratio:5.2f}  (target <= {TARGET_RATIO}) "
              f"{'ok' if ratio <= TARGET_RATIO else 'OVER'}")
    for n, angles, ratio in summary:
        record.figure(f"closed_chain({n}, {angles}): C forward_dynamics / pinocchio constraintDynamics", ratio,
                      unit="x", target=TARGET_RATIO, better="lower", detail=f"median of {BLOCKS} interleaved blocks")
    record.finish()


if __name__ == "__main__":
    main()
