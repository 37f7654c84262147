"""Every script in examples/ runs and writes its plot."""

import runpy
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parents[1] / "examples").glob("*.py"))


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda path: path.stem)
def test_example_script_writes_its_plot(script, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(script), run_name="__main__")
    plot = tmp_path / f"{script.stem}.png"
    assert plot.stat().st_size > 10_000


def test_there_is_a_script_per_shipped_model():
    from kronlag.model.builtin import example_names

    assert set(example_names()) <= {path.stem for path in EXAMPLES}
