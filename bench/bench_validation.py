#!/usr/bin/env python3
"""Validation on the IFToMM benchmark set A01-A05: every problem with every method.

Run by hand (not a pytest test); it writes ``docs/validation.md`` and
``docs/images/validation_A0*.png``::

    PYTHONPATH=src python3 bench/bench_validation.py            # full run, a few minutes
    PYTHONPATH=src python3 bench/bench_validation.py --quick    # A01, A02 (N = 2), A03 only

Every problem of :mod:`kronlag.benchmarks.iftomm` (A02 with N = 2, 4 and 8) is
integrated from its assembled initial state with ``method="auto"`` and with
every method of ``kronlag.simulation.METHODS`` (looked up when the script runs,
so methods added later are included) at rtol 1e-8, atol 1e-10 (A03: rtol 1e-10,
its target), outputs at the benchmark's ``t_eval``.  For each run the table
gives the status, the benchmark's own error measure against its independent
reference (max over the outputs), correct digits (-log10 of the relative
error), the integration time (``Trajectory.wall_time``), the steps and, when
the Trajectory records them, the singular-configuration events.  When Exudyn
is installed (``pip install exudyn``), A02 with N = 2 is also solved by its
index-3 generalized-alpha solver at two fixed step counts, timed in the same
run, as a peer.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import kronlag
from kronlag.benchmarks import iftomm
from kronlag.simulation import METHODS

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
IMAGES = DOCS / "images"

#: (code, options) of every case, in table order.
CASES = [("A01", {}), ("A02", {"n": 2}), ("A02", {"n": 4}), ("A02", {"n": 8}), ("A03", {}), ("A04", {}),
         ("A05", {})]
QUICK_CASES = [("A01", {}), ("A02", {"n": 2}), ("A03", {})]
#: Relative tolerance by problem (default 1e-8); atol is 1e-10 throughout.
RTOL = {"A03": 1e-10}
DEFAULT_RTOL, ATOL = 1e-8, 1e-10
#: Exudyn generalized-alpha step counts over the 10 s of A02.
EXUDYN_STEPS = (10_000, 40_000)
#: A run "succeeds silently wrong" when it reports status 0 with an error above this (m, for A01/A02).
SILENT_LIMIT = 1e-3


@dataclass
class Run:
    """One row of the table."""

    case: str
    method: str
    status: str
    error: float
    digits: float
    seconds: float
    steps: int | None
    events: int | None
    t: np.ndarray
    observed: np.ndarray


def case_name(code: str, options: dict) -> str:
    return f"{code} N={options['n']}" if "n" in options else code


def run_kronlag(benchmark: iftomm.Benchmark, model: kronlag.NumericModel, method: str, case: str) -> Run:
    try:
        trajectory = benchmark.simulate(model, method=method, rtol=RTOL.get(benchmark.code, DEFAULT_RTOL), atol=ATOL)
    except Exception as error:  # a crash is a result here: it goes into the table
        return Run(case, method, f"raised {type(error).__name__}: {error}"[:80], np.nan, np.nan, np.nan, None,
                   None, np.empty(0), np.empty((0, 1)))
    events = getattr(trajectory, "events", None)
    status = "ok" if trajectory.status == 0 else f"failed at t = {trajectory.t[-1]:.3g}" if len(trajectory.t) \
        else "failed"
    if trajectory.status == 0 and benchmark.code in ("A01", "A02") and benchmark.error(trajectory) > SILENT_LIMIT:
        status = "ok, WRONG"
    label = trajectory.method if method == "auto" else method
    return Run(case, "auto (" + label + ")" if method == "auto" else method, status, benchmark.error(trajectory),
               benchmark.digits(trajectory), trajectory.wall_time, trajectory.steps,
               None if events is None else len(events), np.asarray(trajectory.t), benchmark.observe(trajectory))


def warm_up(benchmark: iftomm.Benchmark, model: kronlag.NumericModel) -> None:
    """One short run of every method first, so that no timing includes compiling a driver."""
    q0, qd0 = benchmark.initial_state(model)
    t0 = benchmark.t_span[0]
    for method in METHODS:
        try:
            kronlag.simulate(model, (t0, t0 + 1e-4), q0, qd0, method=method)
        except Exception:  # failures show in the timed run
            pass


def run_exudyn(steps: int, n: int = 2) -> Run | None:
    """A02 by Exudyn's index-3 generalized-alpha solver with ``steps`` fixed steps (None without Exudyn)."""
    try:
        import exudyn as exu
        from exudyn import itemInterface as items
    except ImportError:
        return None
    L, m, g = 1.0, 1.0, iftomm.G
    system_container = exu.SystemContainer()
    mbs = system_container.AddSystem()
    ground = mbs.AddObject(items.ObjectGround())

    def bar(x, y, angle, velocity, omega):
        node = mbs.AddNode(items.NodeRigidBody2D(referenceCoordinates=[x, y, angle],
                                                 initialVelocities=[velocity, 0.0, omega]))
        body = mbs.AddObject(items.ObjectRigidBody2D(nodeNumber=node, mass=m, inertia=m * L**2 / 12))
        centre = mbs.AddMarker(items.MarkerBodyMass(bodyNumber=body))
        mbs.AddLoad(items.LoadMassProportional(markerNumber=centre, loadVector=[0, -g, 0]))
        ends = [mbs.AddMarker(items.MarkerBodyPosition(bodyNumber=body, localPosition=[side * L / 2, 0, 0]))
                for side in (-1, 1)]
        return body, ends

    cranks = [bar(k * L, L / 2, np.pi / 2, L / 2, -1.0) for k in range(n + 1)]     # turning at -1 rad/s
    couplers = [bar((k - 0.5) * L, L, 0.0, L, 0.0) for k in range(1, n + 1)]       # translating at 1 m/s
    for k, (_, ends) in enumerate(cranks):
        pin = mbs.AddMarker(items.MarkerBodyPosition(bodyNumber=ground, localPosition=[k * L, 0, 0]))
        mbs.AddObject(items.RevoluteJoint2D(markerNumbers=[pin, ends[0]]))
    for k, (_, ends) in enumerate(couplers, start=1):
        mbs.AddObject(items.RevoluteJoint2D(markerNumbers=[cranks[k - 1][1][1], ends[0]]))
        mbs.AddObject(items.RevoluteJoint2D(markerNumbers=[ends[1], cranks[k][1][1]]))
    sensor = mbs.AddSensor(items.SensorBody(bodyNumber=cranks[0][0], localPosition=[L / 2, 0, 0], storeInternal=True,
                                            outputVariableType=exu.OutputVariableType.Position))
    mbs.Assemble()
    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = steps
    settings.timeIntegration.endTime = 10.0
    settings.timeIntegration.verboseMode = 0
    settings.solution.file.write = False
    started = time.perf_counter()
    exu.SolveDynamic(mbs, settings)           # generalized-alpha on the index-3 equations (Exudyn's default)
    seconds = time.perf_counter() - started
    data = mbs.GetSensorStoredData(sensor)
    t, x = data[:, 0], data[:, 1:2]
    error = float(np.abs(x - iftomm.four_bar_exact(t, n=n)[:, :1]).max())
    return Run(f"A02 N={n}", f"Exudyn gen.-alpha, {steps} steps", "ok", error, -np.log10(error), seconds, steps, None,
               t, x)


