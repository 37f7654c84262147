"""bench/common.py (interleaved timings, figures beside their targets, JSON records) and bench/report.py
(docs/performance.md generated from the records): their logic, without timing anything real."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture()
def bench_modules(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    for name in ("common", "report"):
        sys.modules.pop(name, None)
    import common
    import report

    return common, report


def test_interleaved_rotates_the_order_and_keeps_one_figure_per_block(bench_modules):
    common, _ = bench_modules
    calls = []
    timings = common.interleaved({"a": lambda: calls.append("a"), "b": lambda: calls.append("b"),
                                  "c": lambda: calls.append("c")}, blocks=3, repeats=2, warmup=1)
    assert calls[:3] == ["a", "b", "c"]  # the warm-up
    blocks = calls[3:]
    assert blocks == ["a", "a", "b", "b", "c", "c", "b", "b", "c", "c", "a", "a", "c", "c", "a", "a", "b", "b"]
    assert {name: len(timing.blocks) for name, timing in timings.items()} == {"a": 3, "b": 3, "c": 3}


def test_ratio_is_the_median_of_the_per_block_ratios(bench_modules):
    common, _ = bench_modules
    timings = {"slow": common.Timing((10.0, 30.0, 8.0)), "fast": common.Timing((1.0, 2.0, 4.0))}
    assert common.ratio(timings, "slow", "fast") == 10.0  # ratios 10, 15, 2
    assert timings["slow"].median == 10.0


def test_figures_say_whether_their_target_is_met(bench_modules, capsys):
    common, _ = bench_modules
    record = common.Record("bench_x", argparse.Namespace(json=None, quick=True))
    assert record.figure("speed-up", 31.0, unit="x", target=30).met is True
    assert record.figure("ratio", 2.5, unit="x", target=2, better="lower").met is False
    assert record.figure("info", 1.0).met is None
    out = capsys.readouterr().out
    assert "speed-up: 31x (target >= 30x: met)" in out and "ratio: 2.5x (target <= 2x: NOT met)" in out
    with pytest.raises(ValueError):
        common.Figure("x", 1.0, better="more")


def test_a_record_written_as_json_becomes_a_row_of_the_generated_page(bench_modules, tmp_path, capsys):
    common, report = bench_modules
    path = tmp_path / "bench_x.json"
    record = common.Record("bench_x", argparse.Namespace(json=str(path), quick=False))
    record.figure("every-step speed-up", 22.5, unit="x", target=30, detail="kronlag 30 ms")
    record.finish()
    assert "machine load (1-min average)" in capsys.readouterr().out
    data = json.loads(path.read_text())
    assert data["script"] == "bench_x" and set(data["load"]) == {"start", "end"}
    assert data["figures"][0] == {"measure": "every-step speed-up", "value": 22.5, "unit": "x", "target": 30.0,
                                  "better": "higher", "met": False, "detail": "kronlag 30 ms"}
    page = report.page({"bench_x": data, "bench_y": None})
    assert "do not edit by hand" in page
    row = next(line for line in page.splitlines() if line.startswith("| every-step speed-up"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[1:4] == ["22.5x", "≥ 30x", "**no**"]
    assert f"on {data['machine']['cpus']} CPUs" in cells[4] and cells[6] == "`bench_x`"
    assert "`bench_y` not run" in page
    assert report.QUICK_MARK not in row


def test_a_quick_run_is_marked_as_a_smoke_run_in_the_page(bench_modules, tmp_path):
    """Quick-mode figures must not pass for the real measurement: the record says ``quick`` and every row
    of it is marked."""
    common, report = bench_modules
    record = common.Record("bench_x", argparse.Namespace(json=None, quick=True))
    record.figure("overhead", 3.0, unit=" µs", target=5, better="lower")
    data = record.as_dict()
    assert data["quick"] is True
    row = next(line for line in report.page({"bench_x": data}).splitlines() if "overhead" in line)
    assert row.startswith(f"| {report.QUICK_MARK} overhead") and "(quick)" in row


def test_the_generated_page_is_the_one_in_the_docs(bench_modules):
    """docs/performance.md is what bench/report.py writes from the saved records (regenerate it with
    ``python3 bench/report.py`` after running a benchmark with ``--json -``)."""
    _, report = bench_modules
    records = {script: json.loads(path.read_text()) if (path := report.RESULTS / f"{script}.json").exists()
               else None for script in report.SCRIPTS}
    assert report.PAGE.read_text() == report.page(records)
