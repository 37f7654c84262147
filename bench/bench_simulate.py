#!/usr/bin/env python3
"""Simulation-time benchmark: kronlag.simulate against what a SymPy user does today.

Run by hand (not a pytest test)::

    python3 bench/bench_simulate.py              # the figures against their targets, a few minutes
    python3 bench/bench_simulate.py --quick      # smoke test: 2 s span, 3 blocks
    python3 bench/bench_simulate.py --accuracy   # also the table of every method's accuracy
    python3 bench/bench_simulate.py --json -     # also write bench/results/bench_simulate.json

The figures (:mod:`common`: interleaved in one process, medians over blocks, the machine load):

* every step (``t_eval=None``): one ``kronlag.simulate`` call (method ``auto``, and method ``dop853``,
  its accelerations, multipliers, energies and residuals at every step computed in C by the driver) against
  ``solve_ivp`` DOP853 on the SymPy right-hand side at the same rtol 1e-8, atol 1e-10, also at
  every step; target >= 30x; RK45 for information;
* outputs every 0.1 s (101 over 10 s), the same two, and kronlag's wall time (target <= 10 ms).

Each speed-up is given twice: in wall time (``time.perf_counter``) and in CPU time of the process
(``time.process_time``), the truer figure on a loaded machine, where other processes stretch the wall
time of the short kronlag call and of the long SymPy run differently.

The case: the four-bar of Van Khang (2011), Sec. 4.1 (l1, l2, l3, l4 = 0.2, 0.6,
0.5, 0.5 m; m1, m2, m3 = 1, 2, 1.5 kg; uniform bars, I_i = m_i l_i^2 / 12;
g = 9.81 m/s^2; no torque), released from rest at q1 = 0.3 rad and simulated for
10 s with rtol 1e-8, atol 1e-10, outputs every 0.1 s; the constraint drift
``max |Phi(q)|`` at the outputs must stay <= 1e-9.

The SymPy side, built independently with ``sympy.physics.mechanics``: frames,
points, rigid bodies, the Lagrangian (T - V), ``LagrangesMethod`` with the two
loop-closure equations as ``hol_coneqs`` and the torque as a load; then
``lambdify(..., cse=True)`` of ``mass_matrix_full`` and ``forcing_full`` (the
augmented system in [q, qd, lambda]); the right-hand side solves it with
``numpy.linalg.solve`` and ``scipy.integrate.solve_ivp`` integrates [q, qd]
(RK45, the default, and DOP853).  This index-1 form has no stabilization, so
when its drift at rtol 1e-8 exceeds 1e-9 the tolerance is tightened (rtol,
atol / 10 at a time) until it does not, and that run is what kronlag is
compared with (both runs are printed).

What is timed (``time.perf_counter``, best of several repeats): one call of
``kronlag.simulate`` (including the accelerations, multipliers, energies and
residuals it recomputes at the outputs), and one ``solve_ivp`` call for SymPy.
Model construction (derivation, code generation, compilation) is timed
separately and printed, for both.  Accuracy: ``max |q - q_ref|`` at the outputs
against kronlag's projection method at rtol 1e-12.  At rtol 1e-8 the compiled
path (BDF, order <= 5) is less accurate in ``q`` than the tightened SymPy run
that meets the drift limit, so the compiled path is also timed at tighter
tolerances and compared at equal accuracy.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from common import Record, add_arguments, interleaved, ratio

#: Targets of the compiled path: speed-up over SymPy + DOP853 at the same rtol (every step), wall
#: time with 101 outputs.
TARGET_SPEEDUP = 30.0
TARGET_SECONDS = 0.010
RTOL, ATOL = 1e-8, 1e-10
DRIFT_LIMIT = 1e-9

LENGTHS = (0.2, 0.6, 0.5, 0.5)
MASSES = (1.0, 2.0, 1.5)
GRAVITY = 9.81
Q1_START = 0.3


def parameters() -> dict[str, float]:
    l1, l2, l3, l4 = LENGTHS
    values = dict(l1=l1, l2=l2, l3=l3, l4=l4, g=GRAVITY, tau=0.0)
    for i, (mass, length) in enumerate(zip(MASSES, LENGTHS), start=1):
        values[f"m{i}"], values[f"I{i}"] = mass, mass * length ** 2 / 12
    return values


def best_time(function, repeats: int):
    """``(seconds, result)``: the best of ``repeats`` calls."""
    best, result = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return best, result


# -- SymPy ------------------------------------------------------------------------------------

def build_sympy():
    """``sympy.physics.mechanics`` four-bar -> ``rhs(t, y)`` for ``y = [q, qd]`` and ``Phi(q)``."""
    import sympy as sp
    from sympy.physics import mechanics as me

    q = me.dynamicsymbols("q1:4")
    qd = [me.dynamicsymbols(f"q{i}", 1) for i in range(1, 4)]
    l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau = sp.symbols("l1 l2 l3 l4 m1 m2 m3 I1 I2 I3 g tau")
    N = me.ReferenceFrame("N")
    A = me.Point("A")
    A.set_vel(N, 0)
    D = A.locatenew("D", l4 * N.x)
    D.set_vel(N, 0)
    frames = [me.ReferenceFrame(f"F{i}") for i in range(1, 4)]
    for frame, angle in zip(frames, q):
        frame.orient_axis(N, N.z, angle)
    B = A.locatenew("B", l1 * frames[0].x)
    B.v2pt_theory(A, N, frames[0])
    centres = [A.locatenew("G1", l1 / 2 * frames[0].x), B.locatenew("G2", l2 / 2 * frames[1].x),
               D.locatenew("G3", l3 / 2 * frames[2].x)]
    for centre, pivot, frame in zip(centres, (A, B, D), frames):
        centre.v2pt_theory(pivot, N, frame)
    bodies = []
    for i, (centre, frame, mass, inertia) in enumerate(zip(centres, frames, (m1, m2, m3), (I1, I2, I3))):
        body = me.RigidBody(f"link{i + 1}", centre, frame, mass, (me.inertia(frame, 0, 0, inertia), centre))
        body.potential_energy = mass * g * centre.pos_from(A).dot(N.y)
        bodies.append(body)
    closure = [l1 * sp.cos(q[0]) + l2 * sp.cos(q[1]) - l3 * sp.cos(q[2]) - l4,
               l1 * sp.sin(q[0]) + l2 * sp.sin(q[1]) - l3 * sp.sin(q[2])]
    lagrangian = me.Lagrangian(N, *bodies)
    method = me.LagrangesMethod(lagrangian, q, hol_coneqs=closure, forcelist=[(frames[0], tau * N.z)], frame=N)
    method.form_lagranges_equations()
    symbols = [l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau]
    values = parameters()
    p = [values[s.name] for s in symbols]
    x = sp.symbols("x0:6")  # plain symbols for [q, qd]
    replace = dict(zip(list(q) + qd, x))
    mass_full = sp.lambdify([x, symbols], method.mass_matrix_full.xreplace(replace), cse=True)
    forcing_full = sp.lambdify([x, symbols], method.forcing_full.xreplace(replace), cse=True)
    constraints = sp.lambdify([x, symbols], sp.Matrix(closure).xreplace(replace), cse=True)

    def rhs(t, y):
        return np.linalg.solve(mass_full(y, p), forcing_full(y, p)).ravel()[:6]

    return rhs, lambda y: np.asarray(constraints(y, p), dtype=float).ravel()


def run_sympy(rhs, phi, y0, t_eval, method: str, rtol: float, atol: float):
    from scipy.integrate import solve_ivp

    solution = solve_ivp(rhs, (t_eval[0], t_eval[-1]), y0, method=method, rtol=rtol, atol=atol, t_eval=t_eval)
    drift = max(np.max(np.abs(phi(y))) for y in solution.y.T)
    return solution, drift


# -- main -------------------------------------------------------------------------------------

def figures(record: Record, model, rhs, q0, qd0, span: float, blocks: int) -> None:
    """The speed-ups over SymPy + solve_ivp, every step and with 101 outputs, interleaved."""
    import kronlag
    from scipy.integrate import solve_ivp

    y0 = np.concatenate([q0, qd0])
    t_eval = np.linspace(0.0, span, int(round(span / 0.1)) + 1)
    for label, outputs in (("every step", None), (f"{len(t_eval)} outputs", t_eval)):
        run = kronlag.simulate(model, (0.0, span), q0, qd0, t_eval=outputs)
        sympy_run = solve_ivp(rhs, (0.0, span), y0, method="DOP853", rtol=RTOL, atol=ATOL, t_eval=outputs)
        print(f"\n{label}: kronlag {run.method} {len(run.t)} outputs, {run.steps} steps; "
              f"SymPy DOP853 {sympy_run.t.size} outputs, {sympy_run.nfev} evaluations")
        timings = interleaved({
            "kronlag": lambda: kronlag.simulate(model, (0.0, span), q0, qd0, t_eval=outputs),
            "kronlag dop853": lambda: kronlag.simulate(model, (0.0, span), q0, qd0, t_eval=outputs, method="dop853"),
            "sympy DOP853": lambda: solve_ivp(rhs, (0.0, span), y0, method="DOP853", rtol=RTOL, atol=ATOL,
                                              t_eval=outputs),
            "sympy RK45": lambda: solve_ivp(rhs, (0.0, span), y0, method="RK45", rtol=RTOL, atol=ATOL,
                                            t_eval=outputs),
        }, blocks=blocks, repeats=3)
        for name, timing in timings.items():
            print(f"  {name:14s} {timing}, CPU {timing.cpu_median * 1e3:.3g} ms")
        kronlag_time, sympy_time = timings["kronlag"], timings["sympy DOP853"]
        target = TARGET_SPEEDUP if outputs is None else None
        record.figure(f"four-bar {span:g} s, {label}: speed-up over SymPy + DOP853 (rtol {RTOL:g})",
                      ratio(timings, "sympy DOP853", "kronlag"), unit="x", target=target,
                      detail=f"kronlag {kronlag_time}, SymPy {sympy_time}")
        record.figure(f"four-bar {span:g} s, {label}: speed-up over SymPy + DOP853 in CPU time (rtol {RTOL:g})",
                      ratio(timings, "sympy DOP853", "kronlag", cpu=True), unit="x", target=target,
                      detail=f"kronlag {kronlag_time.cpu_median * 1e3:.3g} ms, SymPy {sympy_time.cpu_median * 1e3:.3g} ms "
                             "CPU (medians)")
        record.figure(f"four-bar {span:g} s, {label}: speed-up over SymPy + RK45 (rtol {RTOL:g})",
                      ratio(timings, "sympy RK45", "kronlag"), unit="x")
        fast = timings["kronlag dop853"]
        record.figure(f"four-bar {span:g} s, {label}, method 'dop853': speed-up over SymPy + DOP853 (rtol {RTOL:g})",
                      ratio(timings, "sympy DOP853", "kronlag dop853"), unit="x", target=target,
                      detail=f"kronlag dop853 {fast}, SymPy {sympy_time}")
        record.figure(f"four-bar {span:g} s, {label}, method 'dop853': speed-up over SymPy + DOP853 in CPU time "
                      f"(rtol {RTOL:g})", ratio(timings, "sympy DOP853", "kronlag dop853", cpu=True), unit="x",
                      target=target, detail=f"kronlag dop853 {fast.cpu_median * 1e3:.3g} ms, SymPy "
                                            f"{sympy_time.cpu_median * 1e3:.3g} ms CPU (medians)")
        if outputs is not None:
            for method, timing in (("", kronlag_time), (", method 'dop853'", fast)):
                record.figure(f"four-bar {span:g} s, {label}{method}: kronlag wall time", timing.median * 1e3,
                              unit=" ms", target=TARGET_SECONDS * 1e3, better="lower")
                record.figure(f"four-bar {span:g} s, {label}{method}: kronlag CPU time", timing.cpu_median * 1e3,
                              unit=" ms", target=TARGET_SECONDS * 1e3, better="lower")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 s span, 3 blocks (smoke test)")
    parser.add_argument("--accuracy", action="store_true", help="also the table of every method's accuracy")
    add_arguments(parser)
    args = parser.parse_args()
    record = Record("bench_simulate", args)
    span = 2.0 if args.quick else 10.0

    import kronlag

    start = time.perf_counter()
    model = kronlag.derive(kronlag.models.four_bar()).numeric(parameters(), backend="c")
    q0, qd0 = model.assemble([Q1_START, 0.8, 1.3], fixed={"q1": Q1_START})
    kronlag.simulate(model, (0.0, 0.1), q0, qd0)  # builds the driver libraries
    kronlag_build = time.perf_counter() - start

    start = time.perf_counter()
    rhs, phi = build_sympy()
    sympy_build = time.perf_counter() - start
    print(f"model build: kronlag {kronlag_build:.2f} s (derive, C code, compile; cached on disk), "
          f"sympy {sympy_build:.2f} s (LagrangesMethod, lambdify)")
    figures(record, model, rhs, q0, qd0, span, blocks=3 if args.quick else 9)
    if args.accuracy:
        accuracy_table(model, rhs, phi, q0, qd0, span, repeats=3 if args.quick else 20)
    record.finish()


def accuracy_table(model, rhs, phi, q0, qd0, span: float, repeats: int) -> None:
    """Every method's time and accuracy at 101 outputs, the compiled path at tighter tolerances, and
    SymPy tightened until its drift meets :data:`DRIFT_LIMIT` (best of ``repeats``, not interleaved)."""
    import kronlag
    from kronlag.simulation import METHODS

    t_eval = np.linspace(0.0, span, int(round(span / 0.1)) + 1)
    reference = kronlag.simulate(model, (0.0, span), q0, qd0, method="projection", rtol=1e-12, atol=1e-12,
                                 t_eval=t_eval)
    print(f"\nfour-bar, {span:g} s, outputs every 0.1 s, rtol 1e-8, atol 1e-10, drift limit {DRIFT_LIMIT:g}")
    header = (f"{'method':<22}{'time [ms]':>11}{'steps':>8}{'nfev':>8}{'max|Phi|':>11}{'max|vel|':>11}"
              f"{'max|q-ref|':>12}{'|dE|/E':>10}")
    print()
    print(header)
    print("-" * len(header))
    times = {}
    for name in ["auto", *sorted(METHODS)]:
        count = repeats if name in ("auto", "compiled") else max(1, repeats // 10)
        elapsed, run = best_time(lambda: kronlag.simulate(model, (0.0, span), q0, qd0, method=name,
                                                          t_eval=t_eval), count)
        times[name] = elapsed
        label = f"{name} ({run.method})" if name == "auto" else name
        if not run.success:  # a failed run is reported, not compared
            print(f"{label:<22}{elapsed * 1e3:>11.2f}{run.steps:>8}{run.nfev:>8}   FAILED: {run.message}")
            continue
        energy = np.ptp(run.total_energy) / abs(run.total_energy[0])
        print(f"{label:<22}{elapsed * 1e3:>11.2f}{run.steps:>8}{run.nfev:>8}"
              f"{np.max(np.abs(run.position_residual)):>11.1e}{np.max(np.abs(run.velocity_residual)):>11.1e}"
              f"{np.max(np.abs(run.q - reference.q)):>12.1e}{energy:>10.1e}")

    tighter = []  # the compiled path at tighter tolerances: (seconds, error)
    for rtol in (1e-9, 1e-10, 1e-11, 1e-12, 1e-13):
        elapsed, run = best_time(lambda: kronlag.simulate(model, (0.0, span), q0, qd0, method="compiled",
                                                          rtol=rtol, atol=rtol / 100, t_eval=t_eval), repeats)
        error = np.max(np.abs(run.q - reference.q))
        tighter.append((elapsed, error))
        energy = np.ptp(run.total_energy) / abs(run.total_energy[0])
        print(f"{f'compiled rtol {rtol:.0e}':<22}{elapsed * 1e3:>11.2f}{run.steps:>8}{run.nfev:>8}"
              f"{np.max(np.abs(run.position_residual)):>11.1e}{np.max(np.abs(run.velocity_residual)):>11.1e}"
              f"{error:>12.1e}{energy:>10.1e}")

    y0 = np.concatenate([q0, qd0])
    sympy_runs = []
    for method in ("RK45", "DOP853"):
        rtol, atol = 1e-8, 1e-10
        while True:
            elapsed, (solution, drift) = best_time(lambda: run_sympy(rhs, phi, y0, t_eval, method, rtol, atol),
                                                   max(1, repeats // 10))
            error = np.max(np.abs(solution.y[:3].T - reference.q))
            meets = drift <= DRIFT_LIMIT
            sympy_runs.append((elapsed, method, rtol, meets, error))
            print(f"{f'sympy {method} rtol {rtol:.0e}':<22}{elapsed * 1e3:>11.2f}{'':>8}{solution.nfev:>8}"
                  f"{drift:>11.1e}{'':>11}{error:>12.1e}{'':>10}{'' if meets else '  (drift > limit)'}")
            if meets or rtol <= 1e-13:
                break
            rtol, atol = rtol / 10, atol / 10

    compiled = times["auto"]
    fastest = min((run for run in sympy_runs if run[3]), default=None)
    same_rtol = min(run[0] for run in sympy_runs if run[2] == 1e-8)
    print()
    if fastest is not None:
        print(f"speed-up of kronlag (auto) over the fastest SymPy run within the drift limit "
              f"(solve_ivp {fastest[1]}, rtol {fastest[2]:.0e}): {fastest[0] / compiled:.0f}x")
        matched = [elapsed for elapsed, error in tighter if error <= fastest[4]]
        if matched:
            print(f"at equal accuracy (max |q - q_ref| <= {fastest[4]:.1e}, the error of that SymPy run): "
                  f"compiled {min(matched) * 1e3:.2f} ms, speed-up {fastest[0] / min(matched):.0f}x")
    print(f"speed-up over the fastest SymPy run at the same rtol 1e-8 (drift not required): "
          f"{same_rtol / compiled:.0f}x")
    print(f"kronlag (auto) wall time: {compiled * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
