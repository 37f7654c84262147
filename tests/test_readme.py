"""The README opens with the two commands of the product (main job, tests), and CI runs exactly the
test command, with the oldest Python a newcomer has (Debian's system Python when present)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    """The lines of the README's first code block."""
    text = (ROOT / "README.md").read_text()
    title, opening = text.split("\n\n")[:2]
    assert title == "# kronlag" and opening.startswith("```bash\n"), "the README opens with its commands"
    return re.search(r"```bash\n(.*?)```", text, re.S).group(1).strip().splitlines()


def ci_dry_run() -> dict[str, str]:
    result = subprocess.run(["bash", str(ROOT / ".ci" / "run"), "--dry-run"], capture_output=True, text=True,
                            timeout=120, check=True)
    return dict(line.split(" = ", 1) for line in result.stdout.splitlines())


def test_the_readme_opens_with_the_main_job_and_the_tests():
    main_job, tests = readme_commands()
    for command in (main_job, tests):
        assert command.startswith("python3 -m venv .venv && .venv/bin/python -m pip install -e ")
    assert "kronlag derive" in main_job and "kronlag simulate" in main_job and "--plot" in main_job
    assert tests.endswith(".venv/bin/python -m pytest")


def test_ci_runs_exactly_the_readme_test_command():
    assert (ROOT / ".ci" / "run").read_text().rstrip().splitlines()[-1] == readme_commands()[1]


@pytest.mark.skipif(not Path("/usr/bin/python3").exists(), reason="no system Python here")
def test_ci_uses_the_system_python_when_there_is_one():
    # Debian 12's /usr/bin/python3 is 3.11.2: what differs from later 3.11 releases must fail CI.
    assert ci_dry_run()["python3"].startswith("/usr/bin/python3 (3.")
