"""Output files of the command line: checked before any work, written after it, and the result
saved somewhere when a run fails or an output cannot be written."""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import ModelError
from ..model.modelfile import ModelFile

__all__ = ["IncompleteRun", "RunInterrupted", "OutputKind", "PLOT_SUFFIXES", "no_check", "requested_outputs", "check_writable", "finish_run", "emit"]


class IncompleteRun(Exception):
    """A run did not finish or an output could not be written; the message says what was saved."""


class RunInterrupted(IncompleteRun):
    """A run stopped by Ctrl-C (SIGINT); what it computed is saved as an incomplete run's is."""


@dataclass(frozen=True)
class OutputKind:
    """A kind of output file: its option, file name endings, a check made before any work
    (raising ModelError with the reason) and how the result is written."""

    option: str
    suffixes: tuple[str, ...]
    check: Callable[[Path, argparse.Namespace, ModelFile], None]
    write: Callable[[object, Path, argparse.Namespace, ModelFile], None]


def no_check(path: Path, arguments: argparse.Namespace, model: ModelFile) -> None:
    """Nothing to check beyond the file name and the folder."""


PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg")


def requested_outputs(kinds: Sequence[OutputKind], arguments: argparse.Namespace,
                       model: ModelFile) -> list[tuple[OutputKind, Path]]:
    """The output files asked for, each checked before any work: name, folder (created if missing),
    that a file can be written there, and what the kind needs (pyarrow, ffmpeg, drawing hints)."""
    outputs = []
    for kind in kinds:
        value = getattr(arguments, kind.option.removeprefix("--"))
        if value is None:
            continue
        path = Path(value)
        if path.suffix not in kind.suffixes:
            raise ModelError(f"{kind.option} {value}: the file name must end in {', '.join(kind.suffixes)}")
        check_writable(path, kind.option)
        kind.check(path, arguments, model)
        outputs.append((kind, path))
    return outputs


def check_writable(path: Path, option: str) -> None:
    """Make sure a file can be written at ``path`` (by writing nothing to it), creating its folder."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        existed = path.exists()
        with open(path, "ab"):
            pass
        if not existed:
            path.unlink()
    except OSError as error:
        raise ModelError(f"{option} {path}: cannot write there ({error.strerror or error})") from None


def _write_outputs(result, outputs: list[tuple[OutputKind, Path]], arguments: argparse.Namespace,
                   model: ModelFile) -> tuple[list[tuple[OutputKind, Path]], list[str]]:
    """Write every output; one failure does not stop the others.
    Returns the outputs written and the failures, one line each."""
    written, failures = [], []
    for kind, path in outputs:
        try:
            kind.write(result, path, arguments, model)
        except Exception as error:  # noqa: BLE001 - reported, and the other outputs are still written
            failures.append(f"{kind.option} {path}: {type(error).__name__}: {error}")
        else:
            written.append((kind, path))
            print(f"wrote {path}")
    return written, failures


def _rescue(save: Callable[[Path], None], name: str) -> Path:
    """Save a result that no output holds: in the working folder, else in the temporary folder."""
    for folder in (Path.cwd(), Path(tempfile.gettempdir())):
        path = folder / name
        try:
            save(path)
            return path
        except OSError:
            continue
    raise IncompleteRun(f"the result could not be saved as {name} in {Path.cwd()} or {tempfile.gettempdir()}")


def finish_run(result, outputs: list[tuple[OutputKind, Path]], arguments: argparse.Namespace,
                model: ModelFile, *, failure: str, save: Callable[[Path], None], rescue_name: str,
                interrupted: bool = False) -> None:
    """Write the outputs; if the run failed (``failure`` not empty) or an output could not be written,
    make sure the result is saved somewhere and raise :class:`IncompleteRun` saying where
    (:class:`RunInterrupted` for a run stopped by Ctrl-C, ``interrupted``)."""
    written, failures = _write_outputs(result, outputs, arguments, model)
    if not failure and not failures:
        return
    saved = [path for kind, path in written if kind.option == "--output"]
    where = saved[0] if saved else _rescue(save, rescue_name)
    problems = ([failure] if failure else []) + [f"could not write {line}" for line in failures]
    raise (RunInterrupted if interrupted else IncompleteRun)("; ".join(problems) + f"; the results are saved in {where}")


def emit(text: str, output: str | None) -> None:
    if output is None:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    else:
        Path(output).write_text(text, encoding="utf-8")
        print(f"wrote {output}", file=sys.stderr)
