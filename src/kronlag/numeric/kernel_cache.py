"""The C text of a model's lazily generated kernels (ALI3-P's ``"tangent"``), cached on disk.

A compiled library is found in the cache by a hash of its whole source (:mod:`.codegen.build`), so a
driver that appends a kernel to the model's source needed that kernel's text before it could look:
for Cassie's leg, generating the tangent kernel (the derivatives of the whole dynamics) took minutes
in every process.  Here the text is stored under a key known before it is generated: the hash of the
model's own C source (which the model has built already, and which fixes every matrix the kernel is
derived from), the kernel's name and the generator's identity (the hash of the source files of
:mod:`kronlag.symbolic`, :mod:`kronlag.numeric.codegen` and :mod:`kronlag.core.kernels`, and the
versions of SymPy and SymEngine: a changed generator never reads an old text).  A second process with
a warm cache reads the text and finds the compiled library by it, without generating anything.

Each file holds a first line with the SHA-256 of the rest; a file that does not match (truncated,
replaced) is generated again and rewritten.  The files live in the compiled libraries' private
directory (the user's alone: a kernel's text becomes compiled code).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
from collections.abc import Callable
from functools import cache
from pathlib import Path

from .codegen.build import _private_cache_directory

__all__ = ["kernel_key", "cached_kernel_text"]

#: Packages whose source files generate the kernels (their hash is part of every key).
_GENERATOR_PACKAGES = ("symbolic", "numeric/codegen")
_GENERATOR_FILES = ("core/kernels.py",)
#: The first line of a cached text, with the SHA-256 of the rest.
_HEADER = "/* kronlag kernel text, sha256 {} */\n"


@cache
def generator_identity() -> str:
    """A hash of the code that generates the kernels: the generator's source files and the versions
    of SymPy and SymEngine."""
    root = Path(__file__).resolve().parents[1]
    files = sorted(path for package in _GENERATOR_PACKAGES for path in (root / package).glob("*.py"))
    files += [root / name for name in _GENERATOR_FILES]
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    for package in ("sympy", "symengine"):
        try:
            digest.update(f"{package} {importlib.metadata.version(package)}\0".encode())
        except importlib.metadata.PackageNotFoundError:
            digest.update(f"{package} missing\0".encode())
    return digest.hexdigest()


def kernel_key(model_source: str, name: str) -> str:
    """The cache key of the kernel ``name`` of the model whose C source is ``model_source``."""
    facts = (generator_identity(), name, hashlib.sha256(model_source.encode()).hexdigest())
    return hashlib.sha256("\0".join(facts).encode()).hexdigest()[:32]


def cached_kernel_text(model_source: str, name: str, generate: Callable[[], str]) -> str:
    """The C text of the kernel ``name`` of the model whose C source is ``model_source``: read from the
    cache when it is there intact, else ``generate()`` and stored."""
    path = _private_cache_directory() / f"kernel_{name}_{kernel_key(model_source, name)}.c"
    try:
        header, _, text = path.read_text().partition("\n")
        if f"{header}\n" == _HEADER.format(hashlib.sha256(text.encode()).hexdigest()):
            return text
    except (OSError, UnicodeDecodeError):
        pass
    text = generate()
    temporary = path.with_name(f"{path.name}.{os.getpid()}.part")
    try:  # renamed into place: a reader never sees part of it
        temporary.write_text(_HEADER.format(hashlib.sha256(text.encode()).hexdigest()) + text)
        os.replace(temporary, path)
    except OSError:  # a full or read-only cache: the text is still right, only not kept
        temporary.unlink(missing_ok=True)
    return text
