"""A small pool of local worker processes for :func:`kronlag.sweep`: cheap to start, no scheduler.

A local Dask cluster costs seconds to start (a scheduler, nannies, each worker importing kronlag
afresh), as much as a few hundred cases; these workers are forked from the calling process where that
is safe (Linux, no other thread running, JAX not imported), so they start in milliseconds with the model and its C
library already loaded.  Each worker runs one batch at a time; the next batch goes to whichever
worker is free (the load balances itself).  A worker that dies (a crash in a case, killed) is
replaced; its batch is split into single cases and run again, each up to ``retries`` times, so that
only a case that keeps killing its worker is lost, and it is reported by its own row.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection, wait
from typing import Any

__all__ = ["run_batches", "usable_cpus", "WORKER_ENVIRONMENT"]

#: Set in every worker: one thread each for OpenMP, BLAS and kronlag's batched C calls, so that
#: ``workers`` processes use ``workers`` cores rather than ``workers`` times the machine.
WORKER_ENVIRONMENT = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                      "KRONLAG_THREADS": "1"}


def usable_cpus() -> int:
    """The CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


#: Libraries that run threads of their own once imported, which :mod:`threading` does not count: a
#: child forked from under them can deadlock (JAX warns so at every fork).
NATIVE_THREADS = ("jax", "jaxlib", "torch")


def start_method() -> str:
    """``"fork"`` on Linux when no other thread runs in this process (a fork copies only the calling
    thread, so a lock held by another could never be released in the child): none that :mod:`threading`
    counts and none of :data:`NATIVE_THREADS` imported; ``"spawn"`` otherwise."""
    if (sys.platform.startswith("linux") and threading.active_count() == 1
            and not any(name in sys.modules for name in NATIVE_THREADS)):
        return "fork"
    return "spawn"


def _serve(connection: Connection) -> None:
    """A worker's loop: receive the task once, then batches; send back ``(True, result)`` or
    ``(False, message)`` for each; stop at ``None``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is for the calling process, which stops us
    os.environ.update(WORKER_ENVIRONMENT)
    task = connection.recv()
    while (batch := connection.recv()) is not None:
        try:
            connection.send((True, task(batch)))
        except Exception as error:  # reported for the batch; the worker goes on
            connection.send((False, f"{type(error).__name__}: {error}"))


class _Worker:
    """One worker process, its end of the pipe and the batch it is running (with its attempts)."""

    def __init__(self, context, task: Callable[[Any], Any]):
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_serve, args=(child,), daemon=True)
        self.process.start()
        child.close()
        self.connection.send(task)
        self.batch: tuple[Sequence, int] | None = None

    def give(self, batch: Sequence, attempt: int) -> None:
        self.batch = (batch, attempt)
        try:
            self.connection.send(batch)
        except OSError:  # the worker died while idle: its sentinel tells, and the batch is run again
            pass

    def stop(self, *, now: bool) -> None:
        if now:
            self.process.terminate()
        else:
            try:
                self.connection.send(None)
            except OSError:  # already gone
                pass
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.connection.close()


def run_batches(task: Callable[[Sequence], Any], batches: Sequence[Sequence], *, workers: int, retries: int,
                finished: Callable[[Sequence, Any], None], lost: Callable[[Sequence, str], None]) -> None:
    """Run ``task(batch)`` for every batch on ``workers`` processes, calling ``finished(batch, result)``
    in this process as each batch finishes, or ``lost(batch, message)`` when it raised or when its
    items kept killing their worker (a batch whose worker died is split into single items, each run
    again up to ``retries`` times).  ``task`` and the batches must be picklable."""
    environment = {name: os.environ.get(name) for name in WORKER_ENVIRONMENT}
    context = multiprocessing.get_context(start_method())
    pending: list[tuple[Sequence, int]] = [(batch, 0) for batch in reversed(batches)]  # popped from the end
    pool: list[_Worker] = []
    try:
        os.environ.update(WORKER_ENVIRONMENT)  # while workers start: a spawned one reads it as it starts
        pool = [_Worker(context, task) for _ in range(min(workers, len(pending)))]
        while pending or any(worker.batch for worker in pool):
            for worker in pool:
                if worker.batch is None and pending:
                    worker.give(*pending.pop())
            busy = {worker.process.sentinel: worker for worker in pool if worker.batch}
            busy |= {worker.connection: worker for worker in pool if worker.batch}
            for ready in wait(list(busy)):
                worker = busy[ready]
                if worker.batch is None:  # its pipe and its sentinel were both ready
                    continue
                batch, attempt = worker.batch
                try:
                    succeeded, result = worker.connection.recv()
                except (EOFError, OSError):  # the worker died in the batch
                    worker.batch = None
                    worker.stop(now=True)  # reaped: its exit code known (a dead process ignores the SIGTERM)
                    code = worker.process.exitcode
                    pool[pool.index(worker)] = _Worker(context, task)
                    if attempt >= retries:
                        lost(batch, f"its worker died (exit code {code}) in each of {attempt + 1} attempts")
                    else:
                        pending.extend((item_batch, attempt + 1) for item_batch in _split(batch))
                    continue
                worker.batch = None
                if succeeded:
                    finished(batch, result)
                else:
                    lost(batch, result)
    except BaseException:
        for worker in pool:
            worker.stop(now=True)
        raise
    finally:
        _restore(environment)
    for worker in pool:
        worker.stop(now=False)


def _split(batch: Sequence) -> list[Sequence]:
    """The items of a batch one by one (to find the one that kills its worker), the last first."""
    return [batch[index:index + 1] for index in reversed(range(len(batch)))]


def _restore(environment: dict[str, str | None]) -> None:
    for name, value in environment.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value
