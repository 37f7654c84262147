"""The compiled integrators' drivers: C files appended to the model's C source, compiled once per
model, called through ctypes with one :class:`~.interface.DriverOptions`; their outputs and return
codes turned into segments of a solution.

A compiled integrator is a C file in ``simulation/c/`` defining ``int kronlag_<name>(kronlag_options *)``
and an entry in :data:`DRIVERS`; :func:`run` calls it.  CVODE's and DOP853's share the Baumgarte
ODE, the projection and the outputs of ``cvode.c`` and one library."""

from __future__ import annotations

import ctypes
import math
import mmap
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from itertools import accumulate
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import CompilerError, InputError
from ..numeric import codegen
from ..numeric.numeric_model import LIBRARY_EXTENSIONS, NOT_FINITE
from ..numeric.tolerances import numerical_rank
from .controllers import ControlledModel
from .dop853 import c_coefficients
from .interface import DriverOptions, GapFunction, c_declarations, doubles
from .problem import MultibodyProblem, Solution, Solver, SolverOptions, derived_shapes
from .stepping import SUCCESS, approach_text, stopped_text
from .trajectory import Result, SingularPassage
from .watch import LimitStop

if TYPE_CHECKING:
    from ..numeric.numeric_model import NumericModel

__all__ = ["DRIVERS", "Driver", "driver", "driver_source", "run", "Segment", "output_rows", "segment_status", "solution_of",
           "require", "sundials_libraries", "has_driver"]


_SUNDIALS_LIBRARIES = ("sundials_core", "sundials_nvecserial", "sundials_sunmatrixdense",
                       "sundials_sunlinsoldense", "sundials_cvode")


#: Most singular passages stored per run segment (more are counted).
_MAX_EVENTS = 1000


#: Most rows allocated for outputs at every step (``t_eval`` None): a longer run needs ``t_eval``.
_MAX_STEP_ROWS = 1_000_000

#: Output blocks of more bytes than this are mapped with small pages (:func:`_block`).
_LARGE_BLOCK = 1 << 22


@lru_cache(maxsize=1)
def sundials_libraries() -> tuple[Path, ...]:
    """The SUNDIALS shared libraries of the scikit-sundae wheel (``scikit_sundae.libs``) that CVODE
    needs, each after those it depends on (also shipped inside an FMU, :mod:`kronlag.views.fmu`); looked
    up once a process (a sweep's every case needs them)."""
    import sksundae

    directory = Path(sksundae.__file__).resolve().parent.parent / "scikit_sundae.libs"
    found = []
    for name in _SUNDIALS_LIBRARIES:
        matches = sorted(directory.glob(f"lib{name}-*.so*")) or sorted(directory.glob(f"lib{name}.so*"))
        if not matches:
            raise CompilerError(f"the compiled method needs lib{name} from scikit-sundae, not found in {directory}")
        found.append(matches[0])
    return tuple(found)


@lru_cache(maxsize=None)
def _c_file(name: str) -> str:
    """The text of ``simulation/c/<name>``, the C of the compiled integrators (read once a process)."""
    return (Path(__file__).with_name("c") / name).read_text()


@lru_cache(maxsize=None)
def _driver_library(source: str, libraries: tuple[Path, ...]) -> ctypes.CDLL:
    """``source`` (a model's C source with kernels and a driver appended) compiled once, linked with the
    shared ``libraries`` (cached on disk by :func:`codegen.compile_shared_library`, keyed by a hash of
    the source and the libraries' paths), loaded and its key checked (:func:`codegen.load_shared_library`).
    The libraries are loaded as its dependencies, not with global symbols: another SUNDIALS in the same
    process (FMPy's) is not bound to them."""
    return codegen.load_shared_library(source, libraries=libraries)