def fmt(value: float | None, spec: str) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return format(value, spec)


def table(runs: list[Run]) -> list[str]:
    lines = ["| problem | method | status | max error | digits | time (s) | steps | events |",
             "|---|---|---|---:|---:|---:|---:|---:|"]
    for run in runs:
        lines.append(f"| {run.case} | {run.method} | {run.status} | {fmt(run.error, '.2e')} | "
                     f"{fmt(run.digits, '.2f')} | {fmt(run.seconds, '.3f')} | {fmt(run.steps, 'd')} | "
                     f"{fmt(run.events, 'd')} |")
    return lines


def plot(code: str, benchmark: iftomm.Benchmark, runs: list[Run]) -> Path:
    """Measured quantity per method against the reference, and its error."""
    path = IMAGES / f"validation_{code}.png"
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=code != "A03")
    if code == "A03":
        top.bar([run.method for run in runs], [0 if not np.isfinite(run.digits) else run.digits for run in runs])
        top.axhline(9, color="k", linestyle="--", label="target: 9 digits")
        top.set_ylabel("correct digits at t = 0.03 s")
        top.legend()
        bottom.bar([run.method for run in runs], [run.seconds if np.isfinite(run.seconds) else 0 for run in runs])
        bottom.set_ylabel("integration time (s)")
        bottom.set_yscale("log")
        for axis in (top, bottom):
            axis.tick_params(axis="x", labelrotation=20)
    else:
        t = np.linspace(*benchmark.t_span, 2001)
        top.plot(t, benchmark.reference(t)[:, 0], "k--", linewidth=2.5, label="reference", zorder=1)
        for run in runs:
            if run.t.size:
                top.plot(run.t, run.observed[:, 0], linewidth=1, label=f"{run.method} ({run.status})")
                error = np.abs(run.observed[:, 0] - benchmark.reference(run.t)[:, 0])
                bottom.semilogy(run.t, np.maximum(error, 1e-17), linewidth=1, label=run.method)
        top.set_ylabel(benchmark.measure if runs[0].observed.shape[1] == 1
                       else f"first component of the {benchmark.measure}")
        bottom.set_ylabel("|error|")
        bottom.set_xlabel("t (s)")
        top.legend(fontsize=7, loc="best")
    top.set_title(f"IFToMM {code}: {benchmark.title}")
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


