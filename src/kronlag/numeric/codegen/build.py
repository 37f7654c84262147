"""Compiling generated C into shared libraries, cached on disk in a private directory, each library
carrying the key of its source (checked after loading)."""

from __future__ import annotations

import _ctypes
import atexit
import ctypes
import hashlib
import importlib
import importlib.metadata
import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

from ...core.errors import CacheWarning, CompilerError, CompilerWarning

__all__ = ["CCompiler", "c_compiler", "cache_directory", "compile_shared_library", "load_shared_library",
           "library_parts", "C_LARGE_SOURCE", "KEY_FUNCTION"]

#: The function every compiled library exports, ``const char *kronlag_library_key(void)``: the key in
#: its file name, checked after loading (a library is bound to the source it was built from).
KEY_FUNCTION = "kronlag_library_key"

_CFLAGS = ("-fno-math-errno", "-fPIC", "-pthread")
#: Optimization level of the hand-written C (solvers, integrators, batch loops) and of small kernels.
_OPTIMIZATION = "-O2"
#: Part 0 of a library compiled in parts, the solver: -O3 vectorizes its loops of unknown length,
#: KRONLAG_WIDE_LOOPS adds AVX2 clones of them (``numeric/codegen/c/linalg.c``); closed_chain(40): 10.4 us
#: at -O2, 6.7 us so.
_SOLVER_FLAGS = ("-O3", "-DKRONLAG_WIDE_LOOPS")
#: Kernel chunks longer than this (characters, outside part 0) compile with :data:`_LARGE_KERNEL_OPTIMIZATION`:
#: on straight-line generated code GCC's -O2 (its SLP vectorizer above all) takes twice as long and
#: buys nothing (closed_chain(12, "relative"), 39 000 characters: 0.46 s against 0.25 s of CPU a part,
#: forward dynamics 12.7 us against 12.6 us; closed_chain(40, "relative"): O2 9 % slower).
C_LARGE_SOURCE = 30_000
#: -O1 without the dead-store eliminations, which find nothing in kernels that store every temporary
#: once into the workspace ``w`` (closed_chain(40, "relative"): 3.2 s of CPU a part against 3.9 s at
#: -O1, the forward dynamics as fast; without the points-to analysis too, 2.9 s, but 4-7 % slower
#: calls: ``restrict`` needs it).
_LARGE_KERNEL_OPTIMIZATION = ("-O1", "-fno-dse", "-fno-tree-dse")
#: Added to :data:`_LARGE_KERNEL_OPTIMIZATION` for kernels whose temporaries are mostly local variables
#: (:data:`_LOCAL_TEMPORARY`, ``c_backend._local_statements``): their few workspace loads need no
#: points-to analysis to be told apart from the stores (closed_chain(100, "absolute"): the compilers
#: 26 s of CPU against 18 s so, the forward dynamics as fast, 0.97x).
_LOCAL_KERNEL_FLAGS = ("-fno-tree-pta",)
#: How a local temporary of a generated kernel is declared (``c_backend._local_statements``).
_LOCAL_TEMPORARY = re.compile(r"^    const double x\d+ = ", re.MULTILINE)
#: The name under which the C compiler of the ``ziglang`` package is reported and chosen.
_ZIG = "zig cc"
#: Flags of one compiler besides the common ones, by :attr:`CCompiler.name`, when compiling and when
#: linking (zig links a C runtime built for these flags, once: the probe's).  ``zig cc`` compiles
#: for the build machine's own CPU (a library cached in a home directory shared with an older
#: machine would not run there, and FMA contraction would round unlike GCC's baseline build),
#: with debug information and frame pointers unless told otherwise; these flags make it build as
#: GCC does by default.
_COMPILER_FLAGS = {_ZIG: ("-mcpu=baseline", "-g0", "-fomit-frame-pointer")}
_PROBE_SOURCE = "#include <math.h>\ndouble kronlag_probe(double x) { return sqrt(x) + 1.0; }\n"
#: Seconds a compiler may take on the probe (zig builds its C runtime once, in about 30 s).
_PROBE_TIMEOUT = 600


