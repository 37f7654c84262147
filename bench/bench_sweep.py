#!/usr/bin/env python3
"""Parameter sweep of the four-bar: a plain loop vs ``kronlag.sweep`` in one process vs on 2 workers.

Run by hand (not a pytest test)::

    python3 bench/bench_sweep.py                  # 1000 cases, 2 s each, 2 workers, 3 blocks
    python3 bench/bench_sweep.py --quick          # 200 cases, 2 blocks (smoke test)
    python3 bench/bench_sweep.py --json -         # also write bench/results/bench_sweep.json

The cases: a grid of the crank torque ``tau`` and the initial crank speed ``q1d`` (the other values
from ``examples/four_bar.toml``), each simulated for ``--t-end`` seconds (compiled CVODE, outputs at
``--points`` times), outcomes: the final coordinates, energy drift and constraint residual
(:data:`kronlag.studies.sweeps.DEFAULT_OUTCOMES`).  In every block, one after the other (the machine
is shared: its other load varies, so the variants alternate and the medians over the blocks are
compared):

* *plain loop*: what a script without ``kronlag.sweep`` does: for each case
  ``model.with_parameters``, ``assemble``, ``simulate`` and the same outcomes, in this process;
* *sweep, one process*: ``kronlag.sweep(model, ..., workers=0)``;
* *sweep, N workers*: ``kronlag.sweep(model, ..., workers=N)``: starting the worker processes,
  shipping the model and gathering the table included;
* *small sweep* (``--small`` cases, default 20) by ``kronlag.sweep``'s default against a plain loop of
  the same cases: it must run in this process and cost no more;
* with ``--dask``: the same sweep on a Dask ``LocalCluster`` of N workers started inside the timing.

Also printed: the CPU time of each variant (this process's and its workers'), the machine's load
(``os.getloadavg``, 1 min) at the start of each block, whether Linux shares a busy CPU per session
(``sched_autogroup``: then this session's workers together get its one share of a loaded machine),
and the time a case takes in a worker and in this process, wall (the table's median ``wall_time``)
and CPU (this process's CPU time, the workers' from ``RUSAGE_CHILDREN`` once they have exited),
which tells a worker's own overhead (CPU) from its waiting for a core the other load holds (wall).

Targets (issue 19, on an idle 2-core machine): the 2-worker sweep >= 1.7x one process (its start-up
included), and never slower than a plain loop (>= 1.0x), also for small sweeps.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import statistics
import time

import numpy as np

import kronlag
from kronlag.model.builtin import load_example
from kronlag.studies.sweeps import DEFAULT_OUTCOMES, grid

from common import Record, add_arguments

GUESS = ([1.0, 0.5583, 1.3347], [0.0, 0.0, 0.0])


def cases_of(count: int) -> list[dict[str, float]]:
    speeds = max(1, round(math.sqrt(count)))
    torques = math.ceil(count / speeds)
    return grid(tau=np.linspace(-2.0, 2.0, torques), q1d=np.linspace(0.5, 8.0, speeds))[:count]


def plain_loop(model, cases, t_end: float, t_eval) -> list[float]:
    """The sweep written by hand: one case after the other in this process, the same outcomes."""
    finals = []
    for case in cases:
        varied = model.with_parameters(tau=case["tau"])
        q0, qd0 = varied.assemble(GUESS[0], fixed={"q1": GUESS[0][0]}, qd_guess=GUESS[1],
                                  qd_fixed={"q1": case["q1d"]})
        trajectory = kronlag.simulate(varied, (0.0, t_end), q0, qd0, t_eval=t_eval)
        outcomes = {name: outcome(trajectory) for name, outcome in DEFAULT_OUTCOMES.items()}
        finals.append(outcomes["final"]["q1_final"])
    return finals


def autogroup() -> str:
    """A note when Linux shares a busy CPU between sessions: then workers gain only from idle cores."""
    try:
        with open("/proc/sys/kernel/sched_autogroup_enabled", encoding="ascii") as flag:
            enabled = flag.read().strip() == "1"
    except OSError:
        return ""
    return " (CPU shared per session: sched_autogroup on)" if enabled else ""


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--small", type=int, default=20, help="cases of the small sweep (default: 20)")
    parser.add_argument("--t-end", type=float, default=2.0)
    parser.add_argument("--points", type=int, default=101)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--blocks", type=int, default=3, help="blocks of interleaved runs (medians over them)")
    parser.add_argument("--dask", action="store_true", help="also a Dask LocalCluster started in the timing")
    parser.add_argument("--quick", action="store_true", help="200 cases, 2 blocks (smoke test)")
    add_arguments(parser)
    arguments = parser.parse_args()
    if arguments.quick:
        arguments.cases, arguments.blocks = 200, 2
    record = Record("bench_sweep", arguments)
    cases, small = cases_of(arguments.cases), cases_of(arguments.small)
    t_eval = np.linspace(0.0, arguments.t_end, arguments.points)
    example = load_example("four_bar", apply_drives=False)
    model = kronlag.derive(example.system).numeric(example.numeric_values())
    common = dict(initial_states=GUESS, fixed=["q1"], t_span=(0.0, arguments.t_end), t_eval=t_eval, progress=False)
    kronlag.sweep(model, parameters=cases[:2], workers=0, **common)  # the driver library and pandas loaded

    times: dict[str, list[float]] = {}
    cpu_times: dict[str, list[float]] = {}
    loads, cpu, wall, agree = [], {"in-process": [], "worker": []}, {"in-process": [], "worker": []}, True

    def timed(name, run):
        start, start_cpu = time.perf_counter(), time.process_time() + children_cpu()
        result = run()
        times.setdefault(name, []).append(time.perf_counter() - start)
        cpu_times.setdefault(name, []).append(time.process_time() + children_cpu() - start_cpu)
        return result

    workers = f"sweep, {arguments.workers} workers"
    for _ in range(arguments.blocks):
        loads.append(os.getloadavg()[0])
        looped = timed("plain loop", lambda: plain_loop(model, cases, arguments.t_end, t_eval))
        started = time.process_time()
        serial = timed("sweep, one process", lambda: kronlag.sweep(model, parameters=cases, workers=0, **common))
        cpu["in-process"].append((time.process_time() - started) / len(cases))
        started = children_cpu()
        parallel = timed(workers, lambda: kronlag.sweep(model, parameters=cases, workers=arguments.workers,
                                                        **common))
        cpu["worker"].append((children_cpu() - started) / (len(cases) - 2))  # the first two run here
        wall["in-process"].append(serial.table["wall_time"].median())
        wall["worker"].append(parallel.table["wall_time"][2:].median())
        timed("small: plain loop", lambda: plain_loop(model, small, arguments.t_end, t_eval))
        timed("small: sweep (default)", lambda: kronlag.sweep(model, parameters=small, **common))
        if arguments.dask:
            timed(f"Dask LocalCluster, {arguments.workers} workers", lambda: dask_sweep(model, cases, arguments,
                                                                                       common))
        agree &= (serial.table.drop(columns="wall_time").equals(parallel.table.drop(columns="wall_time"))
                  and np.array_equal(serial.table["q1_final"].to_numpy(), looped))

    median = {name: statistics.median(seconds) for name, seconds in times.items()}
    print(f"four-bar sweep: {len(cases)} cases x {arguments.t_end:g} s simulated, {arguments.points} outputs each; "
          f"{arguments.blocks} blocks, medians; load (1 min) at the blocks' starts: "
          + ", ".join(f"{load:.2f}" for load in loads) + f" on {os.cpu_count()} CPUs{autogroup()}")
    print(f"{'variant':<36}{'median s':>10}{'ms/case':>10}{'CPU s':>10}")
    for name, seconds in median.items():
        count = len(small) if name.startswith("small") else len(cases)
        print(f"{name:<36}{seconds:>10.3f}{1000 * seconds / count:>10.2f}{statistics.median(cpu_times[name]):>10.3f}")
    print("time in a case, median (ms): "
          + "; ".join(f"{where}: wall {1000 * statistics.median(wall[where]):.2f}, "
                      f"CPU {1000 * statistics.median(cpu[where]):.2f}" for where in ("in-process", "worker")))
    detail = f"{len(cases)} cases, ratio of the medians of {arguments.blocks} blocks"
    record.figure(f"four-bar sweep: one process / {arguments.workers} workers",
                  median["sweep, one process"] / median[workers], unit="x", target=1.7, detail=detail)
    record.figure(f"four-bar sweep: plain loop / {arguments.workers} workers",
                  median["plain loop"] / median[workers], unit="x", target=1.0, detail=detail)
    record.figure("four-bar sweep: plain loop / one-process sweep",
                  median["plain loop"] / median["sweep, one process"], unit="x", detail=detail)
    record.figure(f"four-bar small sweep ({len(small)} cases): plain loop / sweep (default)",
                  median["small: plain loop"] / median["small: sweep (default)"], unit="x", target=1.0,
                  detail=f"ratio of the medians of {arguments.blocks} blocks")
    print(f"results identical (bitwise) in one process, on workers and in the plain loop: {agree}")
    record.finish()


def dask_sweep(model, cases, arguments, common):
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=arguments.workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        return kronlag.sweep(model, parameters=cases, scheduler=client, **common)


if __name__ == "__main__":
    main()