def git_revision() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def write_report(runs: list[Run], benchmarks: dict[str, iftomm.Benchmark], images: list[Path], quick: bool) -> Path:
    methods = ", ".join(f"`{name}`" for name in METHODS)
    lines = [
        "# Validation on the IFToMM benchmark set",
        "",
        "<!-- Generated by bench/bench_validation.py: do not edit by hand. -->",
        ("This page is generated: regenerate it with `PYTHONPATH=src python3 bench/bench_validation.py` "
         "(never edit it by hand)."),
        "",
        (f"Run of {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, kronlag {kronlag.__version__} "
         f"(git {git_revision()}), Python {platform.python_version()}, {platform.machine()}"
         + (" -- quick mode, a subset of the problems." if quick else ".")),
        "",
        (f"Methods: `auto` (the method it picked in brackets) and every method of `kronlag.simulation.METHODS` "
         f"({methods}); rtol {DEFAULT_RTOL:g} (A03: {RTOL['A03']:g}), atol {ATOL:g}.  Time: "
         "`Trajectory.wall_time` (integration, with the derived quantities at the outputs).  Digits: "
         "-log10 of the largest relative error.  Status `ok, WRONG`: status 0 with an error above "
         f"{SILENT_LIMIT:g} m, a silent wrong answer.  Events: singular passages recorded in the Trajectory "
         "(`-` when the Trajectory does not record them)."),
        "",
        "| problem | measure | reference |",
        "|---|---|---|",
    ]
    lines += [f"| {code} {benchmark.title} | {benchmark.measure} | {benchmark.source} |"
              for code, benchmark in benchmarks.items()]
    lines += ["", "## Results", ""] + table(runs) + ["", "## Plots", ""]
    lines += [f"![{path.stem}](images/{path.name})" for path in images]
    path = DOCS / "validation.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="A01, A02 (N = 2) and A03 only")
    arguments = parser.parse_args()
    IMAGES.mkdir(parents=True, exist_ok=True)
    runs, benchmarks, images = [], {}, []
    for code, options in QUICK_CASES if arguments.quick else CASES:
        benchmark = iftomm.benchmark(code, **options)
        name = case_name(code, options)
        started = time.perf_counter()
        model = benchmark.numeric()
        print(f"{name}: model built in {time.perf_counter() - started:.2f} s", flush=True)
        warm_up(benchmark, model)
        case_runs = []
        for method in ["auto", *METHODS]:
            case_runs.append(run_kronlag(benchmark, model, method, name))
            print("\n".join(table(case_runs[-1:])[2:]), flush=True)
        if (code, options) == ("A02", {"n": 2}):
            peers = [run for run in (run_exudyn(steps) for steps in EXUDYN_STEPS) if run is not None]
            print("\n".join(table(peers)[2:]) if peers else "Exudyn not installed: no peer", flush=True)
            case_runs += peers
        runs += case_runs
        if code not in benchmarks:
            benchmarks[code] = benchmark
            images.append(plot(code, benchmark, case_runs))
    print(f"wrote {write_report(runs, benchmarks, images, arguments.quick)}")


if __name__ == "__main__":
    main()
