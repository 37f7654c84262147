#!/usr/bin/env python3
"""The cost of joint friction (issue 18, item 5): friction in every joint against the same mechanism
without it, on the four-bar and the slider-crank of examples/four_bar_friction.toml and
examples/slider_crank_friction.toml.

Run by hand (not a pytest test)::

    python3 bench/bench_friction.py [--repeat 7] [--rtol 1e-8] [--law exact|smooth|both] [--quick] [--json -]

The frictionless model is the file with its ``friction = {...}`` lines removed (the same bodies,
joints and start).  All run ``kronlag.simulate`` with the compiled method (CVODE) over the file's
``t_end`` at the same tolerances, interleaved in blocks (frictionless, then each law, the order
rotating from block to block) so that a change of the machine's load hits all; a block's time is the
CPU time of this process (``time.process_time``), the ratio the median of the blocks' ratios.
Printed per run, where the cost goes: CVODE's steps, its right-hand-side evaluations (with the
Jacobians' columns), the output rows (one forward dynamics each, with the friction solved), the
stiction events and the segments they cut the run into (CVODE restarts at order 1 at each: inside the
compiled driver at a kinematic dead point, where a pin's direction turns without a return to Python, else
from Python after it decided the new modes); the ratio of the times and per evaluation (``time / (evaluations + rows)`` over the frictionless one's).
Target (issue 18): a ratio <= 1.5, for both laws (``--law both``, the default).  ``--quick``: 3 blocks.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import kronlag
from kronlag.app.workflows import initial_state, numeric_model

from common import Record, add_arguments

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FILES = {"four-bar": EXAMPLES / "four_bar_friction.toml", "slider-crank": EXAMPLES / "slider_crank_friction.toml"}


def _model(path: Path, *, friction: bool, directory: Path, law: str = "smooth"):
    text = path.read_text()
    if not friction:
        text = "\n".join(line for line in text.splitlines() if not line.startswith("friction ="))
    elif law == "exact":  # the same coefficients, exact stiction (no smoothing velocity)
        text = "\n".join(line.split(", smoothing_velocity")[0] + ', law = "exact"}' if line.startswith("friction =")
                         else line for line in text.splitlines())
    copy = directory / f"{path.stem}_{friction}.toml"
    copy.write_text(text)
    model_file = kronlag.load_model(copy, apply_drives=False)
    model = numeric_model(model_file)
    return model, *initial_state(model_file, model), model_file.simulation.t_end


def _counts(trajectory) -> dict[str, int]:
    """Where a run's time goes: CVODE's steps and evaluations, the output rows, the stiction events and
    the segments between them (events at one instant end one segment)."""
    events = [event for event in trajectory.events if hasattr(event, "joint")]
    return {"steps": trajectory.steps, "evaluations": trajectory.nfev, "rows": len(trajectory.t),
            "events": len(events), "segments": 1 + len({event.t for event in events})}


def main() -> None:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="blocks (each runs every model once)")
    parser.add_argument("--rtol", type=float, default=1e-8)
    parser.add_argument("--law", choices=("smooth", "exact", "both"), default="both")
    parser.add_argument("--quick", action="store_true", help="3 blocks (smoke test)")
    add_arguments(parser)
    arguments = parser.parse_args()
    record = Record("bench_friction", arguments)
    blocks = 3 if arguments.quick else arguments.repeat
    laws = ("exact", "smooth") if arguments.law == "both" else (arguments.law,)
    with tempfile.TemporaryDirectory() as directory:
        for name, path in FILES.items():
            runs = {"frictionless": _model(path, friction=False, directory=Path(directory))}
            runs |= {law: _model(path, friction=True, directory=Path(directory), law=law) for law in laws}

            def simulate(run):
                model, q0, qd0, t_end = run
                trajectory = kronlag.simulate(model, (0, t_end), q0, qd0, method="compiled", rtol=arguments.rtol,
                                              atol=arguments.rtol * 1e-2)
                assert trajectory.success, trajectory.result
                return trajectory

            counts = {label: _counts(simulate(run)) for label, run in runs.items()}  # also compiles
            times: dict[str, list[float]] = {label: [] for label in runs}
            labels = list(runs)
            for block in range(blocks):
                for label in labels[block % len(labels):] + labels[:block % len(labels)]:
                    start = time.process_time()
                    simulate(runs[label])
                    times[label].append(time.process_time() - start)
            for label in labels:
                print(f"{name} {label:12s} {statistics.median(times[label]) * 1e3:7.1f} ms  "
                      + ", ".join(f"{value} {key}" for key, value in counts[label].items()))
            for law in laws:
                ratio = statistics.median(a / b for a, b in zip(times[law], times["frictionless"]))
                work = {label: counts[label]["evaluations"] + counts[label]["rows"] for label in (law, "frictionless")}
                per_call = ratio * work["frictionless"] / work[law]
                record.figure(f"{name}, {law} friction law: friction / frictionless", ratio, unit="x", target=1.5,
                              better="lower", detail=f"CPU time, median of {blocks} interleaved blocks; "
                              f"{work[law] / work['frictionless']:.2f}x the evaluations + rows, "
                              f"{per_call:.2f}x per evaluation")
    record.finish()


if __name__ == "__main__":
    main()