@dataclass(frozen=True)
class CCompiler:
    """A C compiler that compiles and links a shared library on this machine (:func:`c_compiler`).

    Attributes
    ----------
    name : str
        ``"$CC"``, ``"gcc"``, ``"cc"`` or ``"zig cc"`` (the compiler of the ``ziglang`` package).
    command : tuple of str
        The command line that runs it, before the arguments.
    version : str
        The first line of its ``--version``.
    flags : tuple of str
        Its own compile flags, besides those every compiler gets (:data:`_COMPILER_FLAGS`).
    """

    name: str
    command: tuple[str, ...]
    version: str
    flags: tuple[str, ...] = ()

    @property
    def identity(self) -> str:
        """What the key of a library built by this compiler includes: libraries of two compilers never mix."""
        return "\0".join((self.name, *self.command, self.version, *self.flags))

    def __str__(self) -> str:
        return f"{self.name} ({' '.join(self.command)}; {self.version})"


def _ziglang_command() -> tuple[str, ...] | None:
    """The ``zig cc`` of the ``ziglang`` package, run as its binary (no Python start per compile), or None."""
    try:
        package = importlib.import_module("ziglang")
    except ImportError:
        return None
    directory = Path(package.__file__).parent
    binary = next((path for path in (directory / "zig", directory / "zig.exe") if path.is_file()), None)
    return (str(binary), "cc") if binary else None


#: A compiler looked for: its name, the command that runs it (None: not found) and what it is called in reports.
_Candidate = tuple[str, tuple[str, ...] | None, str]


def _candidates() -> tuple[_Candidate, ...]:
    """The compilers in the order they are tried (:func:`c_compiler`), for the current ``$CC`` and ``$PATH``."""
    return _candidates_for(os.environ.get("CC") or "", os.environ.get("PATH") or "")


@lru_cache(maxsize=8)
def _candidates_for(cc_variable: str, path_variable: str) -> tuple[_Candidate, ...]:
    """:func:`_candidates` for these values of ``$CC`` and ``$PATH`` (searched once: a simulation asks for the
    compiler at every segment, and ``shutil.which`` costs about a millisecond)."""
    try:
        cc = shlex.split(cc_variable)
    except ValueError:  # an unbalanced quote: taken as one word, not found
        cc = [cc_variable]
    programs = [("$CC", cc, f"$CC={cc_variable}")] if cc else []
    programs += [(name, [name], name) for name in ("gcc", "cc")]
    found = [(name, shutil.which(words[0], path=path_variable or None), words[1:], label) for name, words, label in programs]
    candidates = tuple((name, (path, *arguments) if path else None, label) for name, path, arguments, label in found)
    return candidates + ((_ZIG, _ziglang_command(), "the ziglang package"),)


def c_compiler() -> CCompiler | None:
    """The C compiler kronlag uses: the first of ``$CC``, ``gcc`` and ``cc`` (on PATH) that compiles and
    links a small shared library, else ``zig cc`` of the ``ziglang`` package (``pip install
    kronlag[compiler]``), else None.

    Each compiler is tried once per process.  The choice is reported once, in one line, with a
    :class:`~kronlag.core.errors.CompilerWarning` when a compiler found does not work (``$CC=/bin/false``:
    saying why), when ``zig cc`` is used because no other is found or works, or when there is no
    compiler at all (the ``"auto"`` backend is then the Python one).
    """
    return _choose(_candidates())[0]


@lru_cache(maxsize=None)
def _choose(candidates: tuple[_Candidate, ...]) -> tuple[CCompiler | None, str]:
    """The first of ``candidates`` that works, reported as :func:`c_compiler` says, and what became of
    those tried before it."""
    failures: list[str] = []
    broken = False  # a compiler was found that does not work (not only missing ones)
    for name, command, label in candidates:
        if command is None:
            failures.append(f"{label}: not installed (pip install kronlag[compiler])" if name == _ZIG
                            else f"{label}: not on PATH")
            continue
        compiler, problem = _probe(name, command)
        if compiler is not None:
            if name == _ZIG:
                warnings.warn(f"no {'working ' * broken}C compiler found ({'; '.join(failures)}); using zig cc from "
                              f"the ziglang package ({compiler.version})", CompilerWarning, stacklevel=3)
            elif broken:
                warnings.warn(f"{'; '.join(failures)}; using {compiler}", CompilerWarning, stacklevel=3)
            return compiler, "; ".join(failures)
        failures.append(f"{label} does not work: {problem}")
        broken = True
    warnings.warn(f"no working C compiler found ({'; '.join(failures)}): the C backend is not available, "
                  "the (slower) Python backend is used", CompilerWarning, stacklevel=3)
    return None, "; ".join(failures)


