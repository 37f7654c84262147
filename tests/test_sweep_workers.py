"""Where kronlag.sweep runs its cases: in this process, on local worker processes, on an existing Dask
cluster (``scheduler=``), with the same results; small sweeps stay here; failures keep their rows."""

from __future__ import annotations

import io
import os
import sys
import types

import numpy as np
import pytest

import kronlag
from kronlag.core.errors import InputError
from kronlag.model.builtin import load_example
from kronlag.studies import sweeps
from kronlag.studies.sweeps import grid, sweep

T_EVAL = np.linspace(0.0, 1.0, 21)
INITIAL = ([1.0, 0.5, 1.5], [0.0, 0.0, 0.0])
CASES = grid(tau=[-1.0, 0.0, 1.0, 2.0], q1d=[1.0, 3.0, 5.0])


@pytest.fixture(scope="module")
def model():
    example = load_example("four_bar", apply_drives=False)
    return kronlag.derive(example.system).numeric(example.numeric_values())


@pytest.fixture(scope="module")
def cluster():
    """A Dask LocalCluster of 2 worker processes, started apart from the sweeps (as a user's would be)."""
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as local_cluster:
        yield local_cluster


@pytest.fixture
def pool_calls(monkeypatch):
    """The local pool's runs, recorded; workers used for every sweep, however short."""
    calls = []

    def recorded(*arguments, **options):
        calls.append(options["workers"])
        return run_batches(*arguments, **options)

    run_batches = sweeps.run_batches
    monkeypatch.setattr(sweeps, "run_batches", recorded)
    monkeypatch.setattr(sweeps, "PARALLEL_FROM_SECONDS", 0.0)
    return calls


def run(model, **options):
    return sweep(model, parameters=CASES, initial_states=INITIAL, fixed=["q1"], t_span=(0.0, 1.0), t_eval=T_EVAL,
                 progress=False, **options)


def without_wall_time(result):
    return result.table.drop(columns="wall_time")


@pytest.mark.slow
def test_results_are_bitwise_identical_here_on_local_workers_and_on_a_scheduler(model, cluster, pool_calls):
    here = run(model, workers=0)
    local = run(model, workers=2, batch_size=3)
    assert pool_calls == [2]
    remote = run(model, scheduler=cluster.scheduler_address)  # a "tcp://..." address
    assert set(here.table["status"]) == {"ok"}
    # the same compiled code, the same arithmetic: equal to the last bit, not only to the tolerance
    assert without_wall_time(local).equals(without_wall_time(here))
    assert without_wall_time(remote).equals(without_wall_time(here))
    # and the physics is that of a hand-made case: a crank driven forward turns further
    finals = here.table.set_index(["tau", "q1d"])["q1_final"]
    assert finals[(2.0, 1.0)] > finals[(0.0, 1.0)] > finals[(-1.0, 1.0)]


def test_workers_run_with_one_blas_openmp_and_kronlag_thread(model, pool_calls):
    threads = {name: (lambda trajectory, name=name: float(os.environ.get(name, "nan")))
               for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "KRONLAG_THREADS")}
    before = {name: os.environ.get(name) for name in threads}
    result = run(model, workers=2, outcomes=threads)
    assert pool_calls == [2]
    on_workers = result.table.iloc[2:]  # the first two cases run in this process
    assert (on_workers[list(threads)].to_numpy() == 1.0).all()
    assert {name: os.environ.get(name) for name in threads} == before  # this process's is left as it was


def test_a_case_failing_on_a_worker_keeps_its_row_with_its_parameters(model, pool_calls):
    caller = os.getpid()

    def final_angle(trajectory):
        if os.getpid() != caller and tau_of(trajectory) == 2.0:
            os._exit(3)  # the worker dies in this case (never the test's own process)
        if tau_of(trajectory) == 1.0:
            raise ValueError("no outcome for this case")
        return trajectory.q[-1, 0]

    def tau_of(trajectory):
        return float(np.round(trajectory.model.parameter_values()["tau"], 12))

    result = run(model, workers=2, retries=1, batch_size=4, outcomes={"q1_end": final_angle})
    rows = result.table.set_index(["tau", "q1d"])
    assert len(result.table) == len(CASES)
    assert set(rows.loc[2.0, "status"]) == {"lost"}
    assert all("worker died (exit code 3)" in message for message in rows.loc[2.0, "message"])
    assert set(rows.loc[1.0, "status"]) == {"error"}
    assert all("ValueError: no outcome for this case" in message for message in rows.loc[1.0, "message"])
    assert set(rows.loc[[-1.0, 0.0], "status"]) == {"ok"}


def test_a_short_sweep_runs_in_this_process_without_starting_workers(model, monkeypatch):
    def refuse(*arguments, **options):
        raise AssertionError("workers started for a sweep of a fraction of a second")

    monkeypatch.setattr(sweeps, "run_batches", refuse)
    result = run(model, workers=2)  # 12 cases of ~10 ms: far below PARALLEL_FROM_SECONDS
    assert set(result.table["status"]) == {"ok"}


