#!/usr/bin/env python3
"""Derivation-time benchmark: kronlag against sympy.physics.mechanics.LagrangesMethod.

Run by hand (not a pytest test)::

    python3 bench/bench_derive.py            # full run, several minutes
    python3 bench/bench_derive.py --quick    # smoke test: n = 3, 4 only
    python3 bench/bench_derive.py --json -   # also write bench/results/bench_derive.json

Both tools derive the equations of motion of the same closed planar chain of
``n`` uniform links (``kronlag.models.closed_chain``): links ``l1..ln``,
masses ``m1..mn``, central inertias ``I1..In``, first link pinned at the
origin, tip of the last pinned at the ground point ``(xg, yg)``, gravity ``g``
along -y, coordinates ``q1..qn`` either absolute link angles or relative joint
angles.  The SymPy model is built independently below with
``sympy.physics.mechanics`` (frames, points, rigid bodies, gravity loads, the
Lagrangian and ``LagrangesMethod`` with the two loop-closure equations as
``hol_coneqs``).

What is timed (``time.perf_counter``, imports excluded on both sides):

* kronlag: ``closed_chain(n, angles)``, ``derive(...)`` and reading
  ``eom.M``, ``eom.C``, ``eom.g``, ``eom.Phi_q``;
* SymPy: building the mechanics model, the Lagrangian, ``LagrangesMethod``
  and ``form_lagranges_equations()`` (which forms the mass matrix, the forcing
  vector and the constraint Jacobian eagerly).

Every single measurement runs in a fresh Python subprocess, because SymPy's and
SymEngine's caches would otherwise make later cases (and repeats) look faster
than a cold derivation.  Fast cases are repeated and the best time is kept.
A SymPy case that exceeds its time budget is killed and reported as a lower
bound.  Before timing, a sanity check confirms at a random numerical point
that for ``n = 3`` both tools produce the same ``M``, ``C qd + g`` and
``Phi_q``, so the comparison is between equal things.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

from common import Record, add_arguments

SCRIPT = os.path.abspath(__file__)

#: SymPy time budget per case (seconds); a case that runs longer is killed.
SYMPY_BUDGET_S = 300.0
#: kronlag time budget per case (seconds); generous, only guards against hangs.
KRONLAG_BUDGET_S = 600.0
#: Cases faster than this are repeated (best of ``REPEATS`` fresh processes).
REPEAT_BELOW_S = 10.0
REPEATS = 3

FULL_COMPARE = [(n, a) for a in ("absolute", "relative") for n in (3, 4, 6, 8)]
QUICK_COMPARE = [(n, a) for a in ("absolute", "relative") for n in (3, 4)]

#: Targets: (n, angles, kind, value).  kind "speedup": sympy/kronlag >= value;
#: kind "seconds": kronlag time <= value.
TARGETS = [
    (8, "relative", "speedup", 300.0),
    (20, "relative", "seconds", 5.0),
    (50, "absolute", "seconds", 5.0),
]
KRONLAG_ONLY = [(20, "relative"), (50, "absolute")]
#: Growth of the derivation for the numeric model (``derive`` alone: its matrices stay in SymEngine
#: until read) in both conventions (issue 19: no worse than about n^2.5), sizes per convention.
GROWTH_SIZES = {"relative": (10, 20, 40), "absolute": (25, 50, 100)}
GROWTH_TARGET = 2.5


# --------------------------------------------------------------------------
# Workers: each runs in its own subprocess and prints one JSON line.
# --------------------------------------------------------------------------

def build_sympy_chain(n: int, angles: str):
    """The closed chain with sympy.physics.mechanics; returns (LagrangesMethod, q)."""
    import sympy as sp
    from sympy.physics import mechanics as me

    q = me.dynamicsymbols(f"q1:{n + 1}")
    lengths = sp.symbols(f"l1:{n + 1}")
    masses = sp.symbols(f"m1:{n + 1}")
    inertias = sp.symbols(f"I1:{n + 1}")
    xg, yg, g = sp.symbols("xg yg g")

    N = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(N, 0)

    bodies, loads = [], []
    parent, joint = N, O
    for i in range(n):
        frame = me.ReferenceFrame(f"B{i + 1}")
        if angles == "absolute":
            frame.orient_axis(N, N.z, q[i])
        else:  # joint angle relative to the previous link (link 1: to the ground)
            frame.orient_axis(parent, parent.z, q[i])
        centre = joint.locatenew(f"G{i + 1}", lengths[i] / 2 * frame.x)
        centre.v2pt_theory(joint, N, frame)
        tip = joint.locatenew(f"P{i + 2}", lengths[i] * frame.x)
        tip.v2pt_theory(joint, N, frame)
        body = me.RigidBody(f"link{i + 1}", centre, frame, masses[i],
                            (me.inertia(frame, 0, 0, inertias[i]), centre))
        bodies.append(body)
        loads.append((centre, -masses[i] * g * N.y))
        parent, joint = frame, tip

    tip_position = joint.pos_from(O)
    closure = [tip_position.dot(N.x) - xg, tip_position.dot(N.y) - yg]
    L = me.Lagrangian(N, *bodies)  # kinetic energy only; gravity enters as loads
    lm = me.LagrangesMethod(L, q, hol_coneqs=closure, forcelist=loads, frame=N)
    lm.form_lagranges_equations()
    return lm, q


def worker_sympy(n: int, angles: str) -> dict:
    import sympy  # noqa: F401  (imports are not timed)
    from sympy.physics import mechanics  # noqa: F401

    start = time.perf_counter()
    lm, _ = build_sympy_chain(n, angles)
    _ = lm.mass_matrix, lm.forcing
    return {"seconds": time.perf_counter() - start}


def worker_kronlag(n: int, angles: str) -> dict:
    import kronlag

    start = time.perf_counter()
    eom = kronlag.derive(kronlag.models.closed_chain(n, angles))
    _ = eom.M, eom.C, eom.g, eom.Phi_q
    return {"seconds": time.perf_counter() - start}


def worker_derive(n: int, angles: str) -> dict:
    """``derive`` alone, what building the numeric model needs (no SymPy matrix is formed): CPU
    seconds of this process, which other jobs on a shared machine disturb less than the wall clock."""
    import kronlag

    start = time.process_time()
    kronlag.derive(kronlag.models.closed_chain(n, angles))
    return {"seconds": time.process_time() - start}


def growth_exponent(sizes, seconds) -> float:
    """Least-squares slope of log(seconds) against log(n)."""
    import numpy as np

    return float(np.polyfit(np.log(sizes), np.log(seconds), 1)[0])


def worker_sanity(n: int, angles: str) -> dict:
    """Compare M, C qd + g and Phi_q of both tools at a random point."""
    import random

    import sympy as sp
    from sympy.physics import mechanics as me

    import kronlag

    eom = kronlag.derive(kronlag.models.closed_chain(n, angles))
    lm, q = build_sympy_chain(n, angles)

    t = me.dynamicsymbols._t
    # dynamicsymbols -> kronlag symbols (second derivatives first; msubs handles it).
    mapping = {}
    for qi, sym, spd, acc in zip(q, eom.coordinates, eom.speeds, eom.accelerations):
        mapping[qi.diff(t, 2)] = acc
        mapping[qi.diff(t)] = spd
        mapping[qi] = sym

    rng = random.Random(12345)
    point = {s: sp.Float(rng.uniform(0.3, 1.7)) for s in eom.parameters}
    point.update({s: sp.Float(rng.uniform(-3.0, 3.0)) for s in eom.coordinates + eom.speeds})

    def num(matrix):
        return sp.Matrix(me.msubs(sp.Matrix(matrix), mapping)).subs(point).evalf()

    M_sympy = num(lm.mass_matrix[:, :n])
    Phi_q_sympy = -num(lm.mass_matrix[:, n:]).T  # columns hold lam_coeffs^T = -Phi_q^T
    Cg_sympy = -num(lm.forcing)  # forcing = -(C qd + g)

    qd = sp.Matrix(eom.speeds)
    M_kron = sp.Matrix(eom.M).subs(point).evalf()
    Cg_kron = (sp.Matrix(eom.C) * qd + sp.Matrix(eom.g)).subs(point).evalf()
    Phi_q_kron = sp.Matrix(eom.Phi_q).subs(point).evalf()

    def err(a, b):
        scale = max(1.0, max(abs(float(x)) for x in b))
        return max(abs(float(x - y)) for x, y in zip(a, b)) / scale

    errors = {"M": err(M_kron, M_sympy), "C qd + g": err(Cg_kron, Cg_sympy),
              "Phi_q": err(Phi_q_kron, Phi_q_sympy)}
    return {"errors": errors, "ok": all(e < 1e-9 for e in errors.values())}


WORKERS = {"sympy": worker_sympy, "kronlag": worker_kronlag, "derive": worker_derive, "sanity": worker_sanity}


# --------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------

class CaseError(RuntimeError):
    pass


def run_worker(kind: str, n: int, angles: str, timeout: float) -> dict | None:
    """Run one worker in a fresh interpreter; ``None`` if it ran past ``timeout``."""
    cmd = [sys.executable, SCRIPT, "--worker", kind, str(n), angles]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:  # subprocess.run kills the child
        return None
    if proc.returncode != 0:
        raise CaseError(f"{kind} worker n={n} {angles} failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if not lines:
        raise CaseError(f"{kind} worker n={n} {angles} printed no result:\n{proc.stdout[-2000:]}")
    return json.loads(lines[-1])


def best_time(kind: str, n: int, angles: str, budget: float, repeats: int) -> float | None:
    """Best of up to ``repeats`` fresh-process runs; ``None`` if the first exceeds ``budget``."""
    best = None
    for _ in range(repeats):
        result = run_worker(kind, n, angles, budget)
        if result is None:
            return best  # None on the first run; a later timeout keeps the best so far
        seconds = result["seconds"]
        best = seconds if best is None else min(best, seconds)
        if seconds >= REPEAT_BELOW_S:
            break  # slow case: one run is enough
    return best


def fmt_seconds(seconds: float | None, budget: float) -> str:
    return f">{budget:.0f} s" if seconds is None else f"{seconds:.3f}"


def ratio_of(kron: float | None, sympy: float | None, budget: float) -> tuple[float | None, bool]:
    """(ratio sympy/kronlag, is_lower_bound)."""
    if kron is None:
        return None, False
    if sympy is None:
        return budget / kron, True
    return sympy / kron, False


def fmt_ratio(ratio: float | None, lower_bound: bool) -> str:
    if ratio is None:
        return "-"
    prefix = ">" if lower_bound else ""
    return f"{prefix}{ratio:.0f}x" if ratio >= 10 else f"{prefix}{ratio:.1f}x"


def target_of(n: int, angles: str, kind: str) -> float | None:
    """The value of :data:`TARGETS` for this case and kind (None: none)."""
    return next((value for size, convention, what, value in TARGETS
                 if (size, convention, what) == (n, angles, kind)), None)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only (n = 3, 4), one run each")
    parser.add_argument("--sympy-budget", type=float, default=SYMPY_BUDGET_S,
                        help=f"SymPy time budget per case in seconds (default {SYMPY_BUDGET_S:.0f})")
    parser.add_argument("--worker", nargs=3, metavar=("KIND", "N", "ANGLES"), help=argparse.SUPPRESS)
    add_arguments(parser)
    args = parser.parse_args(argv)

    if args.worker:
        kind, n, angles = args.worker
        print(json.dumps(WORKERS[kind](int(n), angles)), flush=True)
        return 0

    import sympy

    record = Record("bench_derive", args)
    budget = args.sympy_budget
    repeats = 1 if args.quick else REPEATS
    compare = QUICK_COMPARE if args.quick else FULL_COMPARE
    print(f"kronlag vs sympy.physics.mechanics.LagrangesMethod -- closed_chain(n), "
          f"{'quick' if args.quick else 'full'} run")
    print(f"python {platform.python_version()}, sympy {sympy.__version__}, {os.cpu_count()} CPU(s) "
          f"(shared machines make timings noisy); each measurement in a fresh process, "
          f"best of {repeats} for cases under {REPEAT_BELOW_S:.0f} s; SymPy budget {budget:.0f} s per case")
    print(flush=True)

    # Sanity check: both tools derive the same equations.
    status = 0
    sanity = run_worker("sanity", 3, "relative", KRONLAG_BUDGET_S)
    sanity_abs = run_worker("sanity", 3, "absolute", KRONLAG_BUDGET_S)
    for angles, result in (("absolute", sanity_abs), ("relative", sanity)):
        errs = ", ".join(f"{k} {v:.1e}" for k, v in result["errors"].items())
        verdict = "OK" if result["ok"] else "MISMATCH"
        print(f"sanity n=3 {angles:8s}: kronlag vs SymPy relative errors at a random point: {errs} -> {verdict}")
        if not result["ok"]:
            status = 1
    print(flush=True)

    header = f"{'n':>3}  {'angles':8s}  {'kronlag s':>10}  {'sympy s':>10}  {'ratio (sympy/kronlag)':>21}"
    print(header)
    print("-" * len(header), flush=True)
    results: dict[tuple[int, str], tuple[float | None, float | None]] = {}
    for n, angles in compare:
        kron = best_time("kronlag", n, angles, KRONLAG_BUDGET_S, repeats)
        sym = best_time("sympy", n, angles, budget, repeats)
        results[(n, angles)] = (kron, sym)
        ratio, lower = ratio_of(kron, sym, budget)
        print(f"{n:>3}  {angles:8s}  {fmt_seconds(kron, KRONLAG_BUDGET_S):>10}  "
              f"{fmt_seconds(sym, budget):>10}  {fmt_ratio(ratio, lower):>21}", flush=True)
        if ratio is not None:
            record.figure(f"closed_chain({n}, {angles}) derivation: SymPy LagrangesMethod / kronlag", ratio, unit="x",
                          target=target_of(n, angles, "speedup"),
                          detail=f"kronlag {kron:.3g} s, best of {repeats} fresh processes"
                          + ("; lower bound: SymPy hit its budget" if lower else ""))

    if not args.quick:
        for n, angles in KRONLAG_ONLY:
            kron = best_time("kronlag", n, angles, KRONLAG_BUDGET_S, repeats)
            results[(n, angles)] = (kron, None)
            print(f"{n:>3}  {angles:8s}  {fmt_seconds(kron, KRONLAG_BUDGET_S):>10}  "
                  f"{'(not run)':>10}  {'-':>21}", flush=True)
            record.figure(f"closed_chain({n}, {angles}) derivation: kronlag",
                          KRONLAG_BUDGET_S if kron is None else kron, unit=" s",
                          target=target_of(n, angles, "seconds"), better="lower",
                          detail="did not finish" if kron is None else f"best of {repeats} fresh processes")

        print()
        print(f"growth of derive alone (the numeric model's derivation, CPU seconds), load average {os.getloadavg()[0]:.1f} "
              f"on {os.cpu_count()} CPU(s) at the start")
        for angles, sizes in GROWTH_SIZES.items():
            times = [best_time("derive", n, angles, KRONLAG_BUDGET_S, repeats) for n in sizes]
            listed = ", ".join(f"n={n}: {fmt_seconds(t, KRONLAG_BUDGET_S)} s" for n, t in zip(sizes, times))
            if None in times:
                print(f"  {angles:8s} {listed}  (a case did not finish)")
                continue
            exponent = growth_exponent(sizes, times)
            verdict = "PASS" if exponent <= GROWTH_TARGET else "MISS"
            print(f"  {angles:8s} {listed}  ~ n^{exponent:.2f} (target <= n^{GROWTH_TARGET}) {verdict}")
            record.figure(f"closed_chain, {angles}: growth exponent of derive (CPU)", exponent, target=GROWTH_TARGET,
                          better="lower", detail=listed)

        print()
        print("targets")
        for n, angles, kind, value in TARGETS:
            kron, sym = results.get((n, angles), (None, None))
            if kind == "speedup":
                ratio, lower = ratio_of(kron, sym, budget)
                label = f"n={n} {angles}: sympy/kronlag >= {value:.0f}x"
                if ratio is None:
                    verdict, got = "MISS", "kronlag did not finish"
                elif ratio >= value:
                    verdict, got = "PASS", fmt_ratio(ratio, lower)
                elif lower:
                    verdict, got = "UNDECIDED", f"{fmt_ratio(ratio, lower)} (SymPy hit its budget)"
                else:
                    verdict, got = "MISS", f"{fmt_ratio(ratio, lower)} ({value / ratio:.2f}x short)"
            else:
                label = f"n={n} {angles}: kronlag <= {value:.0f} s"
                if kron is None:
                    verdict, got = "MISS", "did not finish"
                elif kron <= value:
                    verdict, got = "PASS", f"{kron:.2f} s"
                else:
                    verdict, got = "MISS", f"{kron:.2f} s ({kron - value:.2f} s / {kron / value:.2f}x over)"
            print(f"  {label:42s} {got:32s} {verdict}")
    record.finish()
    return status


if __name__ == "__main__":
    sys.exit(main())
