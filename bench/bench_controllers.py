#!/usr/bin/env python3
"""The cost of a controller in the loop (issue 18, item 5), on the cart-pole of examples/cart_pole.toml.

Run by hand (not a pytest test)::

    python3 bench/bench_controllers.py [--repeat 5] [--quick] [--json -]   # --quick: best of 2

1. A Python controller called at every evaluation: the LQR state feedback of the file as a Python
   function ``controller(t, q, qd) -> {"u": value}`` against the same law written symbolically into
   the model (a force ``-K (x - x_ref)`` on the cart, compiled into C): 10 s, rtol 1e-8, 1001
   outputs.  Both integrate the same equations, so the integrators take the same steps; the
   overhead per call is ``(time with the controller - time symbolic) / calls``, the calls counted
   in a separate run.  Target (issue 18): <= 5 us a call.  Also the cost of the bare callback
   (a controller returning a constant dict).
2. A sampled controller (:class:`kronlag.Sampled`) at 1 kHz for 10 s (10 000 samples, the
   integrator restarted at each): target <= 0.2 s, with the default method (``method="auto"``, which
   picks a one-step method under a sampled controller, ALI3-P) and, for comparison, each compiled
   method by name (CVODE restarts at order 1 at every sample: about 9 steps a sample).

Times are the best of ``--repeat`` runs of ``kronlag.simulate``, in CPU time of this process
(``time.process_time``: on a machine shared with other jobs the wall time measures the load too;
the runs are single-threaded, so on an idle machine the two agree).
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

import numpy as np
import sympy as sp

import kronlag
from kronlag.app.workflows import initial_state, numeric_model
from kronlag.simulation.controllers import file_controller

from common import Record, add_arguments

MODEL_FILE = Path(__file__).resolve().parents[1] / "examples" / "cart_pole.toml"


def best(run, repeat: int) -> tuple[float, kronlag.Trajectory]:
    times, result = [], None
    for _ in range(repeat):
        started = time.process_time()
        result = run()
        times.append(time.process_time() - started)
    return min(times), result


def symbolic_model(file: kronlag.model.modelfile.ModelFile) -> kronlag.NumericModel:
    """The file's model with its state feedback written into the equations as a force on the cart."""
    spec = file.controller
    symbols = {q.name: q for q in file.system.coordinates}
    symbols.update({f"{q.name}d": kronlag.speed_symbol(q) for q in file.system.coordinates})
    force = -sum(sp.Float(gain.value) * (symbols[name] - sp.Float(reference))
                 for gain, name, reference in zip(spec.gains, spec.states, spec.reference))
    system = copy.deepcopy(file.system)
    system.add_force(system.body("cart").position, (force, 0), name="feedback")
    return kronlag.derive(system).numeric(file.values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="best of 2 (smoke test)")
    add_arguments(parser)
    arguments = parser.parse_args()
    record = Record("bench_controllers", arguments)
    repeat = 2 if arguments.quick else arguments.repeat
    file = kronlag.load_model(MODEL_FILE)
    model = numeric_model(file)
    q0, qd0 = initial_state(file, model)
    feedback = file_controller(file.controller, model)
    symbolic = symbolic_model(file)
    span, outputs = (0.0, 10.0), np.linspace(0.0, 10.0, 1001)
    print(f"cart-pole ({MODEL_FILE.name}), 10 s, rtol 1e-8, atol 1e-10, 1001 outputs; best of {repeat}\n")

    print("1. Python controller at every evaluation (target: <= 5 us a call over the symbolic law)")
    print(f"   {'method':10s} {'symbolic':>10s} {'Python':>10s} {'calls':>8s} {'nfev':>13s} {'overhead/call':>14s}")
    for method in ("compiled", "dop853", "switching", "ali3p"):
        calls = [0]

        def counted(t, q, qd):
            calls[0] += 1
            return feedback(t, q, qd)

        kronlag.simulate(model, span, q0, qd0, method=method, t_eval=outputs, controller=counted)
        base, reference = best(lambda: kronlag.simulate(symbolic, span, q0, qd0, method=method, t_eval=outputs), repeat)
        loop, run = best(lambda: kronlag.simulate(model, span, q0, qd0, method=method, t_eval=outputs,
                                                  controller=feedback), repeat)
        overhead = (loop - base) / calls[0]
        print(f"   {method:10s} {base:9.4f}s {loop:9.4f}s {calls[0]:8d} {reference.nfev:6d}/{run.nfev:<6d} "
              f"{overhead * 1e6:11.2f} us   max |q - q_symbolic| = {np.max(np.abs(run.q - reference.q)):.1e}")
        record.figure(f"cart-pole 10 s, {method}: Python controller overhead a call over the symbolic law",
                      overhead * 1e6, unit=" µs", target=5, better="lower",
                      detail=f"CPU time, best of {repeat}, {calls[0]} calls")
    constant = {"u": 0.0}
    bare, run = best(lambda: kronlag.simulate(model, span, q0, qd0, method="compiled", t_eval=outputs,
                                              controller=lambda t, q, qd: constant), repeat)
    free, plain = best(lambda: kronlag.simulate(model, span, q0, qd0, method="compiled", t_eval=outputs), repeat)
    per_call = (bare - free) / (run.nfev + len(run.t))
    print(f"   the callback alone (a constant dict, compiled): {per_call * 1e6:.2f} us a call"
          f" ({run.nfev} right-hand sides; {plain.nfev} without it)\n")

    print("2. Sampled at 1 kHz for 10 s (target: <= 0.2 s)")
    for method in ("auto", "switching", "compiled", "dop853", "ali3p"):
        for label, t_eval in (("1001 outputs", outputs), ("every step", None)):
            sampled = kronlag.Sampled(feedback, period=1e-3)
            wall, run = best(lambda: kronlag.simulate(model, span, q0, qd0, method=method, t_eval=t_eval,
                                                      controller=sampled), repeat)
            name = f"default ({run.method})" if method == "auto" else method
            print(f"   {name:16s} {label:13s} {wall:7.3f} s  ({run.steps} steps, {run.nfev} evaluations, "
                  f"{len(run.t)} outputs, x(10) = {run.q[-1, 0]:+.2e}, {run.message.split('.')[0]})")
            record.figure(f"cart-pole 10 s sampled at 1 kHz, {name}, {label}", wall, unit=" s", target=0.2,
                          better="lower", detail=f"CPU time, best of {repeat}")
    record.finish()


if __name__ == "__main__":
    main()
