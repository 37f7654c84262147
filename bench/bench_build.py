#!/usr/bin/env python3
"""Numeric build time: code generation + compilation of ``closed_chain(20)``.

Run by hand (not a pytest test)::

    python3 bench/bench_build.py                 # n = 20, both conventions
    python3 bench/bench_build.py --n 12 20 --compare-cse

What is timed (``time.perf_counter``), each case in a fresh Python process with
an empty compiled-library cache (``$KRONLAG_CACHE`` set to a new temporary
directory), after an untimed ``kronlag.derive``:

* ``eom.numeric(parameters, backend="c")``: everything a user waits for,
  split into *code generation* (SymPy -> SymEngine, ``symengine.cse`` of the
  forward-dynamics kernel: M, h = f_Q - C qd - g, Phi, Phi_q, gamma, A, b,
  gamma_nh) and *C printing + compilation* (the C compiler runs on the parts
  of the source in parallel, one process per core up to 8);
* ``eom.numeric(parameters, backend="numpy")`` for comparison;
* with ``--compare-cse``: ``sympy.cse`` against ``symengine.cse`` on the mass
  matrix alone (``sympy.cse`` of the whole kernel takes minutes).

Target: the C build of closed_chain(20) within 10 s for both conventions.
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

SCRIPT = os.path.abspath(__file__)


def measure(n: int, angles: str, compare_cse: bool) -> dict:
    """One case, in this process (called in a fresh subprocess)."""
    import symengine as se
    import sympy as sp

    from kronlag import codegen, derive, models

    eom = derive(models.closed_chain(n, angles))
    values = {p.name: 1.0 for p in eom.parameters}
    result: dict = {}
    start = time.perf_counter()
    source = codegen.KernelSource(eom)
    kernel = source.kernel("dynamics")
    generated = time.perf_counter()
    library = codegen.CLibrary([kernel], m=eom.shape[0], n_parameters=len(eom.parameters))
    compiled = time.perf_counter()
    result.update(codegen=generated - start, compile=compiled - generated, temporaries=len(kernel.temporaries),
                  source_kb=len(library.source) / 1024, parts=min(os.cpu_count() or 1, 8))
    with tempfile.TemporaryDirectory() as fresh:
        os.environ["KRONLAG_CACHE"] = fresh
        start = time.perf_counter()
        eom.numeric(values, backend="c")
        result["numeric_c"] = time.perf_counter() - start
    start = time.perf_counter()
    eom.numeric(values, backend="numpy")
    result["numeric_numpy"] = time.perf_counter() - start
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
    parser.add_argument("--n", type=int, nargs="+", default=[20])
    parser.add_argument("--compare-cse", action="store_true", help="also time sympy.cse on M")
    parser.add_argument("--case", nargs=2, help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.case:
        n, angles = int(arguments.case[0]), arguments.case[1]
        print(json.dumps(measure(n, angles, arguments.compare_cse)))
        return
    print(f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    for n in arguments.n:
        for angles in ("absolute", "relative"):
            with tempfile.TemporaryDirectory() as cache:
                command = [sys.executable, SCRIPT, "--case", str(n), angles]
                if arguments.compare_cse:
                    command.append("--compare-cse")
                output = subprocess.run(command, capture_output=True, text=True, check=True,
                                        env={**os.environ, "KRONLAG_CACHE": cache}).stdout
            r = json.loads(output.strip().splitlines()[-1])
            verdict = "ok" if r["numeric_c"] <= 10.0 else "OVER the 10 s target"
            print(f"\nclosed_chain({n}, {angles!r}): {r['temporaries']} temporaries, "
                  f"{r['source_kb']:.0f} KiB of C, compiled in {r['parts']} parallel parts")
            print(f"  eom.numeric(backend='c')      {r['numeric_c']:7.2f} s  ({verdict})")
            print(f"    code generation (CSE)       {r['codegen']:7.2f} s")
            print(f"    C printing + compilation    {r['compile']:7.2f} s")
            print(f"  eom.numeric(backend='numpy')  {r['numeric_numpy']:7.2f} s")
            if arguments.compare_cse:
                print(f"  cse of M: symengine {r['symengine_cse_M']:.3f} s, sympy {r['sympy_cse_M']:.3f} s")


if __name__ == "__main__":
    main()
