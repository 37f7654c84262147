#!/usr/bin/env python3
"""What watching limits costs (issue 18, item 5): a run with a limit that is never reached against
the same run without it, at the same tolerances.  Target: ratio <= 1.5.

Run by hand (not a pytest test)::

    python3 bench/bench_limits.py            # 10 s runs, best of 7
    python3 bench/bench_limits.py --quick    # 2 s runs, best of 3

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


def _best(model, q0, qd0, t_end: float, method: str, repeats: int) -> tuple[float, kronlag.Trajectory]:
    t_eval = np.linspace(0.0, t_end, int(round(100 * t_end)) + 1)
    kronlag.simulate(model, (0.0, t_end), q0, qd0, method=method, t_eval=t_eval)  # warm-up (compiles)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        trajectory = kronlag.simulate(model, (0.0, t_end), q0, qd0, method=method, t_eval=t_eval,
                                      rtol=1e-8, atol=1e-10)
        times.append(time.perf_counter() - started)
    return min(times), trajectory


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 s runs, best of 3")
    arguments = parser.parse_args()
    t_end, repeats = (2.0, 3) if arguments.quick else (10.0, 7)
    print(f"{'case':<14} {'method':<11} {'without (s)':>12} {'with (s)':>10} {'ratio':>7}  {'max |dq|':>9}  target")
    worst = 0.0
    for name in ("four_bar", "slider_crank"):
        model_file, plain, limited = _models(name)
        q0, qd0 = initial_state(model_file, plain)
        for method in ("switching", "projection"):
            without, reference = _best(plain, q0, qd0, t_end, method, repeats)
            with_limit, trajectory = _best(limited, q0, qd0, t_end, method, repeats)
            assert not [event for event in trajectory.events if hasattr(event, "side")], "the limit was reached"
            ratio = with_limit / without
            worst = max(worst, ratio)
            difference = float(np.max(np.abs(trajectory.q - reference.q)))
            print(f"{name:<14} {method:<11} {without:12.4f} {with_limit:10.4f} {ratio:7.2f}  {difference:9.2e}  "
                  f"<= {TARGET_RATIO} {'ok' if ratio <= TARGET_RATIO else 'MISSED'}")
    print(f"worst ratio {worst:.2f} (target <= {TARGET_RATIO})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
