#!/usr/bin/env python3
"""Parameter sweep of the four-bar: Dask workers vs one process vs rebuilding the model per case.

Run by hand (not a pytest test)::

    python3 bench/bench_sweep.py                  # 1000 cases, 2 s each, 2 workers
    python3 bench/bench_sweep.py --cases 40       # quick

The cases: a grid of the crank torque ``tau`` and the initial crank speed
``q1d`` (the other values from ``examples/four_bar.toml``), each simulated for
``--t-end`` seconds (compiled CVODE, outputs at ``--points`` times), outcomes:
the final coordinates, energy drift and constraint residual.  Timed
(``time.perf_counter``), in this order, in the same run:

* *rebuild per case* (what a script did before kronlag.sweep): for every case
  read the model file, derive, build the numeric model with the case's values
  (code generation; the C library comes from the on-disk cache), assemble,
  simulate;
* *one process*: ``kronlag.sweep(model, ..., workers=0)``: the model built once,
  each case ``model.with_parameters(case)``;
* *Dask, N workers*: ``kronlag.sweep(model, ..., client=client)`` on a running
  local cluster of N processes (one thread each): shipping the model, unpickling
  it once per worker (its kernels generated again, the C library loaded from the
  cache) and gathering the table are included; starting the cluster is timed
  apart (``kronlag.sweep(..., workers=N)`` without a client adds it).

The one-process and Dask runs alternate ``--repeat`` times and the best of
each is kept (the machine is shared: its other load varies from run to run).

Targets (issue 9): Dask on 2 workers >= 1.7x faster than one process and >= 3x
faster than rebuilding per case.  The machine's other load counts: the ratios
are measured in the same run.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import kronlag
from kronlag.model.builtin import load_example


def cases_of(count: int) -> list[dict[str, float]]:
    speeds = max(1, round(math.sqrt(count)))
    torques = math.ceil(count / speeds)
    return kronlag.studies.sweeps.grid(tau=np.linspace(-2.0, 2.0, torques), q1d=np.linspace(0.5, 8.0, speeds))[:count]


def rebuild_per_case(cases, t_end: float, t_eval) -> list[float]:
    finals = []
    for case in cases:
        example = load_example("four_bar")
        values = {**example.numeric_values(), "tau": case["tau"]}
        model = kronlag.derive(example.system).numeric(values)
        q0, qd0 = model.assemble([1.0, 0.5583, 1.3347], fixed={"q1": 1.0}, qd_guess=[case["q1d"], 0, 0],
                                 qd_fixed={"q1": case["q1d"]})
        finals.append(kronlag.simulate(model, (0.0, t_end), q0, qd0, t_eval=t_eval).q[-1, 0])
    return finals


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--t-end", type=float, default=2.0)
    parser.add_argument("--points", type=int, default=101)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=2, help="alternating runs of one process and Dask (best kept)")
    arguments = parser.parse_args()
    cases = cases_of(arguments.cases)
    t_eval = np.linspace(0.0, arguments.t_end, arguments.points)
    example = load_example("four_bar")
    model = kronlag.derive(example.system).numeric(example.numeric_values())
    common = dict(parameters=cases, initial_states=([1.0, 0.5583, 1.3347], [0.0, 0.0, 0.0]), fixed=["q1"],
                  t_span=(0.0, arguments.t_end), t_eval=t_eval, progress=False)
    rebuild_per_case(cases[:2], arguments.t_end, t_eval)  # warm the compiled-library cache

    start = time.perf_counter()
    rebuilt = rebuild_per_case(cases, arguments.t_end, t_eval)
    rebuild_time = time.perf_counter() - start

    from dask.distributed import Client, LocalCluster

    start = time.perf_counter()
    cluster = LocalCluster(n_workers=arguments.workers, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    startup_time = time.perf_counter() - start
    serial_time = distributed_time = math.inf
    try:
        for _ in range(arguments.repeat):  # alternate, best of each: the machine's other load varies
            start = time.perf_counter()
            serial = kronlag.sweep(model, workers=0, **common)
            serial_time = min(serial_time, time.perf_counter() - start)
            start = time.perf_counter()
            distributed = kronlag.sweep(model, client=client, **common)
            distributed_time = min(distributed_time, time.perf_counter() - start)
            client.restart()  # the next repetition unpickles the model in the workers again
    finally:
        client.close()
        cluster.close()

    agree = (np.allclose(serial.table["q1_final"], rebuilt, rtol=1e-10)
             and np.allclose(distributed.table["q1_final"], rebuilt, rtol=1e-10))
    failed = len(serial.failed) + len(distributed.failed)
    print(f"four-bar sweep: {len(cases)} cases x {arguments.t_end:g} s simulated, {arguments.points} outputs each")
    print(f"{'variant':<28}{'total s':>10}{'ms/case':>10}")
    for name, seconds in (("rebuild per case", rebuild_time), ("one process (sweep)", serial_time),
                          (f"Dask, {arguments.workers} workers (sweep)", distributed_time)):
        print(f"{name:<28}{seconds:>10.2f}{1000 * seconds / len(cases):>10.2f}")
    print(f"{'(Dask cluster start-up)':<28}{startup_time:>10.2f}")
    print(f"time inside a case (median): one process {1000 * serial.table['wall_time'].median():.2f} ms, "
          f"Dask workers {1000 * distributed.table['wall_time'].median():.2f} ms (CPU shared with other load)")
    print(f"ratio one process / Dask:        {serial_time / distributed_time:.2f}   (target >= 1.7)")
    print(f"ratio rebuild per case / Dask:   {rebuild_time / distributed_time:.2f}   (target >= 3)")
    print(f"ratio rebuild per case / one process: {rebuild_time / serial_time:.2f}")
    print(f"results agree: {agree}; cases not ok: {failed}")


if __name__ == "__main__":
    main()
