#!/usr/bin/env python3
"""Accessor calls (``model.M``, ``model.g``, ``model.Cqd``, ``model.forward_dynamics``) against Pinocchio.

Run by hand (not a pytest test; needs ``pip install pin``)::

    python3 bench/bench_accessors.py
    python3 bench/bench_accessors.py --previous /path/to/old/kronlag/src   # also time an older kronlag
    python3 bench/bench_accessors.py --quick                              # smoke test

The mechanism is the four-bar linkage as ``kronlag.models.closed_chain(3, "relative")`` (three
links, joint angles relative to the previous link, the tip pinned to the ground), which maps one to
one to a Pinocchio chain of three ``JointModelRZ`` joints (see ``bench_forward_dynamics.py``).
Timed per call from Python, best of several repeats:

* ``model.M(q)`` against ``pinocchio.crba(model, data, q)``;
* ``model.g(q)`` against ``pinocchio.computeGeneralizedGravity(model, data, q)``;
* ``model.Cqd(q, qd)`` against ``pinocchio.nonLinearEffects(model, data, q, v)`` (``C qd + g``:
  Pinocchio's nearest call);
* ``model.forward_dynamics(q, qd)`` against ``pinocchio.constraintDynamics``.

The values are checked against Pinocchio's first (M, g, C qd + g).  With ``--previous`` the same
kronlag calls are timed, in a subprocess, with the kronlag found in that source directory.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import timeit
from pathlib import Path

import numpy as np

import kronlag
from kronlag import models

N_LINKS = 3
CALLS = ("M", "g", "Cqd", "forward_dynamics")
PINOCCHIO = {"M": "crba", "g": "computeGeneralizedGravity", "Cqd": "nonLinearEffects",
             "forward_dynamics": "constraintDynamics"}
QUICK = False


def per_call(function, *, number: int = 50000, repeat: int = 7) -> float:
    """Best time per call in microseconds."""
    number = max(1, number // 100) if QUICK else number
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number * 1e6


def state():
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_forward_dynamics import chain_parameters

    values, q_ref = chain_parameters(N_LINKS)
    model = kronlag.derive(models.closed_chain(N_LINKS, "relative")).numeric(values, backend="c")
    q, qd = model.assemble(q_ref + 0.05, fixed={"q1": q_ref[0] + 0.05},
                           qd_guess=np.random.default_rng(1).uniform(-1, 1, N_LINKS), qd_fixed={"q1": 0.8})
    return values, model, q, qd


def kronlag_times() -> dict[str, float]:
    """The kronlag calls of :data:`CALLS`, timed with whichever kronlag is imported."""
    _, model, q, qd = state()
    return {"M": per_call(lambda: model.M(q)), "g": per_call(lambda: model.g(q)),
            "Cqd": per_call(lambda: model.Cqd(q, qd)),
            "forward_dynamics": per_call(lambda: model.forward_dynamics(q, qd))}


def pinocchio_times(values, model, q, qd) -> dict[str, float]:
    import pinocchio as pin
    from bench_forward_dynamics import pinocchio_chain, pinocchio_links

    pin_model, _, _ = pinocchio_links(N_LINKS, values)
    data = pin_model.createData()
    mass_matrix = pin.crba(pin_model, data, q)
    mass_matrix = np.triu(mass_matrix) + np.triu(mass_matrix, 1).T
    checks = {"M": (model.M(q), mass_matrix), "g": (model.g(q), pin.computeGeneralizedGravity(pin_model, data, q)),
              "Cqd + g": (model.Cqd(q, qd) + model.g(q), pin.nonLinearEffects(pin_model, data, q, qd))}
    for name, (ours, theirs) in checks.items():
        difference = np.max(np.abs(ours - theirs)) / np.max(np.abs(theirs))
        assert difference < 1e-10, f"{name} differs from Pinocchio by {difference:.1e} (relative)"
    forward, _ = pinocchio_chain(N_LINKS, values)
    return {"M": per_call(lambda: pin.crba(pin_model, data, q)),
            "g": per_call(lambda: pin.computeGeneralizedGravity(pin_model, data, q)),
            "Cqd": per_call(lambda: pin.nonLinearEffects(pin_model, data, q, qd)),
            "forward_dynamics": per_call(lambda: forward(q, qd), number=20000)}, pin.__version__


def previous_times(source: str) -> dict[str, float]:
    """:func:`kronlag_times` in a subprocess importing kronlag from ``source``."""
    environment = {**os.environ, "PYTHONPATH": source}
    command = [sys.executable, __file__, "--kronlag-only"] + (["--quick"] if QUICK else [])
    output = subprocess.run(command, capture_output=True, text=True, check=True, env=environment).stdout
    return json.loads(output.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--previous", help="src directory of an older kronlag to time as well")
    parser.add_argument("--quick", action="store_true", help="smoke test: 100 times fewer calls")
    parser.add_argument("--kronlag-only", action="store_true", help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    global QUICK
    QUICK = arguments.quick
    if arguments.kronlag_only:
        print(json.dumps(kronlag_times()))
        return
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
          f"numpy {np.__version__}, kronlag call layer: "
          f"{'kronlag.numeric.codegen._call' if kronlag.numeric.codegen.FAST_CALL else 'ctypes (kronlag.numeric.codegen._call not built)'}")
    values, model, q, qd = state()
    reference, version = pinocchio_times(values, model, q, qd)
    columns = {"kronlag": kronlag_times()}
    if arguments.previous:
        columns["previous kronlag"] = previous_times(arguments.previous)
    print(f"\nfour-bar = closed_chain({N_LINKS}, 'relative'), m = {N_LINKS}, r = 2; pinocchio {version}; "
          "microseconds per call (ratio to pinocchio)")
    for call in CALLS:
        cells = "  ".join(f"{name} {times[call]:7.3f} ({times[call] / reference[call]:5.2f}x)"
                          for name, times in columns.items())
        print(f"  {call:17s} pinocchio {PINOCCHIO[call]:26s} {reference[call]:7.3f}   {cells}")
    print("\ntarget: accessor calls M, g, Cqd <= 1.5x pinocchio")


if __name__ == "__main__":
    main()
