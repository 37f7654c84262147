"""The compiled integrators' drivers: C files appended to the model's C source, compiled once per
model, called through ctypes; their outputs and flags turned into segments of a solution."""

from __future__ import annotations

import ctypes
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import CompilerError, InputError
from ..numeric import codegen
from ..numeric.tolerances import numerical_rank
from .problem import MultibodyProblem, Solution, Solver, SolverOptions
from .stepping import SUCCESS, approach_text
from .trajectory import Result, SingularPassage

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel

__all__ = ["driver", "Segment", "output_rows", "segment_status", "solution_of", "require"]


_SUNDIALS_LIBRARIES = ("sundials_core", "sundials_nvecserial", "sundials_sunmatrixdense",
                       "sundials_sunlinsoldense", "sundials_cvode")


_PROGRESS = ctypes.CFUNCTYPE(None, ctypes.c_double)


#: Most singular passages stored per run segment (more are counted).
_MAX_EVENTS = 1000


#: Most rows allocated for outputs at every step (``t_eval`` None): a longer run needs ``t_eval``.
_MAX_STEP_ROWS = 1_000_000


def _load_sundials() -> None:
    """Load the SUNDIALS shared libraries of the scikit-sundae wheel (``scikit_sundae.libs``)
    with global symbols, so that the driver library resolves its SUNDIALS calls against them."""
    import sksundae

    directory = Path(sksundae.__file__).resolve().parent.parent / "scikit_sundae.libs"
    for name in _SUNDIALS_LIBRARIES:
        matches = sorted(directory.glob(f"lib{name}-*.so*")) or sorted(directory.glob(f"lib{name}.so*"))
        if not matches:
            raise CompilerError(f"the compiled method needs lib{name} from scikit-sundae, not found in {directory}")
        ctypes.CDLL(str(matches[0]), mode=ctypes.RTLD_GLOBAL)


def _c_file(name: str) -> str:
    """The text of ``simulation/c/<name>``, the C of the compiled integrators."""
    return (Path(__file__).with_name("c") / name).read_text()


@lru_cache(maxsize=None)
def _driver_library(source: str) -> ctypes.CDLL:
    """``source`` (a model's C source with kernels and a driver appended) compiled once (cached on
    disk by :func:`codegen.compile_shared_library`, keyed by a hash of the source) and loaded."""
    return ctypes.CDLL(str(codegen.compile_shared_library(source)))


#: The drivers of the compiled methods: the kernels each appends to ``model.c_source`` (after the
#: monitor), its C file, its entry point and the argument types of the entry point.
_P, _D, _I, _L = ctypes.c_void_p, ctypes.c_double, ctypes.c_int, ctypes.c_long


_DRIVERS = {
    "cvode": (("potential_energy", "Phi_q"), "cvode.c", "kronlag_cvode",
              [_P, _D, _D, _P, _I, _P, _D, _D, _D, _D, _D, _L, _I, _P, _P, _P, _P, _P, _I, _P, _P, _P, _PROGRESS]),
    "index3": (("tangent", "potential_energy"), "index3.c", "kronlag_index3",
               [_P, _I, _D, _D, _P, _P, _P, _I, _P, _D, _D, _D, _D, _L, _I, _I] + [_P] * 10
               + [_I, _P, _P, _P, _PROGRESS]),
}


#: Loaded driver libraries per model (a model's are built once, on first use).
_LOADED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def driver(model: NumericModel, kind: str) -> ctypes.CDLL:
    """The shared library of ``model`` with the driver ``kind`` of :data:`_DRIVERS`."""
    libraries = _LOADED.setdefault(model, {})
    if kind not in libraries:
        kernels, file, entry, argtypes = _DRIVERS[kind]
        if kind == "cvode":
            _load_sundials()
        library = _driver_library(model.c_source + model.c_kernels(*kernels) + _c_file("monitor.c") + _c_file(file))
        function = getattr(library, entry)
        function.argtypes, function.restype = argtypes, ctypes.c_int
        if kind == "cvode":
            library.kronlag_outputs.argtypes = [_P, _I] + [_P] * 9
            library.kronlag_outputs.restype = None
            library.kronlag_cvode_flag_name.argtypes = [_I]
            library.kronlag_cvode_flag_name.restype = ctypes.c_char_p
        libraries[kind] = library
    return libraries[kind]