@dataclass(frozen=True)
class Driver:
    """A compiled integrator.

    Attributes
    ----------
    files : tuple of str
        Its C files in ``simulation/c/``, the last defining ``int <entry>(kronlag_options *options)``.
    entry : str
    kernels : tuple of str
        The model's kernels it calls besides the dynamics (appended to ``model.c_source``).
    label : str
        The integrator's name in failure messages.
    sundials : bool
        It calls SUNDIALS (linked with the libraries of scikit-sundae, :func:`sundials_libraries`).
    flag_names : str or None
        A C function ``const char *(int)`` naming its return codes that are no :class:`Result`'s.
    tables : callable or None
        Returns C text its files read, put before them (DOP853's coefficients).
    """

    files: tuple[str, ...]
    entry: str
    kernels: tuple[str, ...]
    label: str
    sundials: bool = False
    flag_names: str | None = None
    tables: Callable[[], str] | None = None


#: The integrators of the Baumgarte ODE, one library (the default method's, built with the model):
#: CVODE's driver and DOP853's, which reads the coefficients and the functions of ``cvode.c``.
_INDEX1_FILES, _INDEX1_KERNELS = ("cvode.c", "dop853.c"), ("potential_energy", "Phi_q")

#: The compiled integrators by name.
DRIVERS = {
    "cvode": Driver(_INDEX1_FILES, "kronlag_cvode", _INDEX1_KERNELS, "CVODE", sundials=True,
                    flag_names="kronlag_cvode_flag_name", tables=c_coefficients),
    "dop853": Driver(_INDEX1_FILES, "kronlag_dop853", _INDEX1_KERNELS, "DOP853", sundials=True, tables=c_coefficients),
    "index3": Driver(("index3.c",), "kronlag_index3", ("tangent", "potential_energy"), "ALI3-P"),
}


#: Loaded driver libraries per model (a model's are built once, on first use).
_LOADED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def driver_source(model: NumericModel, kind: str) -> str:
    """The C source of the driver ``kind`` of :data:`DRIVERS` for ``model``: the model's C source, the
    kernels, :func:`~.interface.c_declarations`, ``monitor.c``, ``progress.c``, ``limits.c``,
    ``controller.c`` and the driver's file (also the core of an exported FMU)."""
    return model.c_source + _driver_extension(model, kind)


def _driver_extension(model: NumericModel, kind: str) -> str:
    """What :func:`driver_source` appends to the model's C source."""
    spec = DRIVERS[kind]
    # the driver in part 0 (KRONLAG_IN_PART): its library reuses the kernel parts of the model's, compiled already
    return (model.c_kernels(*spec.kernels) + "#if KRONLAG_IN_PART(0)\n" + c_declarations()
            + _c_file("monitor.c") + _c_file("progress.c") + _c_file("limits.c") + _c_file("controller.c")
            + (spec.tables() if spec.tables else "") + "".join(_c_file(name) for name in spec.files) + "#endif\n")


def has_driver(model: NumericModel) -> bool:
    """Whether a driver library of ``model`` is loaded already (it then runs without a compiler: a
    run need not look for one again, which costs a search of ``PATH``)."""
    if isinstance(model, ControlledModel):
        model = model.uncontrolled
    return bool(_LOADED.get(model))


def driver(model: NumericModel, kind: str) -> ctypes.CDLL:
    """The shared library of ``model`` with the driver ``kind`` of :data:`DRIVERS` (:func:`driver_source`)."""
    if isinstance(model, ControlledModel):  # a run's view of a model: the model's own libraries
        model = model.uncontrolled
    libraries = _LOADED.setdefault(model, {})
    if kind not in libraries:
        spec = DRIVERS[kind]
        linked = tuple(sundials_libraries()) if spec.sundials else ()
        library = _driver_library(driver_source(model, kind), linked)
        function = getattr(library, spec.entry)
        function.argtypes, function.restype = [ctypes.POINTER(DriverOptions)], ctypes.c_int
        if spec.flag_names:
            names = getattr(library, spec.flag_names)
            names.argtypes, names.restype = [ctypes.c_int], ctypes.c_char_p
        libraries[kind] = library
    return libraries[kind]