@lru_cache(maxsize=None)
def _probe(name: str, command: tuple[str, ...]) -> tuple[CCompiler | None, str]:
    """``command`` as a :class:`CCompiler` if it compiles and links a small shared library as
    :func:`_build` does, else None and why."""
    compiler = CCompiler(name, command, "", _COMPILER_FLAGS.get(name, ()))
    with tempfile.TemporaryDirectory(prefix="kronlag-probe-") as work:
        source, probe, library = Path(work) / "probe.c", Path(work) / "probe.o", Path(work) / "probe.so"
        source.write_text(_PROBE_SOURCE)
        try:
            for step in (_compile_command(compiler, (_OPTIMIZATION,), source, probe),
                         _link_command(compiler, [probe], library)):
                build = subprocess.run(step, capture_output=True, text=True, stdin=subprocess.DEVNULL,
                                       timeout=_PROBE_TIMEOUT)
                if build.returncode:
                    break
            version = subprocess.run([*command, "--version"], capture_output=True, text=True,
                                     stdin=subprocess.DEVNULL, timeout=_PROBE_TIMEOUT)
        except (OSError, subprocess.TimeoutExpired) as error:
            return None, str(error)
        if build.returncode or not library.is_file():
            last_line = (build.stderr.strip().splitlines() or ["no library was written"])[-1]
            return None, f"exit status {build.returncode} building a test library ({last_line})"
    first_line = (version.stdout.strip().splitlines() or ["unknown version"])[0]
    if name == _ZIG:
        first_line = f"ziglang {importlib.metadata.version('ziglang')}, {first_line}"
    return replace(compiler, version=first_line), ""


def _compile_command(compiler: CCompiler, flags: tuple[str, ...], source: Path, output: Path) -> list[str]:
    """The command compiling ``source`` into the object ``output`` with ``flags`` (optimization, defines)."""
    return [*compiler.command, *flags, *_CFLAGS, *compiler.flags, "-c", "-o", str(output), str(source)]


