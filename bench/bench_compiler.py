#!/usr/bin/env python3
"""The C compiler of the ``ziglang`` package against the system's (gcc): build time and speed.

Run by hand (not a pytest test; needs ``pip install kronlag[compiler]`` and gcc)::

    python3 bench/bench_compiler.py                 # the four-bar
    python3 bench/bench_compiler.py --chain 20      # also the build of closed_chain(20, "relative")
    python3 bench/bench_compiler.py --quick         # smoke test: fewer timed calls, a 1 s simulation

Each compiler runs in a fresh Python process with an empty compiled-library cache
(``$KRONLAG_CACHE``): the system's with the environment as it is, zig's with ``$CC`` unset and
PATH holding only the Python interpreter (so that kronlag finds no system compiler and says so),
and zig's own cache (``$ZIG_GLOBAL_CACHE_DIR``) new for this run, so that nothing is reused from
an earlier one.  Timed there (``time.perf_counter``):

* *first use*: :func:`kronlag.numeric.codegen.c_compiler`, the probe that compiles and links a
  small shared library; for zig in a new cache this includes building its C runtime once;
* *build*: ``eom.numeric(parameters, backend="c")`` of the four-bar (the dynamics kernel and the
  solver), then the libraries of the compiled drivers (CVODE's and ALI3-P's, the model's C with
  the driver);
* with ``--chain N``: ``eom.numeric`` of ``closed_chain(N, "relative")`` (large generated
  kernels, compiled in parallel parts).

Then both builds of the four-bar are loaded into this process from those caches and timed in
turns (system, zig, system, zig, ...: the load of a shared machine weighs on both alike), the best
of 7 rounds each:

* *forward dynamics*: ``model.forward_dynamics(q, qd)`` per call;
* *simulate*: ``kronlag.simulate`` of the four-bar over 10 s by the default method, outputs at
  every step.

The results of the two builds are compared (forward dynamics and the trajectory's last state); the
ratios printed are zig / system (1.00: the same; above 1: zig slower).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

SCRIPT = os.path.abspath(__file__)
FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1, m2=3, m3=2.5, I1=0.0033, I2=0.09, I3=0.052, g=9.81, tau=0.7)


def measure(chain: int | None) -> dict:
    """Build times of one compiler, in this process (a fresh subprocess with empty caches)."""
    import warnings

    import kronlag
    from kronlag.numeric import codegen

    warnings.simplefilter("ignore")
    result: dict = {}
    start = time.perf_counter()
    compiler = codegen.c_compiler()
    result["first use"] = time.perf_counter() - start
    result["compiler"] = str(compiler)
    eom = kronlag.derive(kronlag.models.four_bar())
    result |= four_bar(eom)
    if chain:
        chain_eom = kronlag.derive(kronlag.models.closed_chain(chain, "relative"))
        start = time.perf_counter()
        chain_eom.numeric({p.name: 1.0 for p in chain_eom.parameters}, backend="c")
        result[f"build: closed_chain({chain})"] = time.perf_counter() - start
    return result


def four_bar(eom) -> dict:
    """Build the four-bar's numeric model and its drivers with the compiler of the moment: the model
    (key ``"model"``) and the seconds each took."""
    from kronlag.simulation import drivers

    start = time.perf_counter()
    model = eom.numeric(FOUR_BAR, backend="c")
    result = {"build: numeric model": time.perf_counter() - start}
    start = time.perf_counter()
    for kind in drivers.DRIVERS:
        drivers.driver(model, kind)
    return result | {"build: drivers": time.perf_counter() - start, "model": model}


def hidden_system_compiler(directory: Path) -> dict[str, str]:
    """The environment without ``$CC`` and with PATH only the Python interpreter."""
    tools = directory / "bin"
    tools.mkdir(exist_ok=True)
    if not (tools / "python3").exists():
        (tools / "python3").symlink_to(sys.executable)
    return {**{key: value for key, value in os.environ.items() if key != "CC"}, "PATH": str(tools)}


def environments(directory: Path) -> dict[str, dict[str, str]]:
    """The environment of each compiler's run: its own kronlag cache, zig's cache new for this run."""
    zig_cache = {"ZIG_GLOBAL_CACHE_DIR": str(directory / "zig_cache")}
    return {name: {**environment, **zig_cache, "KRONLAG_CACHE": str(directory / f"cache_{name}")}
            for name, environment in (("system", dict(os.environ)), ("zig", hidden_system_compiler(directory)))}


def build_times(environment: dict[str, str], chain: int | None) -> dict:
    command = [sys.executable, SCRIPT, "--measure"] + (["--chain", str(chain)] if chain else [])
    output = subprocess.run(command, capture_output=True, text=True, check=True, env=environment).stdout
    return json.loads(output.strip().splitlines()[-1])


def speeds(environments: dict[str, dict[str, str]], quick: bool) -> dict[str, dict]:
    """Forward dynamics per call and the 10 s simulation by each compiler's build of the four-bar, loaded
    in this process from the caches the build runs filled, timed in turns (A B A B ...) so that the
    load of the machine weighs on both alike: the best of each."""
    import warnings

    import kronlag
    from kronlag.numeric.codegen import build

    warnings.simplefilter("ignore")
    eom = kronlag.derive(kronlag.models.four_bar())
    saved = dict(os.environ)
    models = {}
    for name, environment in environments.items():
        os.environ.clear()
        os.environ.update(environment)
        build._choose.cache_clear()  # the compiler of this environment, for the drivers too
        models[name] = four_bar(eom)["model"]
    os.environ.clear()
    os.environ.update(saved)
    build._choose.cache_clear()
    calls, t_end = (2000, 1.0) if quick else (20000, 10.0)
    results: dict[str, dict] = {name: {"forward dynamics": np.inf, f"simulate {t_end:g} s": np.inf}
                                for name in models}
    for _ in range(3 if quick else 7):
        for name, model in models.items():
            q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 2.0})
            per_call = timeit.timeit(lambda: model.forward_dynamics(q0, qd0), number=calls) / calls
            start = time.perf_counter()
            trajectory = kronlag.simulate(model, (0.0, t_end), q0, qd0)
            seconds = time.perf_counter() - start
            result = results[name]
            result["forward dynamics"] = min(result["forward dynamics"], per_call)
            result[f"simulate {t_end:g} s"] = min(result[f"simulate {t_end:g} s"], seconds)
            result |= {"steps": trajectory.steps, "method": trajectory.method, "q_end": trajectory.q[-1],
                       "qdd": model.forward_dynamics(q0, qd0).qdd}
    return results


def start_up_ms(command: list[str]) -> float:
    """Milliseconds to start ``command --version`` (best of 5)."""
    return 1e3 * min(timeit.repeat(lambda: subprocess.run(command + ["--version"], capture_output=True, check=True),
                                   number=1, repeat=5))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke test: fewer calls, a 1 s simulation")
    parser.add_argument("--chain", type=int, help="also time the build of closed_chain(N, 'relative')")
    parser.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.measure:
        print(json.dumps({key: value for key, value in measure(arguments.chain).items() if key != "model"}))
        return
    print(f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as work:
        runs = environments(Path(work))
        results = {name: build_times(environment, arguments.chain) for name, environment in runs.items()}
        for name, speed in speeds(runs, arguments.quick).items():
            results[name] |= speed
    system, zig = results["system"], results["zig"]
    if "zig cc" not in zig["compiler"] or "zig cc" in system["compiler"]:
        sys.exit(f"need a system compiler and the ziglang package: got {system['compiler']} and {zig['compiler']}")
    print(f"system: {system['compiler']}\nzig:    {zig['compiler']}\n")
    print(f"{'':28s} {'system':>12s} {'zig':>12s} {'zig/system':>11s}")
    for key, value in system.items():
        if isinstance(value, float):
            unit, scale = ("us", 1e6) if key == "forward dynamics" else ("s", 1.0)
            print(f"{key:28s} {value * scale:9.3f} {unit:2s} {zig[key] * scale:9.3f} {unit:2s} "
                  f"{zig[key] / value:10.2f}")
    print(f"{'steps (' + system['method'] + ')':28s} {system['steps']:12d} {zig['steps']:12d}")
    print(f"\nmax |zig - system|: forward dynamics {np.max(np.abs(zig['qdd'] - system['qdd'])):.1e}, "
          f"last state {np.max(np.abs(zig['q_end'] - system['q_end'])):.1e}")
    from kronlag.numeric.codegen import build

    zig_binary = build._ziglang_command()
    if zig_binary:
        print(f"starting zig cc: {start_up_ms(list(zig_binary)):.0f} ms as its binary (what kronlag runs), "
              f"{start_up_ms([sys.executable, '-m', 'ziglang', 'cc']):.0f} ms through python -m ziglang")


if __name__ == "__main__":
    main()