def default_driver_extension(model: NumericModel) -> tuple[str, tuple[Path, ...]] | None:
    """The CVODE driver (the default method's, away from singular configurations) to compile with
    ``model``'s library (:data:`~kronlag.numeric.numeric_model.LIBRARY_EXTENSIONS`): its library is
    then the model's, and a first ``simulate`` compiles nothing.  None for a model with time-varying
    parameters (it runs in Python) or without scikit-sundae (the run that needs it says so)."""
    if model.time_varying:
        return None
    try:
        linked = tuple(sundials_libraries())
    except (CompilerError, ImportError):
        return None
    return _driver_extension(model, "cvode"), linked


LIBRARY_EXTENSIONS.append(default_driver_extension)


def passage(model: NumericModel, record: np.ndarray) -> SingularPassage:
    """A :class:`SingularPassage` from a record ``[t_enter, t_exit, t, ratio, row, q (m)]`` of
    ``src/kronlag/simulation/c/monitor.c``; the constraints involved are read off the left singular vector of
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
    (``flag``: 0 at ``t1``, positive for a hand-over, negative for a failure: :class:`Result` codes
    and :data:`~.interface.HANDBACK`)."""

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
    #: Lowest and highest order used ((0, 0): a fixed-order driver).
    orders: tuple[int, int] = (0, 0)
    #: Limits: the watched functions that fell through zero (``flag`` :attr:`Result.LIMIT`).
    triggered: tuple[int, ...] = ()
    #: Under a controller, the parameters at the outputs (N, P) (:attr:`Solution.parameters`).
    parameters: np.ndarray | None = None
    #: Exact stiction: the directions the driver turned itself (:attr:`Solution.turns`).
    turns: np.ndarray | None = None

    @property
    def hands_over(self) -> bool:
        """It ended for the other method of the switching solver to continue."""
        return self.flag > 0

    def without_first_row(self) -> Segment:
        """The segment without its first output (the hand-over state, already output)."""
        return replace(self, t=self.t[1:], y=self.y[1:],
                       derived={key: value[1:] for key, value in self.derived.items()},
                       parameters=None if self.parameters is None else self.parameters[1:])


def output_rows(problem: MultibodyProblem, t0: float, options: SolverOptions) -> tuple[np.ndarray, int]:
    """The output times left after ``t0`` (``t_eval`` strictly after it, or an empty array for
    every step) and the number of rows to allocate."""
    if problem.t_eval is None:
        return np.empty(0), min(options.max_steps + 1, _MAX_STEP_ROWS)
    times = np.ascontiguousarray(problem.t_eval[problem.t_eval > t0] if t0 > problem.t0 else problem.t_eval)
    return times, len(times)


def _buffers(model: NumericModel, rows: int, watched: int, controlled: bool, turns: int) -> dict[str, np.ndarray]:
    """The output buffers of :class:`~.interface.DriverOptions` by field name: ``t_out`` (rows,),
    ``y_out`` (rows, 2 m), the derived quantities of :class:`Solution` (rows, ...), ``events``,
    ``y_end``, the limits' ``roots`` (``watched`` functions) and ``p_out`` (rows, P) under a
    controller, ``turns`` (``turns`` rows, exact stiction); C-contiguous parts of one block (one allocation: with outputs at every step, ``rows``
    is large and the driver touches only the rows it writes)."""
    m, r, s = model.m, model.r, model.s
    shapes = {"t_out": (rows,), "y_out": (rows, 2 * m), **derived_shapes(rows, m, r, s),
              "events": (_MAX_EVENTS, 5 + m), "y_end": (2 * m,), "roots": (max(watched, 1),),
              "p_out": (rows if controlled else 0, len(model.parameter_names)), "turns": (max(turns, 1), 2 + 4 * m)}
    ends = list(accumulate((math.prod(shape) for shape in shapes.values()), initial=0))
    block = _block(ends[-1])
    return {name: block[start:end].reshape(shape) for (name, shape), start, end in zip(shapes.items(), ends, ends[1:])}


