"""Shared helpers of the benchmarks: timings that tell the truth, figures printed beside their targets,
and a JSON record that ``bench/report.py`` turns into ``docs/performance.md``.

The machine these benchmarks run on is often shared, so a figure is a ratio against a peer measured in
the same process, interleaved with it, never two times taken minutes apart:

* :func:`interleaved` runs the candidates in blocks, one after the other inside each block (the order
  rotates from block to block), and keeps every block's time per call (the best of ``repeats`` calls);
  :class:`Timing` gives the median over the blocks; :func:`ratio` the median of the per-block ratios
  (the load changes between blocks, much less within one);
* :class:`Record` collects the figures (``measure``, ``value``, ``unit``, ``target``, which way is
  better), prints each with its target and ``met`` / ``NOT met``, with the machine load
  (:func:`os.getloadavg`, 1-minute average, over the number of CPUs) at the start and the end, and with
  ``--json PATH`` writes them as JSON.

A script adopts it in four lines::

    from common import Record, add_arguments, interleaved, ratio   # bench/ is the script's folder

    parser = argparse.ArgumentParser(); add_arguments(parser); args = parser.parse_args()
    record = Record("bench_simulate", args)                         # notes the load now
    timings = interleaved({"kronlag": run_kronlag, "sympy": run_sympy}, blocks=7)
    record.figure("every-step four-bar, speed-up over SymPy + DOP853", ratio(timings, "sympy", "kronlag"),
                  unit="x", target=30, better="higher", detail=f"kronlag {timings['kronlag']}")
    record.finish()                                                 # prints the load, writes --json

The JSON file (one per script run; ``bench/results/<script>.json`` by default for ``report.py``)::

    {"script": "bench_simulate", "date": "2026-11-25T02:40:00Z", "quick": false,
     "machine": {"cpus": 2, "platform": "...", "python": "3.11.7"},
     "load": {"start": 1.4, "end": 1.9},
     "figures": [{"measure": "...", "value": 31.2, "unit": "x", "target": 30.0, "better": "higher",
                  "met": true, "detail": "..."}]}

``target`` may be null (a figure shown for information); ``better`` is ``"higher"`` (met when
``value >= target``) or ``"lower"`` (met when ``value <= target``).  Any script that writes this
format (by this module or not) can be listed in ``bench/report.py``'s ``SCRIPTS``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

__all__ = ["Timing", "interleaved", "ratio", "Figure", "Record", "add_arguments", "machine_load",
           "RESULTS"]

#: Where ``--json`` files go by default and where ``report.py`` reads them.
RESULTS = Path(__file__).resolve().parent / "results"


def machine_load() -> float:
    """The 1-minute load average (runnable processes; above the number of CPUs the timings are stretched)."""
    return os.getloadavg()[0]


@dataclass(frozen=True)
class Timing:
    """Seconds per call of one candidate, one entry per block (each the best of its block's repeats);
    ``cpu_blocks`` the same in CPU time of the process (``time.process_time``: less stretched by other
    processes on a loaded machine)."""

    blocks: tuple[float, ...]
    cpu_blocks: tuple[float, ...] = ()

    @property
    def median(self) -> float:
        return statistics.median(self.blocks)

    @property
    def cpu_median(self) -> float:
        return statistics.median(self.cpu_blocks)

    def __str__(self) -> str:
        return f"{self.median * 1e3:.3g} ms (median of {len(self.blocks)} blocks)"


def interleaved(candidates: Mapping[str, Callable[[], object]], *, blocks: int = 7, repeats: int = 1,
                warmup: int = 1) -> dict[str, Timing]:
    """Time the ``candidates`` (name -> function of no argument) interleaved in one process.

    Each is called ``warmup`` times first (compilation, caches, JIT); then, in each of ``blocks``
    blocks, every candidate ``repeats`` times in a row, the candidates' order rotating by one from
    block to block.  A block's figure for a candidate is its best call (``time.perf_counter``; and
    the best in ``time.process_time``, :attr:`Timing.cpu_blocks`).
    """
    names = list(candidates)
    for name in names:
        for _ in range(warmup):
            candidates[name]()
    times: dict[str, list[float]] = {name: [] for name in names}
    cpu_times: dict[str, list[float]] = {name: [] for name in names}
    for block in range(blocks):
        shift = block % len(names)
        for name in names[shift:] + names[:shift]:
            best = best_cpu = float("inf")
            for _ in range(repeats):
                start, start_cpu = time.perf_counter(), time.process_time()
                candidates[name]()
                best = min(best, time.perf_counter() - start)
                best_cpu = min(best_cpu, time.process_time() - start_cpu)
            times[name].append(best)
            cpu_times[name].append(best_cpu)
    return {name: Timing(tuple(times[name]), tuple(cpu_times[name])) for name in names}


def ratio(timings: Mapping[str, Timing], numerator: str, denominator: str, *, cpu: bool = False) -> float:
    """The median over the blocks of ``numerator``'s time over ``denominator``'s (how many times
    faster ``denominator`` is); ``cpu``: of their CPU times."""
    blocks = "cpu_blocks" if cpu else "blocks"
    pairs = zip(getattr(timings[numerator], blocks), getattr(timings[denominator], blocks))
    return statistics.median(a / b for a, b in pairs)


@dataclass
class Figure:
    """A measured figure and its target (None: for information)."""

    measure: str
    value: float
    unit: str = ""
    target: float | None = None
    better: str = "higher"
    met: bool | None = None
    detail: str = ""

    def __post_init__(self) -> None:
        if self.better not in ("higher", "lower"):
            raise ValueError(f"better must be 'higher' or 'lower', got {self.better!r}")
        if self.target is not None:
            self.met = bool(self.value >= self.target if self.better == "higher" else self.value <= self.target)

    def line(self) -> str:
        """``measure: value unit (target >= t: met)``."""
        text = f"{self.measure}: {self.value:.3g}{self.unit}"
        if self.target is not None:
            sign = ">=" if self.better == "higher" else "<="
            text += f" (target {sign} {self.target:g}{self.unit}: {'met' if self.met else 'NOT met'})"
        return text + (f"  [{self.detail}]" if self.detail else "")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--json PATH`` (write the record there; ``-``: ``bench/results/<script>.json``)."""
    parser.add_argument("--json", metavar="PATH", default=None,
                        help="write the figures as JSON to PATH ('-': bench/results/<script>.json)")


