#!/usr/bin/env python3
"""Build time: derivation + C build of ``closed_chain(n)``, against the targets of issue 19.

Run by hand (not a pytest test)::

    python3 bench/bench_build.py                  # closed_chain(40, "relative") and (100, "absolute")
    python3 bench/bench_build.py --n 12 20        # both conventions at each n
    python3 bench/bench_build.py --n 20 --compare-cse
    python3 bench/bench_build.py --quick          # smoke test: n = 8, both conventions
    python3 bench/bench_build.py --json -         # also write bench/results/bench_build.json

What is timed (``time.perf_counter``), each case in a fresh Python process with
an empty compiled-library cache (``$KRONLAG_CACHE`` set to a new temporary
directory):

* the total a user waits for: ``kronlag.derive(system)`` then
  ``eom.numeric(parameters, backend="c")`` (issue 19's targets: at most 10 s for
  ``closed_chain(40, "relative")``, 20 s for ``closed_chain(100, "absolute")``, on a 2-core
  machine), the CPU time of the Python process and of the compilers in it (what other jobs on a
  shared machine do not change much) and the peak memory of that process (target 600 MB);
* the first ``kronlag.simulate`` after it (default method, 0.05 s from an assembled state): what
  it compiles on top (target 1 s);
* the same work again, split into its phases: *derivation*, *conversion*
  (SymPy -> SymEngine of M, h = f_Q - C qd - g, Phi, Phi_q, the time derivatives
  gamma, ...; with recursive kernels only the blocks read off the derivation), *CSE* of the
  forward-dynamics kernel (``symengine.cse``, or ``linear_cse`` above ``LINEAR_CSE_OUTPUTS``
  outputs: the method is printed; with recursive kernels the tree's check and the recursion
  too), *C text* (printing the source)
  and *compilation* (the C compiler on the parts of the source in parallel, a cache emptied again);
* each kernel compiled with the model (``"dynamics"`` and the small ones its library holds; with
  ``--tangent`` also ALI3-P's ``"tangent"``): its construction time and the size of its C text;
* ``eom.numeric(parameters, backend="python")`` for comparison (up to n = 20);
* with ``--compare-cse``: ``sympy.cse`` against ``symengine.cse`` on the mass
  matrix alone (``sympy.cse`` of the whole kernel takes minutes).
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

from common import Record, add_arguments

SCRIPT = os.path.abspath(__file__)
#: Derivation + C build time targets (s) by case; other cases are reported without a target.
TARGETS_S = {(40, "relative"): 10.0, (100, "absolute"): 20.0}
#: Peak memory (MB) and first-simulate (s) targets of every case.
PEAK_MB_TARGET = 600.0
FIRST_SIMULATE_TARGET_S = 1.0
#: The Python backend is built for comparison up to this many links.
PYTHON_BACKEND_MAX_N = 20


def measure(n: int, angles: str, compare_cse: bool, with_tangent: bool = False) -> dict:
    """One case, in this process (called in a fresh subprocess with an empty cache)."""
    import symengine as se
    import sympy as sp

    from kronlag import codegen, derive, models
    from kronlag.numeric.codegen.recursive import dynamics_algorithm

    import resource

    import numpy as np

    from kronlag import simulate

    def cpu(who: int) -> float:
        usage = resource.getrusage(who)
        return usage.ru_utime + usage.ru_stime

    result: dict = {}
    start, python, compilers = time.perf_counter(), cpu(resource.RUSAGE_SELF), cpu(resource.RUSAGE_CHILDREN)
    eom = derive(models.closed_chain(n, angles))
    values = {p.name: 1.0 for p in eom.parameters}
    values.update(xg=0.6 * n, yg=0.0)
    model = eom.numeric(values, backend="c")
    result["total"] = time.perf_counter() - start
    result["python_cpu"] = cpu(resource.RUSAGE_SELF) - python
    result["compiler_cpu"] = cpu(resource.RUSAGE_CHILDREN) - compilers
    result["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    guess = np.linspace(0.8, -0.8, n) if angles == "absolute" else np.r_[0.8, np.full(n - 1, -1.6 / (n - 1))]
    q0, qd0 = model.assemble(guess)
    start = time.perf_counter()
    simulate(model, (0.0, 0.05), q0, qd0)
    result["first_simulate"] = time.perf_counter() - start

    phases = {}
    start = time.perf_counter()
    eom = derive(models.closed_chain(n, angles))
    phases["derivation"] = time.perf_counter() - start
    start = time.perf_counter()
    source = codegen.KernelSource(eom)
    algorithm = dynamics_algorithm(eom.system)
    # the blocks the dynamics kernel reads off the derivation (a recursive kernel computes M, h, Phi_q, gamma)
    read = codegen.LAYOUTS["dynamics"] if algorithm != "recursive" else ("f_Q", "Phi", "Phi_t", "A", "b", "gamma_nh")
    for block in read:
        source.matrix(block)
    phases["conversion"] = time.perf_counter() - start
    start = time.perf_counter()
    kernel = source.kernel("dynamics")
    phases["CSE"] = time.perf_counter() - start
    start = time.perf_counter()
    text = codegen.c_kernel(kernel, 1)[0]
    phases["C text"] = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as fresh:
        os.environ["KRONLAG_CACHE"] = fresh
        start = time.perf_counter()
        library = codegen.CLibrary([kernel], m=eom.shape[0], n_parameters=len(eom.parameters))
        phases["compilation"] = time.perf_counter() - start - phases["C text"]
    from kronlag.core.kernels import LINEAR_CSE_OUTPUTS

    outputs = sum(block.size for block in kernel.blocks)
    result["algorithm"] = algorithm
    result["cse_method"] = "linear_cse" if outputs > LINEAR_CSE_OUTPUTS else "symengine.cse"
    result.update(phases=phases, temporaries=len(kernel.temporaries), source_kb=len(library.source) / 1024,
                  kernel_kb=len(text) / 1024, parts=codegen.library_parts(library.source))
    # what the model's library is made of: each kernel compiled with it, its construction time
    # (conversion + CSE, the recursion's check once) and its C text
    from kronlag.numeric.numeric_model import _LIBRARY_GROUPS

    fresh_source = codegen.KernelSource(eom)
    kernels = {}
    for name in _LIBRARY_GROUPS["dynamics"] + (("tangent",) if with_tangent else ()):
        start = time.perf_counter()
        built = fresh_source.kernel(name)
        made = time.perf_counter() - start
        kernels[name] = (made, len(codegen.c_kernel(built, 0)[0]) / 1024)
    result["kernels"] = kernels
    if n <= PYTHON_BACKEND_MAX_N:
        start = time.perf_counter()
        eom.numeric(values, backend="python")
        result["numeric_python"] = time.perf_counter() - start
    if compare_cse:
        entries = list(eom.M)
        converted = [source.convert(entry) for entry in entries]
        start = time.perf_counter()
        se.cse(converted)
        result["symengine_cse_M"] = time.perf_counter() - start
        start = time.perf_counter()
        sp.cse(entries)
        result["sympy_cse_M"] = time.perf_counter() - start
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", help="numbers of links (both conventions each); "
                        "default: the target cases")
    parser.add_argument("--compare-cse", action="store_true", help="also time sympy.cse on M")
    parser.add_argument("--tangent", action="store_true",
                        help="also build the tangent kernel (ALI3-P's, compiled when a run needs it)")
    parser.add_argument("--case", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--quick", action="store_true", help="smoke test: n = 8, both conventions")
    add_arguments(parser)
    arguments = parser.parse_args()
    if arguments.case:
        n, angles = int(arguments.case[0]), arguments.case[1]
        print(json.dumps(measure(n, angles, arguments.compare_cse, arguments.tangent)))
        return
    record = Record("bench_build", arguments)
    sizes = [8] if arguments.quick and not arguments.n else arguments.n
    cases = ([(n, angles) for n in sizes for angles in ("absolute", "relative")] if sizes
             else list(TARGETS_S))
    print(f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, load average "
          f"{os.getloadavg()[0]:.1f} at the start (a shared machine: other jobs slow the compiler)")
    for n, angles in cases:
        with tempfile.TemporaryDirectory() as cache:
            command = [sys.executable, SCRIPT, "--case", str(n), angles]
            if arguments.compare_cse:
                command.append("--compare-cse")
            if arguments.tangent:
                command.append("--tangent")
            output = subprocess.run(command, capture_output=True, text=True, check=True,
                                    env={**os.environ, "KRONLAG_CACHE": cache}).stdout
        r = json.loads(output.strip().splitlines()[-1])
        target = TARGETS_S.get((n, angles))
        verdict = "" if target is None else f"  (target {target:.0f} s: {'ok' if r['total'] <= target else 'OVER'})"
        print(f"\nclosed_chain({n}, {angles!r}): M and h {r['algorithm']}, {r['cse_method']}, "
              f"{r['temporaries']} temporaries, {r['kernel_kb']:.0f} KiB of kernel C "
              f"({r['source_kb']:.0f} KiB with the solver), compiled in {r['parts']} parallel parts")
        print(f"  derive + eom.numeric(backend='c')  {r['total']:7.2f} s{verdict}  (load {os.getloadavg()[0]:.1f})")
        print(f"  CPU: Python {r['python_cpu']:.2f} s, compilers {r['compiler_cpu']:.2f} s (at least "
              f"{r['python_cpu'] + r['compiler_cpu'] / (os.cpu_count() or 1):.1f} s on {os.cpu_count()} idle cores; "
              "wall time on a shared machine says less)")
        print(f"  peak memory                        {r['peak_mb']:7.0f} MB  (target {PEAK_MB_TARGET:.0f} MB: "
              f"{'ok' if r['peak_mb'] <= PEAK_MB_TARGET else 'OVER'})")
        print(f"  first simulate                     {r['first_simulate']:7.2f} s  (target {FIRST_SIMULATE_TARGET_S:.0f} s: "
              f"{'ok' if r['first_simulate'] <= FIRST_SIMULATE_TARGET_S else 'OVER'})")
        for phase, seconds in r["phases"].items():
            print(f"    {phase:30s} {seconds:7.2f} s")
        print("  the model's kernels: construction (conversion, CSE) and C text")
        for name, (seconds, kib) in r["kernels"].items():
            print(f"    {name:30s} {seconds:7.2f} s {kib:8.0f} KiB")
        if "numeric_python" in r:
            print(f"  eom.numeric(backend='python')     {r['numeric_python']:7.2f} s  (after derive)")
        if arguments.compare_cse:
            print(f"  cse of M: symengine {r['symengine_cse_M']:.3f} s, sympy {r['sympy_cse_M']:.3f} s")
        case = f"closed_chain({n}, {angles})"
        record.figure(f"{case}: derive + C build (empty cache)", r["total"], unit=" s", target=target, better="lower",
                      detail="fresh process")
        record.figure(f"{case}: compiler CPU time of the build", r["compiler_cpu"], unit=" s", better="lower",
                      detail=f"Python {r['python_cpu']:.1f} s of CPU besides")
        cores = os.cpu_count() or 1
        record.figure(f"{case}: derive + C build from CPU times on {cores} idle cores", r["python_cpu"]
                      + r["compiler_cpu"] / cores, unit=" s", better="lower",
                      detail="Python CPU + compiler CPU / cores: what a loaded machine stretches less")
        record.figure(f"{case}: peak memory of derive + build", r["peak_mb"], unit=" MB", target=PEAK_MB_TARGET,
                      better="lower")
        record.figure(f"{case}: first simulate after the build", r["first_simulate"], unit=" s",
                      target=FIRST_SIMULATE_TARGET_S, better="lower")
    record.finish()


if __name__ == "__main__":
    main()
