"""Parameter sweeps: many simulations of one model, on local worker processes or a Dask cluster.

:func:`sweep` runs one simulation per case -- a set of parameter values and
initial coordinates or speeds, from a grid or a list of samples -- and gathers a
:class:`pandas.DataFrame` of scalar outcomes, one row per case.  The first two
cases run in the calling process; the faster of them estimates the rest, which
run there too when that is quicker than starting workers
(:data:`PARALLEL_FROM_SECONDS`), else on local worker processes
(:mod:`kronlag.studies.local_pool`: forked, no scheduler) or, given
``scheduler``, on the workers of a Dask cluster, in batches of cases
(:data:`TASK_SECONDS` each).  The model is built once: each worker unpickles it
once and makes every case with :meth:`~kronlag.numeric.NumericModel.with_parameters`
(no code generated or compiled per case).  A case that fails keeps its row, with
its status and message; a task lost with a dying worker is run again elsewhere.
Rows are handed to ``on_row`` as cases finish, and a sweep stopped by Ctrl-C
raises :class:`SweepInterrupted` carrying the finished rows.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import math
import pickle
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.errors import InputError
from ..numeric.numeric_model import NumericModel
from ..simulation.labelled import LabelledArrays, rate_unit
from ..simulation.controllers import Sampled
from ..simulation.simulate import simulate
from .local_pool import run_batches, usable_cpus

if TYPE_CHECKING:
    import pandas
    import xarray

    from ..simulation.trajectory import Trajectory

__all__ = ["sweep", "SweepResult", "SweepInterrupted", "grid", "DEFAULT_OUTCOMES", "PARALLEL_FROM_SECONDS",
           "TASK_SECONDS"]


def _final_coordinates(trajectory: Trajectory) -> dict[str, float]:
    return {f"{name}_final": float(value) for name, value in zip(trajectory.coordinate_names, trajectory.q[-1])}


def _energy_drift(trajectory: Trajectory) -> float:
    """``max |E(t) - E(0) - W(t) - E_events(t)|``: the energy balance with the work ``W`` of non-conservative
    forces, dampers and drives, less what the events (impacts) changed (:attr:`Trajectory.energy_drift`), as
    ``kronlag simulate`` reports it."""
    drift = trajectory.energy_drift
    return float(np.max(np.abs(drift))) if drift.size else 0.0


def _max_position_residual(trajectory: Trajectory) -> float:
    residual = trajectory.position_residual
    return float(np.max(np.abs(residual))) if residual.size else 0.0


#: Outcomes recorded when none are given: ``name -> f(trajectory)``; a function returning a
#: dict contributes one column per key.  ``energy_drift`` is the energy balance
#: ``max |E(t) - E(0) - W(t)|`` less what impacts changed, zero up to the integration error also for
#: driven and damped models and with impacts.
DEFAULT_OUTCOMES: dict[str, Callable] = {
    "final": _final_coordinates,
    "energy_drift": _energy_drift,
    "max_position_residual": _max_position_residual,
}


def _column_units(units: Mapping[str, str], coordinate_names: Sequence[str]) -> dict[str, str]:
    """The units of the table's columns that ``units`` (by name) determine: the swept parameters and
    coordinates, the speeds, the default outcomes and ``wall_time``."""
    known = {name: unit for name, unit in units.items() if name not in ("t", "energy")}
    known |= {f"{name}d": rate for name in coordinate_names if (rate := rate_unit(units.get(name), units))}
    known |= {f"{name}_final": units[name] for name in coordinate_names if name in units}
    if "energy" in units:
        known["energy_drift"] = units["energy"]
    return known | {"wall_time": "s"}


_STATUS_OK, _STATUS_FAILED, _STATUS_ERROR, _STATUS_LOST = "ok", "failed", "error", "lost"

#: Without a scheduler, the cases after the first two run on local worker processes only when they would
#: take at least this long in this process (s, estimated from the faster of the first two): below it,
#: starting the workers (0.1-0.3 s forked, more spawned) and shipping the model would cost more than
#: they save.
PARALLEL_FROM_SECONDS = 1.0

#: The duration a task (a batch of cases) is sized to, in s, by the time of the first cases: long against
#: the few ms a task costs to send and gather, short against the whole sweep (a balanced end).
TASK_SECONDS = 0.25


def grid(**axes: Sequence[float]) -> list[dict[str, float]]:
    """All combinations of the values of each named axis (the last name varies fastest).

    >>> grid(m2=[1.0, 2.0], q1d=[0.0, 3.0])
    [{'m2': 1.0, 'q1d': 0.0}, {'m2': 1.0, 'q1d': 3.0}, {'m2': 2.0, 'q1d': 0.0}, {'m2': 2.0, 'q1d': 3.0}]
    """
    names = list(axes)
    return [dict(zip(names, (float(value) for value in values)))
            for values in itertools.product(*(axes[name] for name in names))]


@dataclass(frozen=True, eq=False)
class SweepResult:
    """What :func:`sweep` gathered.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per case, in the order of the cases: ``case``, the swept values,
        ``status`` (``"ok"``; ``"failed"``: the integrator stopped; ``"error"``: an
        exception, e.g. no consistent initial state; ``"lost"``: the task could not be
        run, e.g. its workers kept dying), ``message``, the outcomes and
        ``wall_time`` (s, in the worker).
    trajectories : dict of int -> Trajectory, or None
        With ``keep_trajectories=True``: the trajectory of every case that ran.
    """

    table: pandas.DataFrame
    trajectories: dict[int, Trajectory] | None = None

    @property
    def failed(self) -> pandas.DataFrame:
        """The rows whose status is not ``"ok"``."""
        return self.table[self.table["status"] != _STATUS_OK]

    @classmethod
    def _of(cls, cases: list[dict], results: Mapping[int, tuple[dict, Trajectory | None]],
            keep_trajectories: bool) -> SweepResult:
        """The result of the finished cases (``results`` by case index), in the order of the cases."""
        import pandas as pd

        rows = [_row(index, cases[index], results[index][0]) for index in sorted(results)]
        leading = ["case", *dict.fromkeys(name for case in cases for name in case), "status", "message"]
        table = pd.DataFrame(rows, columns=None if rows else leading)
        table = table[leading + [column for column in table.columns if column not in leading]]
        trajectories = ({index: trajectory for index, (_, trajectory) in results.items() if trajectory is not None}
                        if keep_trajectories else None)
        return cls(table, trajectories)

    def to_xarray(self, *, units: Mapping[str, str] | None = None) -> xarray.Dataset:
        """The kept trajectories as an :class:`xarray.Dataset` with dimensions ``case``, ``time``,
        ``coordinate`` (variables ``q``, ``qd``; the cases' scalar columns as coordinates of
        ``case``).  Needs xarray and ``keep_trajectories=True`` with a common ``t_eval``.

        ``units`` (by name: the parameters', and the coordinates', ``"t"`` and ``"energy"`` as
        :meth:`kronlag.Trajectory.to_xarray` takes them) become the ``units`` attributes of ``q``,
        ``qd``, the swept parameters, coordinates and speeds, and the default outcomes
        (:data:`DEFAULT_OUTCOMES`: ``<q>_final`` in the unit of ``q``, ``energy_drift`` in the
        energy's); ``wall_time`` is in ``s``.
        """
        if not self.trajectories:
            raise InputError("no trajectories kept: run the sweep with keep_trajectories=True")
        cases = sorted(self.trajectories)
        first = self.trajectories[cases[0]]
        if any(len(self.trajectories[case].t) != len(first.t) or not np.allclose(self.trajectories[case].t, first.t)
               for case in cases):
            raise InputError("the trajectories have different output times: give t_eval to the sweep")
        arrays = LabelledArrays(first.t, units)
        rows = self.table.set_index("case").loc[cases]
        column_units = _column_units(arrays.units, first.coordinate_names)
        arrays.dimension("case", cases)
        arrays.coords |= {column: ("case", rows[column].to_numpy(),
                                   {"units": column_units[column]} if column in column_units else {})
                          for column in rows.columns}
        arrays.coordinates(first.coordinate_names, np.stack([self.trajectories[c].q for c in cases]),
                           np.stack([self.trajectories[c].qd for c in cases]), None,
                           dims=("case", "time", "coordinate"))
        return arrays.dataset({})


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C (KeyboardInterrupt) stopped a :func:`sweep`; ``partial`` is the :class:`SweepResult` of
    the cases that finished (``except KeyboardInterrupt as stop: stop.partial``)."""

    def __init__(self, partial: SweepResult, total: int):
        super().__init__(f"sweep interrupted after {len(partial.table)} of {total} cases")
        self.partial = partial


def _row(index: int, values: Mapping[str, float], row: Mapping[str, Any]) -> dict[str, Any]:
    """A row of the table: the case's index, its swept values, then what the run gave."""
    return {"case": index, **values, **row}


# -- one case, in a worker ----------------------------------------------------------------------------

#: Models unpickled in this process, by the hash of their pickle (a worker unpickles a model once).
_MODELS: dict[str, Any] = {}


def _unpickled(token: str, payload: bytes):
    model = _MODELS.get(token)
    if model is None:
        model = _MODELS[token] = pickle.loads(payload)
    return model


def _run_case(source, values: Mapping[str, float], settings: Mapping[str, Any]) -> tuple[dict, Trajectory | None]:
    """Simulate one case; never raises (a failure becomes the row's status and message)."""

    started = time.perf_counter()
    row: dict[str, Any] = {}
    trajectory = None
    try:
        if isinstance(source, NumericModel):
            state = _state_names(source)
            model = source.with_parameters({k: v for k, v in values.items() if k not in state})
        else:
            model = source(dict(values))
        q0, qd0 = _initial_state(model, values, settings)
        trajectory = simulate(model, settings["t_span"], q0, qd0, **settings["simulate"])
        row["status"] = _STATUS_OK if trajectory.success else _STATUS_FAILED
        row["message"] = trajectory.message
        for name, outcome in settings["outcomes"].items():
            value = outcome(trajectory)
            row.update(value if isinstance(value, Mapping) else {name: float(value)})
    except Exception as error:  # a case's failure is data, reported in its row
        row.update(status=_STATUS_ERROR, message=f"{type(error).__name__}: {error}")
    row["wall_time"] = time.perf_counter() - started
    return row, trajectory if settings["keep_trajectories"] else None


def _state_names(model: NumericModel) -> dict[str, tuple[str, str]]:
    """Swept names that set the initial state: ``"q1" -> ("q", "q1")``, ``"q1d" -> ("qd", "q1")``."""
    names = {name: ("q", name) for name in model.coordinate_names}
    names.update({f"{name}d": ("qd", name) for name in model.coordinate_names})
    return names


def _initial_state(model: NumericModel, values: Mapping[str, float], settings: Mapping[str, Any]):
    """``(q0, qd0)``: the given state, or the guess with swept coordinates/speeds held, assembled."""
    initial = settings["initial_states"]
    if callable(initial):
        return initial(model, dict(values))
    q, qd = (np.array(x, dtype=float) for x in initial)
    fixed = {name: q[i] for i, name in enumerate(model.coordinate_names) if name in settings["fixed"]}
    qd_fixed = {name: qd[i] for i, name in enumerate(model.coordinate_names) if name in settings["qd_fixed"]}
    held, state = {"q": fixed, "qd": qd_fixed}, _state_names(model)
    for name, value in values.items():
        if name in state:
            kind, coordinate = state[name]
            held[kind][coordinate] = value
    if not fixed and not qd_fixed and not settings["assemble"]:
        return q, qd
    return model.assemble(q, fixed=fixed or None, qd_guess=qd, qd_fixed=qd_fixed or None)


def _run_batch(token: str, payload: bytes, cases: list[tuple[int, dict]], settings_payload: bytes) -> list:
    """The task sent to a worker: a batch of cases of one model."""
    source = _unpickled(token, payload)
    settings = _unpickled(hashlib.sha256(settings_payload).hexdigest(), settings_payload)
    return [(index, *_run_case(source, values, settings)) for index, values in cases]


# -- the sweep ------------------------------------------------------------------------------------------


def _batches(cases: Iterable[tuple[int, dict]], size: int) -> Iterator[list[tuple[int, dict]]]:
    """The ``(index, case)`` pairs in consecutive batches of ``size`` (one pass over the cases)."""
    batch: list[tuple[int, dict]] = []
    for item in cases:
        batch.append(item)
        if len(batch) == size:
            yield batch
            batch = []
    if batch:
        yield batch


def _check_options(workers, batch_size, retries) -> None:
    """InputError for a negative number of workers or retries or a batch size below 1."""
    for name, value, least in (("workers", 0 if workers is None else workers, 0), ("retries", retries, 0),
                               ("batch_size", 1 if batch_size is None else batch_size, 1)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
            raise InputError(f"{name} must be an integer >= {least}, got {value!r}")


def _cases(parameters) -> list[dict[str, float]]:
    """Cases from a grid (mapping name -> values), a list of dicts, or a DataFrame (one case a row)."""
    if isinstance(parameters, Mapping):
        return grid(**parameters)
    if hasattr(parameters, "to_dict") and hasattr(parameters, "columns"):
        return [{k: float(v) for k, v in row.items()} for row in parameters.to_dict("records")]
    cases = [dict(case) for case in parameters]
    if not all(isinstance(case, dict) for case in cases):
        raise InputError("parameters must be a mapping name -> values (a grid), a list of dicts or a DataFrame")
    return cases


def _check_names(source, cases: list[dict]) -> None:
    if not isinstance(source, NumericModel):
        return
    known = set(source.parameter_names) | set(_state_names(source))
    unknown = sorted({name for case in cases for name in case} - known)
    if unknown:
        raise InputError(f"unknown swept name(s) {', '.join(unknown)}: expected parameters "
                         f"({', '.join(source.parameter_names)}), coordinates ({', '.join(source.coordinate_names)}) "
                         f"or speeds ({', '.join(n + 'd' for n in source.coordinate_names)})")


class _TextProgress:
    """``[#####.....] done/total cases`` on standard error (a terminal only), at most 10 redraws/s."""

    def __init__(self, total: int, stream=None, width: int = 30):
        stream = sys.stderr if stream is None else stream  # the one of the time of the sweep
        self.total, self.stream, self.width, self.drawn = total, stream, width, 0.0
        self.enabled = hasattr(stream, "isatty") and stream.isatty()

    def __call__(self, done: int, total: int) -> None:
        now = time.monotonic()
        if not self.enabled or (now - self.drawn < 0.1 and done < total):
            return
        self.drawn = now
        filled = self.width * done // max(total, 1)
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {done}/{total} cases")
        if done == total:
            self.stream.write("\n")
        self.stream.flush()


def sweep(model_or_factory: NumericModel | Callable[[dict], NumericModel], *, parameters,
          initial_states, t_span: tuple[float, float], outcomes: Mapping[str, Callable] | None = None,
          scheduler=None, client=None, workers: int | None = None, fixed: Iterable[str] = (),
          qd_fixed: Iterable[str] = (), assemble: bool = True, keep_trajectories: bool = False,
          batch_size: int | None = None, retries: int = 3, progress: bool | Callable[[int, int], None] = True,
          on_row: Callable[[dict], None] | None = None, controller: Callable | Sampled | None = None,
          **simulate_options) -> SweepResult:
    """Simulate every case of a grid or sample of parameter values and initial states.

    Parameters
    ----------
    model_or_factory : NumericModel or callable
        A built model (each case is ``model.with_parameters(case)``: no new code), or
        ``factory(case: dict) -> NumericModel`` for cases that change the equations.
        Either is pickled (cloudpickle) and unpickled once per worker.
    parameters : mapping name -> values, list of dicts, or pandas.DataFrame
        A mapping is a grid (every combination, :func:`grid`); a list or a frame gives
        the cases one by one.  A name is a parameter, a coordinate (``q1``: its
        initial value, held while assembling) or a speed (``q1d``).
    initial_states : (q, qd) pair of (m,) arrays, or callable ``f(model, case) -> (q0, qd0)``
        The initial guess, assembled for every case (``model.assemble``) holding
        ``fixed``/``qd_fixed`` and the swept coordinates and speeds; or a function
        returning the consistent state of a case.
    t_span : (t0, t1)
    outcomes : mapping name -> callable(Trajectory), optional
        Scalar outcomes (a callable may return a dict: one column per key);
        :data:`DEFAULT_OUTCOMES` (final coordinates, energy drift: the energy
        balance ``max |E - E(0) - W|``, constraint residual) when omitted.  Must be picklable
        (cloudpickle: lambdas are).
    scheduler : str or dask.distributed.Client, optional
        An existing Dask cluster to run on: its scheduler's address (``"tcp://host:8786"``;
        a client is connected for the sweep and closed after it) or a connected
        ``Client``.  None: local worker processes (``workers``), no Dask.
    client : dask.distributed.Client, optional
        The same as ``scheduler=client`` (give one of the two).
    workers : int, optional
        Local worker processes (>= 0) when no scheduler is given: by default one per CPU
        this process may use; 0 runs every case in this process.  The first two cases
        always run in this process; when the faster of them, times the remaining cases,
        is below :data:`PARALLEL_FROM_SECONDS` (or one worker is all there is), the rest
        run here too: starting workers would cost more than it saves.
    fixed, qd_fixed : coordinate names held while assembling every case.
    assemble : bool
        False: use ``initial_states`` as given (already consistent) when nothing is held.
    keep_trajectories : bool
        Also gather every trajectory (memory!); see :meth:`SweepResult.to_xarray`.
    batch_size : int, optional
        Cases per task, >= 1 (default: at least 4 tasks per worker, each of about
        :data:`TASK_SECONDS` by the time of the first cases).  A task lost with its
        worker is run again (a local one case by case, each up to ``retries`` times);
        on Dask ``retries`` more times when it raises.
    progress : bool or callable ``f(done, total)``
        True: a bar on standard error when it is a terminal (never in tests or
        doctests); False: none.
    on_row : callable ``f(row: dict)``, optional
        Called in this process with each row of the table as its case finishes (in the
        order they finish), e.g. to append it to a file.
    controller : callable or Sampled, optional
        The controller in the loop of every case (:func:`kronlag.simulate`'s ``controller``;
        pickled with cloudpickle, each case starts from its initial ``state``).
    **simulate_options
        Passed to :func:`kronlag.simulate` (``method``, ``rtol``, ``atol``, ``t_eval``, ...).

    Returns
    -------
    SweepResult
        ``table`` (a DataFrame, one row per case), ``trajectories``, ``failed``.

    Raises
    ------
    InputError
        Unknown swept names, ``workers`` or ``retries`` < 0, ``batch_size`` < 1, both
        ``scheduler`` and ``client``.
    SweepInterrupted
        Ctrl-C (a KeyboardInterrupt) stopped the sweep; its ``partial`` is the
        :class:`SweepResult` of the cases that finished.
    """
    _check_options(workers, batch_size, retries)
    if scheduler is not None and client is not None:
        raise InputError("give scheduler= or client=, not both")
    scheduler = client if scheduler is None else scheduler
    cases = _cases(parameters)
    _check_names(model_or_factory, cases)
    settings = {"t_span": tuple(t_span), "initial_states": initial_states, "fixed": set(fixed),
                "qd_fixed": set(qd_fixed), "assemble": assemble, "outcomes": dict(outcomes or DEFAULT_OUTCOMES),
                "keep_trajectories": keep_trajectories, "simulate": {**simulate_options, "controller": controller}}
    report = progress if callable(progress) else _TextProgress(len(cases)) if progress else (lambda done, total: None)
    results: dict[int, tuple[dict, Trajectory | None]] = {}

    def finished(index: int, row: dict, trajectory: Trajectory | None) -> None:
        results[index] = (row, trajectory)
        if on_row is not None:
            on_row(_row(index, cases[index], row))
        report(len(results), len(cases))

    try:
        local = usable_cpus() if workers is None else workers
        first = 0 if scheduler is None and local == 0 else min(len(cases), 2)
        for index in range(first):  # in this process: their time estimates the rest
            finished(index, *_run_case(model_or_factory, cases[index], settings))
        rest = list(enumerate(cases))[first:]
        per_case = min((results[index][0]["wall_time"] for index in range(first)), default=0.0)
        if scheduler is not None:
            _run_distributed(model_or_factory, rest, settings, scheduler, per_case, batch_size, retries, finished)
        elif rest and local > 1 and per_case * len(rest) >= PARALLEL_FROM_SECONDS:
            _run_local(model_or_factory, rest, settings, local, per_case, batch_size, retries, finished)
        else:
            for index, values in rest:
                finished(index, *_run_case(model_or_factory, values, settings))
    except KeyboardInterrupt:
        raise SweepInterrupted(SweepResult._of(cases, results, keep_trajectories), len(cases)) from None
    return SweepResult._of(cases, results, keep_trajectories)


def _batch_size(count: int, workers: int, per_case: float) -> int:
    """Cases per task: at least 4 tasks a worker (the last to finish leaves the others idle for at most
    about one task), each of about :data:`TASK_SECONDS` (a task's overhead is a few ms)."""
    balanced = math.ceil(count / (4 * max(workers, 1)))
    short = int(TASK_SECONDS / per_case) if per_case > 0 else balanced
    return max(1, min(balanced, short))


def _shipped(source, settings) -> tuple[str, bytes, bytes]:
    """The model (or factory) and the settings pickled for the workers, with the model's token."""
    try:
        import cloudpickle
    except ImportError as error:
        raise ImportError("kronlag.sweep needs cloudpickle for worker processes: pip install cloudpickle "
                          "(or kronlag[sweep]); workers=0 runs the cases in this process") from error
    payload = cloudpickle.dumps(source)  # carries lambdas: factories, time-varying parameters, outcomes
    return hashlib.sha256(payload).hexdigest(), payload, cloudpickle.dumps(settings)


def _lost(batch: Sequence[tuple[int, dict]], message: str) -> list:
    """The rows of the cases of a batch that could not be run."""
    return [(index, {"status": _STATUS_LOST, "message": message, "wall_time": float("nan")}, None)
            for index, _ in batch]


def _run_local(source, cases, settings, workers, per_case, batch_size, retries, finished) -> None:
    """The cases on local worker processes (:mod:`kronlag.studies.local_pool`)."""
    token, payload, settings_payload = _shipped(source, settings)

    def gather(ran: list) -> None:
        for index, row, trajectory in ran:
            finished(index, row, trajectory)

    run_batches(functools.partial(_run_batch, token, payload, settings_payload=settings_payload),
                list(_batches(cases, batch_size or _batch_size(len(cases), workers, per_case))),
                workers=workers, retries=retries, finished=lambda batch, ran: gather(ran),
                lost=lambda batch, message: gather(_lost(batch, message)))


def _run_distributed(source, cases, settings, scheduler, per_case, batch_size, retries, finished) -> None:
    """The cases on a Dask cluster: ``scheduler`` is a ``Client`` or a scheduler's address."""
    try:
        from dask.distributed import Client, as_completed
    except ImportError as error:
        raise ImportError("kronlag.sweep(scheduler=...) needs Dask: pip install 'dask[distributed]' (or "
                          "kronlag[sweep]); without a scheduler the cases run on local processes") from error
    if not cases:
        return
    owned = Client(scheduler) if isinstance(scheduler, str) else None
    client = owned or scheduler
    try:
        token, payload, settings_payload = _shipped(source, settings)
        # sent to every worker once, not with every task (a big model's pickle is megabytes)
        payload, settings_payload = client.scatter([payload, settings_payload], broadcast=True, hash=False)
        threads = sum(worker.get("nthreads", 1) for worker in client.scheduler_info().get("workers", {}).values())
        size = batch_size or _batch_size(len(cases), max(threads, 1), per_case)
        futures = {client.submit(_run_batch, token, payload, batch, settings_payload=settings_payload, pure=False,
                                 retries=retries): batch for batch in _batches(cases, size)}
        for future in as_completed(futures):
            try:
                ran = future.result()
            except Exception as error:  # the task itself was lost (its workers kept dying)
                ran = _lost(futures[future], f"{type(error).__name__}: {error}")
            for index, row, trajectory in ran:
                finished(index, row, trajectory)
    finally:
        if owned is not None:
            owned.close()