def _block(size: int) -> np.ndarray:
    """``size`` uninitialised doubles.  A large block (outputs at every step: rows for ``max_steps``, most
    never written) is mapped with small pages where the system says so (``MADV_NOHUGEPAGE``): with
    transparent huge pages the first write into each of its parts would zero a 2 MiB page, about 5 ms a
    driver call (a run with exact stiction calls the driver once per segment)."""
    if size * 8 <= _LARGE_BLOCK or not hasattr(mmap, "MADV_NOHUGEPAGE"):
        return np.empty(size)
    mapped = mmap.mmap(-1, size * 8)
    mapped.madvise(mmap.MADV_NOHUGEPAGE)
    return np.frombuffer(mapped, dtype=float)


def run(kind: str, problem: MultibodyProblem, options: SolverOptions, t0: float, y0: np.ndarray,
        **inputs: float | np.ndarray) -> Segment:
    """The driver ``kind`` of :data:`DRIVERS` from the consistent state ``(t0, y0)`` (2 m,).

    ``inputs`` set fields of :class:`~.interface.DriverOptions` beyond those that follow from
    ``problem`` and ``options`` (or replace them, e.g. a scaled ``rtol``); arrays are passed as
    ``double *``.
    """
    model = problem.model
    library = driver(model, kind)
    times, rows = output_rows(problem, t0, options)
    watch = problem.watch
    loop = model.loop if isinstance(model, ControlledModel) else None
    turns = int(inputs.get("max_turns", 0))
    buffers = _buffers(model, rows, watch.size if watch else 0, loop is not None, turns)
    p = model.parameter_vector(t0)
    arrays = {"p": p, "y0": y0, "t_eval": times}
    arrays |= {name: value for name, value in inputs.items() if isinstance(value, np.ndarray)}
    arrays = {name: np.ascontiguousarray(value, dtype=float) for name, value in arrays.items()}
    progress, progress_interval = options.control.c_progress(options.progress)
    fields = {"n_parameters": len(p), "t0": t0, "t1": problem.t1, "rtol": options.rtol, "atol": options.atol,
              "max_step": options.max_step if np.isfinite(options.max_step) else 0.0, "max_steps": options.max_steps,
              "max_order": options.max_order or 0, "n_eval": len(times), "max_rows": rows, "max_events": _MAX_EVENTS,
              "t_end": t0, "progress": progress, "progress_interval": progress_interval}
    fields |= {name: value for name, value in inputs.items() if name not in arrays}
    if watch is not None:  # limits: the functions the driver watches (c/limits.c)
        fields |= {"gaps": GapFunction(watch.kernels.c_address), "n_gaps": len(watch.kernels),
                   "n_contacts": len(watch.contact_rows)}
        if watch.first_step > 0 and "h0" not in inputs:
            fields["h0"] = watch.first_step
        arrays |= {"gap_parameters": p, "gap_watched": watch.watched.astype(float),
                   "contact_rows": np.array(watch.contact_rows, dtype=float)}
    if loop is not None:  # the controller's buffers are the loop's own (it reads and writes them)
        control = loop.driver_fields(rows)
        arrays |= {name: control.pop(name) for name in ("p_control", "control_buffer")}
        fields |= control
    arguments = DriverOptions(**fields, **{name: doubles(array) for name, array in (arrays | buffers).items()})
    flag = getattr(library, DRIVERS[kind].entry)(ctypes.byref(arguments))
    n = arguments.n_out
    outputs = {name: buffers[name][:n].copy() for name in ("t_out", "y_out", *Solution.DERIVED)}
    passages = tuple(passage(model, record) for record in buffers["events"][:min(arguments.n_events, _MAX_EVENTS)])
    return Segment(t=outputs.pop("t_out"), y=outputs.pop("y_out"), derived=outputs, events=passages, flag=flag,
                   t_end=arguments.t_end, y_end=buffers["y_end"].copy(), steps=arguments.steps, nfev=arguments.nfev,
                   njev=arguments.njev, orders=(arguments.lowest_order, arguments.highest_order),
                   triggered=tuple(np.flatnonzero(buffers["roots"][:watch.size]).tolist()) if watch else (),
                   parameters=buffers["p_out"][:n].copy() if loop is not None else None,
                   turns=buffers["turns"][:arguments.n_turns].copy() if turns else None)