@dataclass
class Record:
    """The figures of one run of a benchmark script, with the machine load at its start and end."""

    script: str
    arguments: argparse.Namespace | None = None
    figures: list[Figure] = field(default_factory=list)
    load_start: float = field(default_factory=machine_load)

    def figure(self, measure: str, value: float, *, unit: str = "", target: float | None = None,
               better: str = "higher", detail: str = "") -> Figure:
        """Add a figure and print it beside its target."""
        figure = Figure(measure, float(value), unit, None if target is None else float(target), better, detail=detail)
        self.figures.append(figure)
        print(figure.line(), flush=True)
        return figure

    def load_text(self) -> str:
        return (f"machine load (1-min average) {self.load_start:.2f} at the start, {machine_load():.2f} at the "
                f"end, on {os.cpu_count()} CPUs")

    def as_dict(self) -> dict:
        quick = bool(getattr(self.arguments, "quick", False))
        return {"script": self.script,
                "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                "quick": quick,
                "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                            "python": platform.python_version()},
                "load": {"start": round(self.load_start, 2), "end": round(machine_load(), 2)},
                "figures": [asdict(figure) for figure in self.figures]}

    def finish(self) -> dict:
        """Print the load; write the JSON file if ``--json`` was given; return the record as a dict."""
        print(self.load_text(), flush=True)
        record = self.as_dict()
        path = getattr(self.arguments, "json", None)
        if path:
            target = RESULTS / f"{self.script}.json" if path == "-" else Path(path)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(json.dumps(record, indent=1) + "\n")
            print(f"figures written to {target}")
        return record