def _link_command(compiler: CCompiler, objects: list[Path], output: Path,
                  libraries: tuple[Path, ...] = ()) -> list[str]:
    """The command linking ``objects`` into the shared library ``output``, with an optimization level
    because zig links a C runtime built for it (once per level: always the same one).  The shared
    ``libraries`` (paths: the SUNDIALS of the compiled drivers) are linked by path, with their
    directories as run paths, so that loading ``output`` loads them as its own dependencies: no
    library needs to be loaded with global symbols first (where another copy of SUNDIALS in the
    process, FMPy's, would bind to them)."""
    undefined = ["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []
    run_paths = [option for directory in dict.fromkeys(str(path.parent) for path in libraries)
                 for option in ("-Xlinker", "-rpath", "-Xlinker", directory)]
    return [*compiler.command, _OPTIMIZATION, *compiler.flags, "-shared", "-pthread", *undefined, "-o", str(output),
            *map(str, objects), *map(str, libraries), *run_paths, "-lm"]


def cache_directory() -> Path:
    """Where compiled libraries are cached: ``$KRONLAG_CACHE`` or ``~/.cache/kronlag``.

    :func:`compile_shared_library` creates it with mode 0700 and uses it only if it belongs to the
    user, no one else can write to it and it is writable; otherwise it warns once
    (:class:`CacheWarning`, naming the directory and the reason) and uses a private temporary
    directory for the rest of the process.
    """
    return Path(os.environ.get("KRONLAG_CACHE") or Path.home() / ".cache" / "kronlag")


#: The private temporary directory used instead of each unusable cache directory (one warning each).
_FALLBACKS: dict[Path, Path] = {}


def _cache_problems(directory: Path) -> list[str]:
    """Why ``directory`` (created 0700 if missing) cannot hold compiled code: empty if it can.

    A library there is loaded into the process: a directory another user can
    write to would let that user run code as whoever runs kronlag.
    """
    try:
        directory.mkdir(mode=0o700, parents=True, exist_ok=True)
        status = directory.stat()
    except OSError as error:
        return [f"it cannot be created ({error.strerror or error})"]
    problems = []
    if not stat.S_ISDIR(status.st_mode):
        problems.append("it is not a directory")
    if hasattr(os, "geteuid") and status.st_uid != os.geteuid():
        problems.append(f"it is owned by uid {status.st_uid}, not by you (uid {os.geteuid()})")
    writers = [who for who, bit in (("its group", stat.S_IWGRP), ("others", stat.S_IWOTH)) if status.st_mode & bit]
    if writers:
        problems.append(f"it is writable by {' and '.join(writers)} (mode {stat.S_IMODE(status.st_mode):o})")
    for parent in directory.resolve().parents:  # anyone could rename the directory away and plant another
        mode = parent.stat().st_mode
        if mode & stat.S_IWOTH and not mode & stat.S_ISVTX:
            problems.append(f"it is inside {parent}, which everyone may write to "
                            f"(mode {stat.S_IMODE(mode):o}, no sticky bit)")
    if not problems and not os.access(directory, os.W_OK | os.X_OK):
        problems.append("it is not writable")
    return problems


def _temporary_cache(why: str) -> Path:
    """A new private directory (mkdtemp: mode 0700, the user's) removed at exit; CompilerError
    starting with ``why`` if none can be made."""
    try:
        directory = Path(tempfile.mkdtemp(prefix="kronlag-cache-"))
    except OSError as error:
        raise CompilerError(f"{why}, nor create a private temporary directory: {error}") from None
    atexit.register(shutil.rmtree, directory, ignore_errors=True)
    return directory


def _fallback_directory(directory: Path, reason: str) -> Path:
    """A private temporary directory (0700, removed at exit) used instead of ``directory``; the
    first time for ``directory``, a :class:`CacheWarning` naming it and ``reason``."""
    if directory not in _FALLBACKS:
        fallback = _temporary_cache(f"cannot use the kronlag cache directory {directory} ({reason})")
        warnings.warn(f"not using the kronlag cache directory {directory}: {reason}; compiled code goes to the "
                      f"private temporary directory {fallback} for this run (point $KRONLAG_CACHE to a directory "
                      "of your own, mode 700, to keep it)", CacheWarning, stacklevel=4)
        _FALLBACKS[directory] = fallback
    return _FALLBACKS[directory]


def _private_cache_directory() -> Path:
    """:func:`cache_directory` if it is the user's alone and writable, else its private fallback."""
    directory = cache_directory()
    if directory in _FALLBACKS:
        return _FALLBACKS[directory]
    problems = _cache_problems(directory)
    if problems:
        return _fallback_directory(directory, "; ".join(problems))
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


def _keyed_source(source: str, key: str) -> str:
    """``source`` with :data:`KEY_FUNCTION` returning ``key`` (in part 0 of a library compiled in parts)."""
    return (f"{source}\n#if !defined(KRONLAG_PART) || KRONLAG_PART == 0\n"
            f"const char *{KEY_FUNCTION}(void) {{ return \"{key}\"; }}\n#endif\n")


def _build_plan(source: str, parts: int, libraries: tuple[Path, ...] = ()) -> tuple[CCompiler, list[tuple[str, ...]],
                                                                                    str]:
    """The compiler, the optimization flags of each part and the library's key (a hash of them, the
    compiler's identity, the source and the paths of the shared libraries linked)."""
    compiler, failures = _choose(_candidates())
    if compiler is None:
        raise CompilerError(f"the C backend needs a working C compiler ({failures}); "
                            "use backend='python'")
    kernel_level = _LARGE_KERNEL_OPTIMIZATION if _kernel_characters(source) > C_LARGE_SOURCE else (_OPTIMIZATION,)
    if _LOCAL_TEMPORARY.search(source):
        kernel_level += _LOCAL_KERNEL_FLAGS
    levels = [_SOLVER_FLAGS] + [kernel_level] * (parts - 1) if parts > 1 else [(_OPTIMIZATION,)]
    facts = (compiler.identity, *_CFLAGS, *map(" ".join, levels), source, *(f"link {path}" for path in libraries))
    key = hashlib.sha256("\0".join(facts).encode()).hexdigest()[:32]
    return compiler, levels, key


def compile_shared_library(source: str, *, parts: int | None = None, libraries: tuple[Path, ...] = ()) -> Path:
    """Compile C ``source`` into a shared library in :func:`cache_directory` (reused when intact).

    ``parts`` defaults to :func:`library_parts`.  With ``parts > 1`` the source is compiled ``parts`` times in parallel with
    ``-DKRONLAG_PART=i -DKRONLAG_PARTS=parts`` (each keeps the chunks
    ``KRONLAG_IN_PART`` selects) and the objects are linked; part 0, the
    hand-written C, with :data:`_SOLVER_FLAGS` (``-O3``), the others, the generated
    kernel chunks, at ``-O2``, or ``-O1`` when they are longer than
    :data:`C_LARGE_SOURCE` characters.  A single part is compiled at ``-O2``.  The library
    exports ``const char *kronlag_library_key(void)`` (:data:`KEY_FUNCTION`) returning its key,
    the hash of the source and the flags in its name (``kronlag_<key>.so``), which
    :func:`load_shared_library` checks after loading.  The library is renamed into place, then its
    SHA-256 is written next to it (``<library>.sha256``); a library whose content does not match
    its recorded hash (truncated, replaced, or its build interrupted) is rebuilt, never returned.
    ``libraries``: shared libraries (absolute paths) linked into it, with their directories as run
    paths; their paths are part of the key.

    Raises
    ------
    CompilerError
        No compiler, or it failed.
    """
    compiler, levels, key = _build_plan(source, library_parts(source) if parts is None else parts, libraries)
    target = _private_cache_directory() / f"kronlag_{key}.so"
    return target if _intact(target) else _build(compiler, levels, _keyed_source(source, key), target, libraries)


def load_shared_library(source: str, *, parts: int | None = None, libraries: tuple[Path, ...] = ()) -> ctypes.CDLL:
    """:func:`compile_shared_library`, loaded with :mod:`ctypes` and checked to be the library of
    ``source``: one whose key does not match (the files of two models swapped, a truncated or
    foreign file) is rebuilt; if the rebuilt one does not match either, a :class:`CacheWarning`
    and the library is built again in a private temporary directory.

    Raises
    ------
    CompilerError
        No compiler, it failed, or not even the library built privately carries the key.
    """
    compiler, levels, key = _build_plan(source, library_parts(source) if parts is None else parts, libraries)
    source = _keyed_source(source, key)
    directory = _private_cache_directory()
    target = directory / f"kronlag_{key}.so"
    if _intact(target) and (library := _load_keyed(target, key)):
        return library
    try:
        _build(compiler, levels, source, target, libraries)
    except OSError as error:  # full, or made read-only since it was checked
        target = _fallback_directory(cache_directory(), f"writing there failed ({error})") / target.name
        _build(compiler, levels, source, target, libraries)
    if library := _load_keyed(target, key):
        return library
    private = _temporary_cache(f"the library {target} does not carry its key {key} after rebuilding")
    warnings.warn(f"the compiled library {target} still does not carry its key {key} after rebuilding it: "
                  f"building it again in the private temporary directory {private}", CacheWarning, stacklevel=2)
    target = _build(compiler, levels, source, private / target.name, libraries)
    if library := _load_keyed(target, key):
        return library
    raise CompilerError(f"the library built from this model's C code in {private} does not carry its key {key}")


def _load_keyed(path: Path, key: str) -> ctypes.CDLL | None:
    """The library at ``path`` loaded, if its :data:`KEY_FUNCTION` returns ``key``; else None (unloaded again)."""
    try:
        library = ctypes.CDLL(str(path))
    except OSError:  # not a shared library of this machine, or truncated
        return None
    try:
        function = getattr(library, KEY_FUNCTION)
    except AttributeError:
        function = None
    if function is not None:
        function.argtypes, function.restype = [], ctypes.c_char_p
        if function() == key.encode():
            return library
    unload = getattr(_ctypes, "dlclose", None)
    if unload is not None:  # so that the path can be loaded again once rebuilt
        unload(library._handle)
    return None


#: The guards of generated kernel chunks, ``KRONLAG_IN_PART(<chunk>)`` (:func:`library_parts`).
_CHUNK_GUARD = re.compile(r"KRONLAG_IN_PART\((\d+)\)")
#: Most parts a library is compiled in (one compiler process each).
_MAX_PARTS = 8


def library_parts(source: str) -> int:
    """The number of parts a generated ``source`` is compiled in: part 0 (the hand-written C) and one
    per core for its kernel chunks (the guards ``KRONLAG_IN_PART(c)``, ``c >= 1``), at most
    :data:`_MAX_PARTS`.  A library that appends code to another's source (a driver) gets the same
    parts, so that its kernel parts are the same objects (:func:`_build` reuses them)."""
    chunks = max((int(chunk) for chunk in _CHUNK_GUARD.findall(source)), default=0)
    return 1 + min(chunks, os.cpu_count() or 1, _MAX_PARTS - 1)


#: A kernel chunk: its guard and its code.
_CHUNK = re.compile(r"^#if KRONLAG_IN_PART\(([1-9]\d*)\)\n(.*?)^#endif", re.DOTALL | re.MULTILINE)


def _kernel_characters(source: str) -> int:
    """The length of the kernel chunks of ``source`` outside part 0 (what decides their optimization
    level: a driver appended to a model's source keeps the level, and so the objects, of its kernel parts)."""
    return sum(len(match.group(2)) for match in _CHUNK.finditer(source))


def _object_key(compiler: CCompiler, level: tuple[str, ...], preprocessed: bytes) -> str:
    return hashlib.sha256("\0".join((compiler.identity, *_CFLAGS, *level)).encode() + b"\0" + preprocessed).hexdigest()[:32]


def _compile_parts(compiler: CCompiler, levels: list[tuple[str, ...]], source_path: Path, work: Path,
                   cache: Path) -> list[Path]:
    """The objects of the parts of ``source_path``, compiled in parallel; a part compiled in parts is
    preprocessed first and its object reused from ``cache`` when the same compiler and flags compiled
    the same preprocessed text before (the kernel parts of a model, again in a driver's library)."""
    parts = len(levels)
    defines = [(f"-DKRONLAG_PART={i}", f"-DKRONLAG_PARTS={parts}") if parts > 1 else () for i in range(parts)]
    objects = [work / f"part{i}.o" for i in range(parts)]
    # part 0 (the hand-written C, and the library's key) directly; the kernel parts preprocessed first
    inputs: list[tuple[tuple[str, ...], Path, Path, Path | None]] = [((*levels[0], *defines[0]), source_path,
                                                                      objects[0], None)]
    # named .c, not .i: zig cc (clang 22) refuses its own -mcpu flag on .i inputs
    preprocessing = [(i, work / f"part{i}_preprocessed.c") for i in range(1, parts)]
    try:
        steps = [subprocess.Popen([*compiler.command, *levels[i], *defines[i], *_CFLAGS, *compiler.flags, "-E", "-P",
                                   "-o", str(path), str(source_path)],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for i, path in preprocessing]
    except OSError as error:
        raise CompilerError(f"cannot run the C compiler {compiler}: {error}") from None
    for (i, path), step in zip(preprocessing, steps):
        error = step.communicate()[1]
        if step.returncode:
            raise CompilerError(f"preprocessing the generated C code with {compiler} failed: exit status "
                                f"{step.returncode}\n{error[-4000:]}".rstrip())
        cached = cache / f"kronlag_part_{_object_key(compiler, levels[i], path.read_bytes())}.o"
        if _intact(cached):
            objects[i] = cached
        else:
            inputs.append(((*levels[i], *defines[i]), path, objects[i], cached))
    try:
        processes = [subprocess.Popen(_compile_command(compiler, flags, path, obj),
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                     for flags, path, obj, _ in inputs]
    except OSError as error:
        raise CompilerError(f"cannot run the C compiler {compiler}: {error}") from None
    errors = [process.communicate()[1] for process in processes]
    failed = [f"exit status {process.returncode}\n{error[-4000:]}"
              for process, error in zip(processes, errors) if process.returncode]
    if failed:
        raise CompilerError(f"compiling the generated C code with {compiler} failed: {failed[0]}".rstrip())
    for _, _, obj, cached in inputs:
        if cached is not None:  # the object first, its hash after (as a library)
            shutil.copyfile(obj, work / "object.part")
            os.replace(work / "object.part", cached)
            _write_atomically(_digest_path(cached), _digest(cached).encode(), work)
    return objects


def _build(compiler: CCompiler, levels: list[tuple[str, ...]], source: str, target: Path,
           libraries: tuple[Path, ...] = ()) -> Path:
    """Compile ``source`` (in parts, one per entry of ``levels``; :func:`_compile_parts`) into ``target``
    linked with the shared ``libraries``, then write its digest."""
    with tempfile.TemporaryDirectory(dir=target.parent) as work:
        source_path = Path(work) / "model.c"
        source_path.write_text(source)
        objects = _compile_parts(compiler, levels, source_path, Path(work), target.parent)
        built = Path(work) / "model.so"
        link = subprocess.run(_link_command(compiler, objects, built, libraries), capture_output=True, text=True)
        failed = [f"exit status {link.returncode} (linking)\n{link.stderr[-4000:]}"] if link.returncode else []
        if failed or not built.is_file():
            output = failed[0] if failed else "no library was written"
            raise CompilerError(f"compiling the generated C code with {compiler} failed: {output}".rstrip())
        # the library first, its hash after: a library without a matching hash is never loaded
        digest = _digest(built)
        os.replace(built, target)
        _write_atomically(_digest_path(target), digest.encode(), Path(work))
    return target
