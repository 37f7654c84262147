#!/usr/bin/env python3
"""Batched evaluation over many states against a Python loop of single calls.

Run by hand (not a pytest test)::

    python3 bench/bench_batch.py                 # four-bar, 1e5 states
    python3 bench/bench_batch.py --states 1000   # smoke test

The four-bar (``kronlag.models.four_bar``, constant torque ``tau = 1``) at random states:

* ``model.forward_dynamics_batch(q, qd)`` (C, one call, threads: ``$KRONLAG_THREADS`` or all CPUs)
  against a Python loop of ``model.forward_dynamics(q[i], qd[i])`` (C backend);
* ``model.evaluate_batch("M", q)`` against a loop of ``model.M(q[i])``;
* the Python backend's batch (NumPy-vectorised kernels), for information.

Prints microseconds per state and the speed-up of the batch over the loop.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import kronlag
from kronlag import codegen, models

FOUR_BAR = dict(l1=1.0, l2=2.0, l3=2.0, l4=2.0, m1=1.0, m2=2.0, m3=2.0, I1=1 / 12, I2=2 / 3, I3=2 / 3, g=9.81,
                tau=1.0)


def per_state(function, n: int, repeat: int = 5) -> float:
    """Best wall time of ``function()`` over ``repeat`` runs, in microseconds per state."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best / n * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=100_000, help="states in a batch")
    arguments = parser.parse_args()
    n = arguments.states
    loop_n = min(n, 10_000)
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
          f"numpy {np.__version__}, {codegen.batch_threads()} thread(s) for batches")
    eom = kronlag.derive(models.four_bar())
    c_model = eom.numeric(FOUR_BAR, backend="c")
    python_model = eom.numeric(FOUR_BAR, backend="python")
    rng = np.random.default_rng(0)
    q, qd = rng.uniform(-3, 3, (n, 3)), rng.uniform(-3, 3, (n, 3))

    batch = c_model.forward_dynamics_batch(q, qd)
    for i in range(0, n, max(1, n // 50)):
        single = c_model.forward_dynamics(q[i], qd[i])
        assert np.allclose(batch.qdd[i], single.qdd, rtol=1e-12, atol=1e-12)

    rows = {
        "forward dynamics, C batch": per_state(lambda: c_model.forward_dynamics_batch(q, qd), n),
        "forward dynamics, loop of C calls": per_state(
            lambda: [c_model.forward_dynamics(q[i], qd[i]) for i in range(loop_n)], loop_n, repeat=3),
        "forward dynamics, Python backend batch": per_state(
            lambda: python_model.forward_dynamics_batch(q[:loop_n // 10], qd[:loop_n // 10]), loop_n // 10,
            repeat=1),
        "M, C batch": per_state(lambda: c_model.evaluate_batch("M", q), n),
        "M, loop of C calls": per_state(lambda: [c_model.M(q[i]) for i in range(loop_n)], loop_n, repeat=3),
        "M, Python backend batch (NumPy)": per_state(lambda: python_model.evaluate_batch("M", q), n, repeat=3),
    }
    print(f"\nfour-bar, {n} states; microseconds per state")
    for name, value in rows.items():
        print(f"  {name:40s} {value:8.3f}")
    fd_speedup = rows["forward dynamics, loop of C calls"] / rows["forward dynamics, C batch"]
    m_speedup = rows["M, loop of C calls"] / rows["M, C batch"]
    print(f"\nbatch speed-up over the loop: forward dynamics {fd_speedup:.1f}x, M {m_speedup:.1f}x "
          "(target >= 5x)")
    print(f"forward dynamics batch: {rows['forward dynamics, C batch']:.3f} us/state (target <= 1 us/state)")


if __name__ == "__main__":
    main()