def test_batches_leave_every_worker_several_tasks_of_a_fraction_of_a_second():
    assert sweeps._batch_size(1000, 2, 0.012) == int(sweeps.TASK_SECONDS / 0.012)
    assert sweeps._batch_size(40, 2, 0.001) == 5  # at least 4 tasks per worker
    assert sweeps._batch_size(10, 2, 5.0) == 1


def test_scheduler_and_client_together_are_refused(model):
    with pytest.raises(InputError, match="scheduler= or client="):
        run(model, scheduler="tcp://127.0.0.1:1", client=object())


@pytest.mark.slow
def test_cli_sweep_runs_on_the_scheduler_given(cluster, tmp_path, monkeypatch, capsys):
    from kronlag.app.cli import main

    addresses = []
    distributed = sweeps._run_distributed

    def recorded(source, cases, settings, scheduler, *rest):
        addresses.append(scheduler)
        return distributed(source, cases, settings, scheduler, *rest)

    monkeypatch.setattr(sweeps, "_run_distributed", recorded)
    output = tmp_path / "sweep.csv"
    assert main(["sweep", "four_bar", "--grid", "m3=2:4:3", "--t-end", "0.5", "--points", "11",
                 "--scheduler", cluster.scheduler_address, "--output", str(output)]) == 0
    assert addresses == [cluster.scheduler_address]
    assert "3 cases, 3 ok" in capsys.readouterr().out
    assert output.read_text().count("\n") == 4


@pytest.mark.slow
def test_spawned_workers_give_the_same_results(model, pool_calls, monkeypatch):
    """Where fork is not safe (threads running, macOS, Windows) the workers are started afresh."""
    from kronlag.studies import local_pool

    monkeypatch.setattr(local_pool, "start_method", lambda: "spawn")
    spawned = run(model, workers=2)
    assert pool_calls == [2]
    assert without_wall_time(spawned).equals(without_wall_time(run(model, workers=0)))


@pytest.mark.parametrize("library", ["jax", "jaxlib", "torch"])
def test_workers_are_not_forked_from_under_a_library_with_threads_of_its_own(monkeypatch, library):
    """JAX's threads are native (``threading`` does not count them) and a child forked from under them
    can deadlock: once such a library is imported the workers are spawned."""
    from kronlag.studies import local_pool

    monkeypatch.setattr(local_pool.threading, "active_count", lambda: 1)
    monkeypatch.setattr(local_pool.sys, "platform", "linux")
    for name in local_pool.NATIVE_THREADS:
        monkeypatch.delitem(sys.modules, name, raising=False)
    assert local_pool.start_method() == "fork"
    monkeypatch.setitem(sys.modules, library, types.ModuleType(library))
    assert local_pool.start_method() == "spawn"


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("progress", [True, False])
def test_the_progress_bar_is_drawn_on_a_terminal_unless_switched_off(model, monkeypatch, capsys, progress):
    run(model, workers=0)  # standard error is no terminal here (as in every test and doctest): no bar
    assert capsys.readouterr().err == ""
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    sweep(model, parameters=CASES, initial_states=INITIAL, fixed=["q1"], t_span=(0.0, 1.0), workers=0,
          progress=progress)
    assert (f"] {len(CASES)}/{len(CASES)} cases" in terminal.getvalue()) is progress


def test_a_local_worker_killed_mid_sweep_loses_nothing(model, pool_calls):
    import multiprocessing
    import signal

    killed = []

    def kill_a_worker(done: int, total: int) -> None:
        workers = multiprocessing.active_children()
        if done >= 4 and workers and not killed:
            os.kill(workers[0].pid, signal.SIGKILL)  # a worker process of this sweep
            killed.append(workers[0].pid)

    result = sweep(model, parameters=CASES, initial_states=INITIAL, fixed=["q1"], t_span=(0.0, 4.0), workers=2,
                   batch_size=1, progress=kill_a_worker)
    assert killed and pool_calls == [2]
    assert len(result.table) == len(CASES) and set(result.table["status"]) == {"ok"}, result.failed
    here = sweep(model, parameters=CASES, initial_states=INITIAL, fixed=["q1"], t_span=(0.0, 4.0), workers=0,
                 progress=False)
    assert without_wall_time(result).equals(without_wall_time(here))


@pytest.mark.slow
def test_bench_sweep_prints_every_figure_beside_its_target():
    import subprocess
    from pathlib import Path

    bench = Path(__file__).resolve().parents[1] / "bench" / "bench_sweep.py"
    proc = subprocess.run([sys.executable, str(bench), "--cases", "8", "--small", "4", "--blocks", "1",
                           "--t-end", "0.5"], capture_output=True, text=True, timeout=1800)  # a guard against a hang
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "load (1 min)" in proc.stdout and "time in a case" in proc.stdout
    assert proc.stdout.count("(target >=") == 3
    assert "results identical (bitwise) in one process, on workers and in the plain loop: True" in proc.stdout