def segment_status(segment: Segment, model: NumericModel, kind: str) -> tuple[Result, str]:
    """The :class:`Result` of a driver's ``segment`` and the message: ``Integration failed at t = ...,
    q = ...: reason[; the last singular passage]``."""
    result = Result.of_code(segment.flag)
    if result is Result.SUCCESS:
        return result, SUCCESS
    if result is Result.LIMIT:  # an event: the run goes on from there (no message shown; q not formatted)
        return result, f"{result.value} at t = {segment.t_end:.9g}"
    q = segment.y_end[:model.m]
    if result is Result.APPROACH:
        return result, approach_text(segment.t_end, q)
    if result in (Result.INTERRUPTED, Result.RAISED):
        return result, stopped_text(segment.t_end, result)
    reason, spec = result.value, DRIVERS[kind]
    if result is Result.SOLVER_FAILED and spec.flag_names:
        name = getattr(driver(model, kind), spec.flag_names)(segment.flag).decode()
        reason = f"{spec.label} {name} ({segment.flag})"
    if result is Result.SINGULAR and not np.isfinite(segment.y_end).all():
        result, reason = Result.SOLVER_FAILED, NOT_FINITE
    message = f"Integration failed at t = {segment.t_end:.6g}, q = {np.array2string(q, precision=6)}: {reason}"
    return result, message + (f"; last passage: {segment.events[-1]}" if segment.events else "")


def solution_of(segments: Sequence[Segment], result: Result, message: str) -> Solution:
    """The :class:`Solution` of consecutive segments (one segment's arrays as they are, not copied)."""
    def joined(arrays: list) -> np.ndarray:
        return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)

    derived = {key: joined([segment.derived[key] for segment in segments]) for key in segments[0].derived}
    return Solution(t=joined([segment.t for segment in segments]),
                    y=joined([segment.y for segment in segments]), result=result, message=message,
                    nfev=sum(segment.nfev for segment in segments), njev=sum(segment.njev for segment in segments),
                    steps=sum(segment.steps for segment in segments), derived=derived,
                    events=tuple(event for segment in segments for event in segment.events),
                    stop=_limit_stop(segments[-1]),
                    parameters=None if segments[0].parameters is None
                    else joined([segment.parameters for segment in segments]),
                    turns=_turns(segments))


def _turns(segments: Sequence[Segment]) -> np.ndarray | None:
    """The directions the drivers of ``segments`` turned (:attr:`Solution.turns`), None where none could."""
    turns = [segment.turns for segment in segments if segment.turns is not None]
    return np.concatenate(turns) if turns else None


def _limit_stop(segment: Segment) -> LimitStop | None:
    """Limits: where ``segment`` ended at an event, or None."""
    if segment.flag != Result.LIMIT.code:
        return None
    return LimitStop(segment.t_end, segment.y_end.copy(), segment.triggered)


def require(solver: Solver, model: NumericModel) -> None:
    """Raise :class:`InputError` if ``solver`` cannot run ``model`` (saying what it needs)."""
    if not solver.supports(model):
        raise InputError(f"method={solver.name!r} cannot run this model: {solver.requirements}")
