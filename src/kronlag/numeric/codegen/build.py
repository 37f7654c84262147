"""Compiling generated C into shared libraries, cached on disk in a private directory."""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

from ...core.errors import CompilerError

__all__ = ["c_compiler", "cache_directory", "compile_shared_library", "C_LARGE_SOURCE"]

_CFLAGS = ("-fno-math-errno", "-fPIC", "-pthread")
#: Optimization level of the hand-written C (solvers, integrators, batch loops) and of small kernels.
_OPTIMIZATION = "-O2"
#: Part 0 of a library compiled in parts, the solver: -O3 vectorizes its loops of unknown length,
#: KRONLAG_WIDE_LOOPS adds AVX2 clones of them (``numeric/codegen/c/linalg.c``); closed_chain(40): 10.4 us
#: at -O2, 6.7 us so.
_SOLVER_FLAGS = ("-O3", "-DKRONLAG_WIDE_LOOPS")
#: Sources longer than this (characters) compile their kernel chunks with :data:`_LARGE_KERNEL_OPTIMIZATION`:
#: on straight-line generated code GCC's -O2 takes 1.6 times as long as -O1 and buys nothing
#: (closed_chain(30, "relative"): 13 s against 8 s, the kernel 15.5 us either way).
C_LARGE_SOURCE = 100_000
_LARGE_KERNEL_OPTIMIZATION = "-O1"

def c_compiler() -> str | None:
    """Path of the C compiler (``$CC``, else ``gcc``, else ``cc``), or None."""
    for candidate in (os.environ.get("CC"), "gcc", "cc"):
        if candidate and shutil.which(candidate):
            return shutil.which(candidate)
    return None


def cache_directory() -> Path:
    """Where compiled libraries are cached: ``$KRONLAG_CACHE`` or ``~/.cache/kronlag``.

    :func:`compile_shared_library` creates it with mode 0700 and refuses to use it
    (PermissionError) unless it belongs to the user and no one else can write to it.
    """
    return Path(os.environ.get("KRONLAG_CACHE") or Path.home() / ".cache" / "kronlag")


def _private_cache_directory() -> Path:
    """:func:`cache_directory`, created 0700; PermissionError naming it unless it is the user's alone.

    A library there is loaded into the process: a directory another user can
    write to would let that user run code as whoever runs kronlag.
    """
    directory = cache_directory()
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    status = directory.stat()
    problems = []
    if not stat.S_ISDIR(status.st_mode):
        problems.append("not a directory")
    if hasattr(os, "geteuid") and status.st_uid != os.geteuid():
        problems.append(f"owned by uid {status.st_uid}, not by you (uid {os.geteuid()})")
    writers = [who for who, bit in (("its group", stat.S_IWGRP), ("others", stat.S_IWOTH)) if status.st_mode & bit]
    if writers:
        problems.append(f"writable by {' and '.join(writers)} (mode {stat.S_IMODE(status.st_mode):o})")
    for parent in directory.resolve().parents:  # anyone could rename the directory away and plant another
        mode = parent.stat().st_mode
        if mode & stat.S_IWOTH and not mode & stat.S_ISVTX:
            problems.append(f"inside {parent}, which everyone may write to "
                            f"(mode {stat.S_IMODE(mode):o}, no sticky bit)")
    if problems:
        raise PermissionError(
            f"refusing to use the kronlag cache directory {directory}: it is {'; '.join(problems)}. Compiled "
            "code loaded from there runs in this process, so it must be yours alone: run "
            f"`chmod 700 {directory}` if it is yours, or point $KRONLAG_CACHE to a private directory")
    return directory


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _digest_path(library: Path) -> Path:
    """The sidecar recording the SHA-256 of ``library``, written after the library."""
    return library.with_name(library.name + ".sha256")


def _intact(library: Path) -> bool:
    """Whether ``library`` exists with the content hash recorded when it was built."""
    try:
        return _digest_path(library).read_text().strip() == _digest(library)
    except OSError:
        return False


def _write_atomically(target: Path, data: bytes, work: Path) -> None:
    """Write ``data`` to ``target`` through a file in ``work`` renamed over it (readers never see a part)."""
    temporary = work / (target.name + ".part")
    temporary.write_bytes(data)
    os.replace(temporary, target)


def compile_shared_library(source: str, *, parts: int = 1) -> Path:
    """Compile C ``source`` into a shared library in :func:`cache_directory` (reused when intact).

    With ``parts > 1`` the source is compiled ``parts`` times in parallel with
    ``-DKRONLAG_PART=i -DKRONLAG_PARTS=parts`` (each keeps the chunks
    ``KRONLAG_IN_PART`` selects) and the objects are linked; part 0, the
    hand-written C, with :data:`_SOLVER_FLAGS` (``-O3``), the others, the generated
    kernel chunks, at ``-O2``, or ``-O1`` when the source is longer than
    :data:`C_LARGE_SOURCE` characters.  A single part is compiled at ``-O2``.  The library is
    renamed into place, then its SHA-256 is written next to it
    (``<library>.sha256``); a library whose content does not match its recorded
    hash (truncated, replaced, or its build interrupted) is rebuilt, never returned.

    Raises
    ------
    CompilerError
        No compiler, or it failed.
    PermissionError
        The cache directory is not the user's alone (see :func:`cache_directory`).
    """
    compiler = c_compiler()
    if compiler is None:
        raise CompilerError("the C backend needs a C compiler (gcc or cc on PATH, or $CC); "
                            "use backend='python'")
    kernel_level = _LARGE_KERNEL_OPTIMIZATION if len(source) > C_LARGE_SOURCE else _OPTIMIZATION
    levels = [_SOLVER_FLAGS] + [(kernel_level,)] * (parts - 1) if parts > 1 else [(_OPTIMIZATION,)]
    key = hashlib.sha256("\0".join((compiler, *_CFLAGS, *map(" ".join, levels), source)).encode()).hexdigest()[:32]
    directory = _private_cache_directory()
    target = directory / f"kronlag_{key}.so"
    if _intact(target):
        return target
    with tempfile.TemporaryDirectory(dir=directory) as work:
        source_path = Path(work) / "model.c"
        source_path.write_text(source)
        objects = [Path(work) / f"part{i}.o" for i in range(parts)]
        defines = [[f"-DKRONLAG_PART={i}", f"-DKRONLAG_PARTS={parts}"] if parts > 1 else [] for i in range(parts)]
        try:
            processes = [subprocess.Popen([compiler, *level, *_CFLAGS, *define, "-c", "-o", str(obj), str(source_path)],
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                         for level, define, obj in zip(levels, defines, objects)]
        except OSError as error:
            raise CompilerError(f"cannot run the C compiler {compiler}: {error}") from None
        errors = [process.communicate()[1] for process in processes]
        failed = [f"exit status {process.returncode}\n{error[-4000:]}"
                  for process, error in zip(processes, errors) if process.returncode]
        built = Path(work) / "model.so"
        if not failed:
            undefined = ["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []
            link = subprocess.run([compiler, "-shared", "-pthread", *undefined, "-o", str(built), *map(str, objects),
                                   "-lm"], capture_output=True, text=True)
            failed = [f"exit status {link.returncode} (linking)\n{link.stderr[-4000:]}"] if link.returncode else []
        if failed or not built.is_file():
            output = failed[0] if failed else "no library was written"
            raise CompilerError(f"compiling the generated C code with {compiler} failed: {output}".rstrip())
        # the library first, its hash after: a library without a matching hash is never loaded
        digest = _digest(built)
        os.replace(built, target)
        _write_atomically(_digest_path(target), digest.encode(), Path(work))
    return target

