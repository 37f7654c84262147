"""The limits of :mod:`kronlag.core.limits` applied to a model file: its size, nesting and number of
entries, checked before the file is read any further (a ModelFileError naming the file)."""

from __future__ import annotations

import re
from pathlib import Path

from ...core.errors import ModelFileError
from ...core.limits import MAX_ENTRIES, MAX_MODEL_FILE_BYTES, MAX_NESTING, MAX_PARAMETERS

__all__ = ["read_bounded", "check_text", "check_document"]

#: What can hold a bracket that opens no array or table (strings, comments), or a bracket.
_BRACKETS = re.compile(r'"""(?:\\.|[^\\])*?"""|\'\'\'.*?\'\'\'|"(?:\\.|[^"\\\n])*"|\'[^\'\n]*\'|#[^\n]*|[\[\]{}]',
                       re.DOTALL)


def _too_large(source: str) -> ModelFileError:
    return ModelFileError(f"{source}: the file is larger than {MAX_MODEL_FILE_BYTES // 2**20} MiB, the limit "
                          "of a model file")


def read_bounded(path: Path) -> str:
    """The text of ``path``, reading at most one byte more than :data:`MAX_MODEL_FILE_BYTES`
    (``/dev/zero`` is refused, not read forever)."""
    try:
        with open(path, "rb") as file:
            data = file.read(MAX_MODEL_FILE_BYTES + 1)
        if len(data) > MAX_MODEL_FILE_BYTES:
            raise _too_large(str(path))
        return data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ModelFileError(f"{path}: cannot read the file: {error}") from None


def check_text(text: str, source: str) -> None:
    """ModelFileError unless ``text`` is within :data:`MAX_MODEL_FILE_BYTES` and its arrays and
    inline tables nest at most :data:`MAX_NESTING` deep (checked before parsing: the TOML parser
    recurses into them)."""
    if len(text) > MAX_MODEL_FILE_BYTES or len(text.encode("utf-8", "surrogatepass")) > MAX_MODEL_FILE_BYTES:
        raise _too_large(source)
    depth = 0
    for match in _BRACKETS.finditer(text):
        token = match.group()
        if token in ("[", "{"):
            depth += 1
            if depth > MAX_NESTING:
                line = text.count("\n", 0, match.start()) + 1
                raise ModelFileError(f"{source}: line {line}: arrays and tables nested more than {MAX_NESTING} "
                                     "levels deep")
        elif token in ("]", "}"):
            depth -= 1


def check_document(document: dict, source: str) -> None:
    """ModelFileError unless every array and table of ``document`` has at most :data:`MAX_ENTRIES`
    entries (``[parameters]``: :data:`MAX_PARAMETERS`) and nests at most :data:`MAX_NESTING` deep
    (dotted keys nest without brackets)."""
    stack: list[tuple[str, object, int]] = [("", document, 0)]
    while stack:
        entry, value, depth = stack.pop()
        if not isinstance(value, dict | list):
            continue
        where = entry or "file"
        if depth > MAX_NESTING:
            raise ModelFileError(f"{source}: {where}: arrays and tables nested more than {MAX_NESTING} levels deep")
        limit = MAX_PARAMETERS if entry == "parameters" else MAX_ENTRIES
        if len(value) > limit:
            raise ModelFileError(f"{source}: {where}: {len(value)} entries, more than the limit of {limit}")
        items = value.items() if isinstance(value, dict) else ((f"[{i}]", item) for i, item in enumerate(value))
        for key, item in items:
            name = f"{entry}{key}" if isinstance(value, list) else f"{entry}.{key}" if entry else key
            stack.append((name, item, depth + 1))
