"""Smoke test: the derivation benchmark runs in quick mode and prints its table."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench" / "bench_derive.py"


@pytest.mark.slow
def test_bench_derive_quick():
    proc = subprocess.run([sys.executable, str(BENCH), "--quick"], capture_output=True, text=True,
                          timeout=1800)  # a guard against a hung process, far above any run under load
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert "absolute" in out and "relative" in out
    assert "ratio (sympy/kronlag)" in out
    assert "MISMATCH" not in out
