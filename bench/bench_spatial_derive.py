#!/usr/bin/env python3
"""Derivation time of spatial serial arms with the default settings.

Run by hand (not a pytest test)::

    python3 bench/bench_spatial_derive.py            # kronlag cases and SymPy's KanesMethod (<= 60 s)
    python3 bench/bench_spatial_derive.py --quick    # kronlag cases only

Cases (each in a fresh Python subprocess, best of 3 for kronlag; imports excluded):

* ``ur5``, ``panda``: ``kronlag.models.ur5()`` / ``panda()`` (RotationSequence bodies) built
  and derived with ``kronlag.derive(system)``, then ``eom.M``, ``eom.C``, ``eom.g`` read;
* ``ur5 matrix``: the same UR5 with every rotation passed as a plain SymPy matrix
  (``RigidBody(..., simplify=True)``, the default): J_R is ``vee(R^T dR/dq)`` with the
  trigsimp of small entries only;
* ``ur5 KanesMethod``: the UR5 with ``sympy.physics.mechanics`` (frames oriented by
  ``orient_axis`` along the DH chain, ``RigidBody``, gravity loads, ``KanesMethod`` with
  ``u = qd``, ``kanes_equations``), the peer; killed after ``SYMPY_BUDGET_S`` and reported
  as a lower bound.  When it finishes, its mass matrix is compared with kronlag's at a
  random configuration.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

SCRIPT = os.path.abspath(__file__)
SYMPY_BUDGET_S = 60.0
KRONLAG_BUDGET_S = 300.0
REPEATS = 3
TARGETS_S = {"ur5": 2.0, "panda": 5.0}


def work_kronlag(case: str) -> dict:
    import sympy as sp

    import kronlag
    start = time.perf_counter()
    system = kronlag.models.BUILTIN_MODELS[case.split()[0]]()
    if case.endswith("matrix"):
        plain = kronlag.System(system.coordinates, parameters=system.parameters, gravity=system.gravity)
        for body in system.bodies:
            plain.add_body(kronlag.RigidBody(body.name, mass=body.mass, inertia=body.inertia,
                                             position=body.position, rotation=sp.Matrix(body.rotation)))
        system = plain
    equations = kronlag.derive(system)
    equations.M, equations.C, equations.g
    return {"seconds": time.perf_counter() - start}


def ur5_kanes():
    """The UR5 with sympy.physics.mechanics; returns (KanesMethod, q)."""
    import sympy as sp
    from sympy.physics import mechanics as me

    import kronlag
    reference = kronlag.models.ur5()  # its numbers only: masses, inertias, centres from the DH table below
    dh = [(0, 0.089159, sp.pi / 2), (-0.425, 0, 0), (-0.39225, 0, 0), (0, 0.10915, sp.pi / 2),
          (0, 0.09465, -sp.pi / 2), (0, 0.0823, 0)]
    centres = [(0, -0.02561, 0.00193), (0.2125, 0, 0.11336), (0.15, 0, 0.0265), (0, -0.0018, 0.01634),
               (0, 0.0018, 0.01634), (0, 0, -0.001159)]
    q = me.dynamicsymbols("q1:7")
    u = me.dynamicsymbols("u1:7")
    g = sp.Symbol("g")
    ground = me.ReferenceFrame("N")
    origin = me.Point("O")
    origin.set_vel(ground, 0)
    frame, point, bodies, loads = ground, origin, [], []
    for i, (a, d, alpha) in enumerate(dh):
        joint = me.ReferenceFrame(f"J{i + 1}")
        joint.orient_axis(frame, frame.z, q[i])
        link = me.ReferenceFrame(f"L{i + 1}")
        link.orient_axis(joint, joint.x, alpha)
        point = point.locatenew(f"P{i + 1}", d * frame.z + a * joint.x)
        centre = point.locatenew(f"G{i + 1}", sum(c * axis for c, axis in zip(centres[i], (link.x, link.y, link.z))))
        body = reference.body(f"link{i + 1}")
        inertia = me.inertia(link, *[body.inertia[k, k] for k in range(3)],
                             body.inertia[0, 1], body.inertia[1, 2], body.inertia[0, 2])
        bodies.append(me.RigidBody(f"B{i + 1}", centre, link, body.mass, (inertia, centre)))
        loads.append((centre, -body.mass * g * ground.z))
        frame = link
    for body in bodies:
        body.masscenter.set_vel(ground, body.masscenter.pos_from(origin).dt(ground))
    kinematics = [qi.diff() - ui for qi, ui in zip(q, u)]
    kane = me.KanesMethod(ground, q_ind=q, u_ind=u, kd_eqs=kinematics)
    kane.kanes_equations(bodies, loads)
    return kane, q


def work_sympy(case: str) -> dict:
    start = time.perf_counter()
    kane, q = ur5_kanes()
    mass_matrix = kane.mass_matrix
    seconds = time.perf_counter() - start
    import numpy as np

    import kronlag
    rng = np.random.default_rng(1)
    point = dict(zip(q, rng.uniform(-3, 3, 6)))
    theirs = np.array(mass_matrix.subs(point).evalf(), float)
    ours = kronlag.derive(kronlag.models.ur5()).numeric({"g": 9.81} | {f"tau{i}": 0 for i in range(1, 7)},
                                                         backend="numpy").M(np.array(list(point.values())))
    return {"seconds": seconds, "max_difference_of_M": float(np.abs(theirs - ours).max())}


def measure(tool: str, case: str, budget: float) -> dict:
    try:
        proc = subprocess.run([sys.executable, SCRIPT, "--worker", tool, case], capture_output=True, text=True,
                              timeout=budget)
    except subprocess.TimeoutExpired:
        return {"timeout": budget}
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "failed"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="kronlag cases only")
    parser.add_argument("--worker", nargs=2, metavar=("TOOL", "CASE"), help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.worker:
        tool, case = arguments.worker
        print(json.dumps((work_kronlag if tool == "kronlag" else work_sympy)(case)))
        return
    print(f"# python {platform.python_version()}, {platform.machine()}, {os.cpu_count()} cores")
    print(f"{'case':24s} {'seconds':>10s}  note")
    results = {}
    for case in ("ur5", "panda", "ur5 matrix"):
        runs = [measure("kronlag", case, KRONLAG_BUDGET_S) for _ in range(REPEATS)]
        times = [run["seconds"] for run in runs if "seconds" in run]
        results[case] = min(times) if times else None
        target = TARGETS_S.get(case)
        note = "" if target is None else f"target <= {target} s: {'met' if times and min(times) <= target else 'MISSED'}"
        shown = f"{min(times):10.3f}" if times else f"{'failed':>10s}"
        print(f"{'kronlag ' + case:24s} {shown}  {note or runs[0].get('error', '')}")
    if arguments.quick:
        return
    sympy = measure("sympy", "ur5", SYMPY_BUDGET_S)
    if "seconds" in sympy:
        ratio = sympy["seconds"] / results["ur5"]
        print(f"{'sympy ur5 KanesMethod':24s} {sympy['seconds']:10.3f}  ratio (sympy/kronlag) {ratio:.1f}; "
              f"max |M_sympy - M_kronlag| = {sympy['max_difference_of_M']:.2e}")
    elif "timeout" in sympy:
        print(f"{'sympy ur5 KanesMethod':24s} {'>' + format(SYMPY_BUDGET_S, '.0f'):>10s}  not finished within the "
              f"budget: ratio (sympy/kronlag) > {SYMPY_BUDGET_S / results['ur5']:.0f}")
    else:
        print(f"{'sympy ur5 KanesMethod':24s} {'failed':>10s}  {sympy['error']}")


if __name__ == "__main__":
    main()
