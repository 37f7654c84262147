#!/usr/bin/env python3
"""JAX ``jit(vmap)`` forward dynamics against the C batch, interleaved in one process.

Run by hand (not a pytest test)::

    python3 bench/bench_jax.py                  # four-bar, 1e5 states, 9 blocks
    python3 bench/bench_jax.py --quick          # 1e4 states, 3 blocks (smoke test)
    python3 bench/bench_jax.py --json -         # also write bench/results/bench_jax.json

The four-bar (``kronlag.models.four_bar``, constant torque ``tau = 1``) at random states:
``jax.jit(jax.vmap(jax_functions(model)["forward_dynamics"], in_axes=(0, 0, None, None)))`` in
float64, compiled once before timing, each call ended by ``jax.block_until_ready``, against
``model.forward_dynamics_batch(q, qd)`` (C, threads: ``$KRONLAG_THREADS`` or all CPUs; the thread
count is printed), and, for information, against the C batch on one thread.  Both results are
checked against each other first.  Target: JAX within 2x of the C batch.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from common import Record, add_arguments, interleaved, ratio

import kronlag
from kronlag import codegen, models

FOUR_BAR = dict(l1=1.0, l2=2.0, l3=2.0, l4=2.0, m1=1.0, m2=2.0, m3=2.0, I1=1 / 12, I2=2 / 3, I3=2 / 3, g=9.81,
                tau=1.0)

#: JAX's time per batch over the C batch's, at most.
TARGET_RATIO = 2.0


def one_thread(function):
    """``function`` run with ``$KRONLAG_THREADS=1`` (the C batch reads it at every call)."""
    def run():
        previous = os.environ.get("KRONLAG_THREADS")
        os.environ["KRONLAG_THREADS"] = "1"
        try:
            return function()
        finally:
            if previous is None:
                del os.environ["KRONLAG_THREADS"]
            else:
                os.environ["KRONLAG_THREADS"] = previous
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1e4 states, 3 blocks (smoke test)")
    parser.add_argument("--states", type=int, default=None, help="states in a batch (default 1e5)")
    add_arguments(parser)
    args = parser.parse_args()
    record = Record("bench_jax", args)
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    from kronlag.symbolic.interop import jax_functions

    n = args.states or (10_000 if args.quick else 100_000)
    model = kronlag.derive(models.four_bar()).numeric(FOUR_BAR, backend="c")
    rng = np.random.default_rng(0)
    q, qd = rng.uniform(-3, 3, (n, 3)), rng.uniform(-3, 3, (n, 3))
    start = time.perf_counter()
    batched = jax.jit(jax.vmap(jax_functions(model)["forward_dynamics"], in_axes=(0, 0, None, None)))
    p, Q, QD = jnp.asarray(model.parameter_vector(0.0)), jnp.asarray(q), jnp.asarray(qd)
    qdd, lam, _ = jax.block_until_ready(batched(Q, QD, p, 0.0))
    compile_seconds = time.perf_counter() - start
    reference = model.forward_dynamics_batch(q, qd)
    error = max(np.max(np.abs(np.asarray(qdd) - reference.qdd) / (1 + np.abs(reference.qdd))),
                np.max(np.abs(np.asarray(lam) - reference.lam) / (1 + np.abs(reference.lam))))
    print(f"four-bar, {n} states, float64; jax {jax.__version__} on {jax.devices()[0].platform}, C batch on "
          f"{codegen.batch_threads()} thread(s); export + jit + first call {compile_seconds:.2f} s; "
          f"largest relative difference JAX - C {error:.1e}")
    if not error <= 1e-9:
        raise SystemExit(f"JAX and C disagree: {error:.3g}")
    timings = interleaved({"C batch": lambda: model.forward_dynamics_batch(q, qd),
                           "C batch, 1 thread": one_thread(lambda: model.forward_dynamics_batch(q, qd)),
                           "JAX jit(vmap)": lambda: jax.block_until_ready(batched(Q, QD, p, 0.0))},
                          blocks=3 if args.quick else 9, repeats=3)
    for name, timing in timings.items():
        print(f"  {name:16s} {timing.median / n * 1e9:8.1f} ns per state  ({timing})")
    record.figure("JAX jit(vmap) forward dynamics / C batch, four-bar", ratio(timings, "JAX jit(vmap)", "C batch"),
                  unit="x", target=TARGET_RATIO, better="lower",
                  detail=f"{n} states, C on {codegen.batch_threads()} thread(s)")
    record.figure("JAX jit(vmap) forward dynamics / C batch on 1 thread, four-bar",
                  ratio(timings, "JAX jit(vmap)", "C batch, 1 thread"), unit="x", detail=f"{n} states")
    record.finish()


if __name__ == "__main__":
    main()