def passage(model: NumericModel, record: np.ndarray) -> SingularPassage:
    """A :class:`SingularPassage` from a record ``[t_enter, t_exit, t, ratio, row, q (m)]`` of
    ``src/kronlag/c/monitor.c``; the constraints involved are read off the left singular vector of
    ``Phi_q`` that belongs to the singular value that (nearly) vanished, the one at the start's rank."""
    t_enter, t_exit, t, ratio, row = record[:5]
    q = np.array(record[5:5 + model.m])
    names = model.constraint_names
    U, S, _ = np.linalg.svd(model.Phi_q(q, t))
    # the smallest singular value above the rank tolerance is the one that (nearly) vanishes
    direction = np.abs(U[:, max(numerical_rank(S, model.rank_rtol), 1) - 1])
    involved = tuple(names[i] for i in np.flatnonzero(direction >= 0.1 * direction.max()))
    return SingularPassage(t=float(t), t_enter=float(t_enter), t_exit=float(t_exit), q=q, ratio=float(ratio),
                           constraints=involved or (names[int(row)],))


@dataclass(eq=False)
class Segment:
    """What one call of a compiled driver produced: outputs, counters, events and where it ended
    (``flag``: 0 at ``t1``, positive for a hand-over, negative for a failure)."""

    t: np.ndarray
    y: np.ndarray
    derived: dict[str, np.ndarray]
    events: tuple[SingularPassage, ...]
    flag: int
    t_end: float
    y_end: np.ndarray
    steps: int
    nfev: int
    njev: int

    def without_first_row(self) -> Segment:
        """The segment without its first output (the hand-over state, already output)."""
        return replace(self, t=self.t[1:], y=self.y[1:], derived={key: value[1:] for key, value in self.derived.items()})


def output_rows(problem: MultibodyProblem, t0: float, options: SolverOptions) -> tuple[np.ndarray, int]:
    """The output times left after ``t0`` (``t_eval`` strictly after it, or an empty array for
    every step) and the number of rows to allocate."""
    if problem.t_eval is None:
        return np.empty(0), min(options.max_steps + 1, _MAX_STEP_ROWS)
    times = np.ascontiguousarray(problem.t_eval[problem.t_eval > t0] if t0 > problem.t0 else problem.t_eval)
    return times, len(times)


#: The flags of the C drivers (``src/kronlag/c/cvode.c``, ``index3.c``) that are not CVODE's own:
#: what each means.
_DRIVER_RESULTS = {
    "cvode": {-1: Result.MAX_STEPS, 2: Result.APPROACH, -1002: Result.PROJECTION_FAILED,
              -1003: Result.SINGULAR, -1004: Result.OUTPUTS_FULL},
    "index3": {-1: Result.MAX_STEPS, -2: Result.STEP_TOO_SMALL, -3: Result.NEWTON_FAILED,
               -6: Result.SINGULAR, -7: Result.OUTPUTS_FULL},
}


def segment_status(segment: Segment, model: NumericModel, kind: str) -> tuple[Result, str]:
    """The :class:`Result` of a driver's ``segment`` and the message: ``Integration failed at t = ...,
    q = ...: reason[; the last singular passage]``."""
    if segment.flag == 0:
        return Result.SUCCESS, SUCCESS
    q = segment.y_end[:model.m]
    result = _DRIVER_RESULTS[kind].get(segment.flag, Result.SOLVER_FAILED)
    if result is Result.APPROACH:
        return result, approach_text(segment.t_end, q)
    reason = result.value
    if result is Result.SOLVER_FAILED:
        reason = f"CVODE {driver(model, 'cvode').kronlag_cvode_flag_name(segment.flag).decode()} ({segment.flag})"
    message = f"Integration failed at t = {segment.t_end:.6g}, q = {np.array2string(q, precision=6)}: {reason}"
    return result, message + (f"; last passage: {segment.events[-1]}" if segment.events else "")


def solution_of(segments: Sequence[Segment], result: Result, message: str) -> Solution:
    """The :class:`Solution` of consecutive segments."""
    derived = {key: np.concatenate([segment.derived[key] for segment in segments]) for key in segments[0].derived}
    return Solution(t=np.concatenate([segment.t for segment in segments]),
                    y=np.concatenate([segment.y for segment in segments]), result=result, message=message,
                    nfev=sum(segment.nfev for segment in segments), njev=sum(segment.njev for segment in segments),
                    steps=sum(segment.steps for segment in segments), derived=derived,
                    events=tuple(event for segment in segments for event in segment.events))


def require(solver: Solver, model: NumericModel) -> None:
    if not solver.supports(model):
        raise InputError(f"method={solver.name!r} cannot run this model: {solver.requirements}")
