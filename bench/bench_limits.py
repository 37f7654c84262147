#!/usr/bin/env python3
"""What watching limits costs (issue 18, item 5): a run with a limit that is never reached against
the same run without it, at the same tolerances.  Target: ratio <= 1.5.

Run by hand (not a pytest test)::

    python3 bench/bench_limits.py            # 10 s runs, best of 7
    python3 bench/bench_limits.py --quick    # 2 s runs, best of 3
    python3 bench/bench_limits.py --validate # also the validation table of the closed forms
    python3 bench/bench_limits.py --json -   # also write bench/results/bench_limits.json

The cases: the shipped four-bar and slider-crank model files (their parameter values and initial
states), simulated for the span with rtol 1e-8, atol 1e-10 and outputs every 0.01 s, by the default
method (switching: CVODE with root finding in C) and by the projection method (DOP853 in Python,
the watch evaluated after every step).  The limits: the crank tip's height ``l1 sin q1 >= -10 l1``
on the four-bar and the slider's travel ``-10 <= x <= 10`` on the slider-crank, both never reached.
Times are ``time.perf_counter`` around ``kronlag.simulate``, best of the repeats, after a warm-up
run (which compiles).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sympy as sp

import kronlag
from kronlag.app.workflows import initial_state, numeric_model
from kronlag.model.builtin import example_path

from common import Record, add_arguments

TARGET_RATIO = 1.5


def _models(name: str):
    """The model of the shipped file ``name`` without and with a limit that is never reached."""
    plain = kronlag.load_model(example_path(name), apply_drives=False)
    limited = kronlag.load_model(example_path(name), apply_drives=False)
    if name == "four_bar":
        q1, l1 = sp.Symbol("q1"), sp.Symbol("l1")
        limited.system.add_limit(l1 * sp.sin(q1), lower=-10 * l1, restitution=0.5, name="tip")
    else:
        limited.system.add_limit(sp.Symbol("x"), lower=-10, upper=10, restitution=0.5, name="travel")
    return plain, numeric_model(plain), numeric_model(limited)


def _best(models, q0, qd0, t_end: float, method: str, repeats: int) -> list[tuple[float, kronlag.Trajectory]]:
    """The best time of each model's run and its trajectory; the runs alternate between the models
    (the machine's load falls on both alike)."""
    t_eval = np.linspace(0.0, t_end, int(round(100 * t_end)) + 1)
    for model in models:  # warm-up (compiles)
        kronlag.simulate(model, (0.0, t_end), q0, qd0, method=method, t_eval=t_eval)
    times: list[list[float]] = [[] for _ in models]
    trajectories = []
    for _ in range(repeats):
        trajectories = []
        for model, seconds in zip(models, times):
            started = time.perf_counter()
            trajectories.append(kronlag.simulate(model, (0.0, t_end), q0, qd0, method=method, t_eval=t_eval,
                                                 rtol=1e-8, atol=1e-10))
            seconds.append(time.perf_counter() - started)
    return [(min(seconds), trajectory) for seconds, trajectory in zip(times, trajectories)]


def _ball(e: float, m: float):
    y, m_, g_, e_ = sp.symbols("y m g e")
    system = kronlag.System([y], parameters=[m_, g_, e_], gravity=(0, -g_), name="ball")
    system.add_body(kronlag.PointMass("ball", mass=m_, position=[0, y]))
    system.add_limit(y, lower=0, restitution=e_, name="floor")
    return kronlag.derive(system).numeric({"m": m, "g": 9.81, "e": e})


def _pendulum(e: float):
    x, y, th, m, L, g, e_ = sp.symbols("x y th m L g e")
    system = kronlag.System([x, y, th], parameters=[m, L, g, e_], gravity=(0, -g), name="pendulum")
    system.add_body(kronlag.PlanarBody("rod", mass=m, inertia=m * L**2 / 12, position=[x, y], angle=th))
    system.add_joint("revolute", "ground", "rod", at_b=[-L / 2, 0], name="pivot")
    system.add_limit(th, lower=-sp.pi / 2, restitution=e_, name="stop")
    return kronlag.derive(system).numeric({"m": 2.0, "L": 0.8, "g": 9.81, "e": e})


def validation() -> None:
    """The validation table of the closed forms (docs/limits.md, tests/test_limits.py): case,
    reference, error, wall time of the run (default method, rtol 1e-8, atol 1e-10)."""
    rows = []
    e, h0, g, m = 0.5, 1.0, 9.81, 0.5
    model = _ball(e, m)
    t1 = np.sqrt(2 * h0 / g)
    times = t1 + np.concatenate([[0.0], np.cumsum([2 * e**k * t1 for k in range(1, 6)])])
    apexes = times[:-1] + e ** np.arange(1, 6) * t1
    kronlag.simulate(model, (0, 2.5), [h0], [0.0])  # warm-up: compiles the drivers and the contact model
    trajectory = kronlag.simulate(model, (0, 2.5), [h0], [0.0], t_eval=apexes)
    impacts = np.array([event.t for event in trajectory.events if event.kind == "impact"][:6])
    rows.append(("ball: impact times t_1..t_6", "t_k closed form", np.max(np.abs(impacts / times - 1)),
                 trajectory.wall_time))
    rows.append(("ball: apex heights k = 1..5", "e^(2k) h0",
                 np.max(np.abs(trajectory.q[:, 0] / (h0 * e ** (2 * np.arange(1, 6))) - 1)), trajectory.wall_time))
    resting = kronlag.simulate(model, (0, 2.5), [h0], [0.0])
    contact = next(event for event in resting.events if event.kind == "contact")
    rows.append(("ball: contact force at rest", "m g", abs(resting.limit_forces[-1, 0] / (m * g) - 1),
                 resting.wall_time))
    t_inf = t1 * (1 + 2 * e / (1 - e))
    rows.append(("ball: persistent contact time", "t_inf (Zeno)", abs(contact.t / t_inf - 1), resting.wall_time))
    pendulum = _pendulum(0.6)
    kronlag.simulate(pendulum, (0, 0.6), [0.4, 0.0, 0.0], [0.0, 0.0, 0.0])  # warm-up
    run = kronlag.simulate(pendulum, (0, 0.6), [0.4, 0.0, 0.0], [0.0, 0.0, 0.0])
    impact = next(event for event in run.events if event.kind == "impact")
    speed = np.sqrt(3 * g / 0.8)
    rows.append(("pendulum on a stop: rebound", "e sqrt(3 g / L)", abs(impact.speed_after / (0.6 * speed) - 1),
                 run.wall_time))
    after = np.flatnonzero(run.t == impact.t)[-1]
    rows.append(("pendulum: Phi_q qd+ (abs)", "0", float(np.max(np.abs(pendulum.Phi_q(run.q[after]) @ run.qd[after]))),
                 run.wall_time))
    print(f"{'case':<32} {'reference':<18} {'error (rel.)':>12} {'time (s)':>9}")
    for case, reference, error, seconds in rows:
        print(f"{case:<32} {reference:<18} {error:12.2e} {seconds:9.4f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 s runs, best of 3")
    parser.add_argument("--validate", action="store_true", help="also print the validation table")
    add_arguments(parser)
    arguments = parser.parse_args()
    record = Record("bench_limits", arguments)
    if arguments.validate:
        validation()
    t_end, repeats = (2.0, 3) if arguments.quick else (10.0, 7)
    print(f"{'case':<14} {'method':<11} {'without (s)':>12} {'with (s)':>10} {'ratio':>7}  {'max |dq|':>9}  target")
    worst = 0.0
    for name in ("four_bar", "slider_crank"):
        model_file, plain, limited = _models(name)
        q0, qd0 = initial_state(model_file, plain)
        for method in ("switching", "projection"):
            (without, reference), (with_limit, trajectory) = _best((plain, limited), q0, qd0, t_end, method,
                                                                   repeats)
            assert not [event for event in trajectory.events if hasattr(event, "side")], "the limit was reached"
            ratio = with_limit / without
            worst = max(worst, ratio)
            difference = float(np.max(np.abs(trajectory.q - reference.q)))
            print(f"{name:<14} {method:<11} {without:12.4f} {with_limit:10.4f} {ratio:7.2f}  {difference:9.2e}  "
                  f"<= {TARGET_RATIO} {'ok' if ratio <= TARGET_RATIO else 'MISSED'}")
            record.figure(f"{name} {t_end:g} s, {method} method: with an unreached limit / without", ratio,
                          unit="x", target=TARGET_RATIO, better="lower", detail=f"best of {repeats}")
    print(f"worst ratio {worst:.2f} (target <= {TARGET_RATIO})")
    record.finish()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
