#!/usr/bin/env python3
"""The cost of joint friction (issue 18, item 5): friction in every joint against the same mechanism
without it, on the four-bar and the slider-crank of examples/four_bar_friction.toml and
examples/slider_crank_friction.toml.

Run by hand (not a pytest test)::

    python3 bench/bench_friction.py [--repeat 5] [--rtol 1e-8] [--law exact|smooth|both] [--quick] [--json -]

The frictionless model is the file with its ``friction = {...}`` lines removed (the same bodies,
joints and start).  Both run ``kronlag.simulate`` with the compiled method (CVODE) over the file's
``t_end`` at the same tolerances; the runs are interleaved (friction, frictionless, friction, ...)
so that a change of the machine's load hits both, and each time is the best of ``--repeat`` in CPU
time of this process (``time.process_time``).  Printed: the times, the right-hand-side evaluations
(friction changes the motion, hence the steps), the ratio of the times and the ratio per evaluation.
Target (issue 18): a ratio <= 1.5, for both laws (``--law both``, the default).  ``--quick``: best of 2.
"""

from __future__ import annotations

import argparse
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


def main() -> None:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--rtol", type=float, default=1e-8)
    parser.add_argument("--law", choices=("smooth", "exact", "both"), default="both")
    parser.add_argument("--quick", action="store_true", help="best of 2 (smoke test)")
    add_arguments(parser)
    arguments = parser.parse_args()
    record = Record("bench_friction", arguments)
    repeat = 2 if arguments.quick else arguments.repeat
    laws = ("exact", "smooth") if arguments.law == "both" else (arguments.law,)
    with tempfile.TemporaryDirectory() as directory:
        for law, (name, path) in ((law, item) for law in laws for item in FILES.items()):
            runs = {friction: _model(path, friction=friction, directory=Path(directory), law=law)
                    for friction in (True, False)}
            times = {True: float("inf"), False: float("inf")}
            evaluations = {}
            for _ in range(repeat):
                for friction, (model, q0, qd0, t_end) in runs.items():
                    start = time.process_time()
                    trajectory = kronlag.simulate(model, (0, t_end), q0, qd0, method="compiled",
                                                  rtol=arguments.rtol, atol=arguments.rtol * 1e-2)
                    times[friction] = min(times[friction], time.process_time() - start)
                    assert trajectory.success, trajectory.result
                    evaluations[friction] = trajectory.nfev
            ratio = times[True] / times[False]
            per_call = (times[True] / max(evaluations[True], 1)) / (times[False] / max(evaluations[False], 1))
            print(f"{name} ({law} law): friction {times[True] * 1e3:.1f} ms ({evaluations[True]} evaluations), "
                  f"frictionless {times[False] * 1e3:.1f} ms ({evaluations[False]} evaluations): "
                  f"ratio {ratio:.2f} (target <= 1.5), per evaluation {per_call:.2f}")
            record.figure(f"{name}, {law} friction law: friction / frictionless", ratio, unit="x", target=1.5,
                          better="lower", detail=f"CPU time, best of {repeat}; per evaluation {per_call:.2f}x")
    record.finish()


if __name__ == "__main__":
    main()
