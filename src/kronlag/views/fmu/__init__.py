"""FMU export: a numeric model as a Functional Mock-up Unit (FMI 2.0 or 3.0, Model Exchange and
Co-Simulation in one binary), for Simulink, Dymola, OpenModelica, FMPy and other importers.

:func:`export_fmu` writes ``<modelIdentifier>.fmu``: ``modelDescription.xml`` (:mod:`.description`),
``binaries/<platform>/<modelIdentifier>.so`` compiled here from the model's generated C with the SUNDIALS
libraries it links next to it, and ``sources/`` with that C, the FMI headers and
``buildDescription.xml`` (:mod:`.build`).  ``docs/fmu.md`` lists what is exported.
"""

from __future__ import annotations

import datetime
import hashlib
import re
import uuid
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from ...core.errors import CompilerError, InputError
from ...numeric import codegen
from ...numeric.reactions import multiplier_labels
from .build import STANDARDS, build_description, c_source, compile_fmu, reactions, temporary_directory
from .description import KINDS, Layout, model_description

if TYPE_CHECKING:
    from ...numeric.numeric_model import NumericModel

__all__ = ["export_fmu", "KINDS", "input_parameters"]

#: The matrices an input parameter must not enter (it may enter the generalized forces ``f_Q`` only).
_NOT_IN_INPUTS = ("M", "Cqd", "g", "Phi", "A", "b")

#: Largest constraint residual of a start state (larger: not an assembled state; the FMU projects the
#: start values onto the constraints, which from far away may find another assembly branch).
_START_RESIDUAL = 1e-6

#: Most CVODE steps of one co-simulation step.
_MAX_STEPS = 1_000_000


def input_parameters(model: NumericModel) -> tuple[str, ...]:
    """The parameters that enter the equations only through the generalized forces ``f_Q`` (a drive
    torque, an external force) and are not defined by an expression of others: an FMU's inputs."""
    equations = model.equations
    defined = model.parameter_definitions()
    potential = sp.sympify(equations.potential_energy)
    uses = [expression.free_symbols for expression in defined.values()]
    found = []
    for symbol in equations.parameters:
        if symbol.name in defined or any(symbol in used for used in uses) or potential.has(symbol):
            continue
        if equations.f_Q.has(symbol) and not any(getattr(equations, name).has(symbol) for name in _NOT_IN_INPUTS):
            found.append(symbol.name)
    return tuple(found)


def _identifier(name: str) -> str:
    """``name`` as a C identifier (the FMU's modelIdentifier and file name)."""
    identifier = re.sub(r"\W", "_", name, flags=re.ASCII) or "model"
    return f"_{identifier}" if identifier[0].isdigit() else identifier


def _c_model(model: NumericModel) -> NumericModel:
    """``model`` with the C backend (built again when it has the Python one); InputError for a
    time-varying parameter, CompilerError without a C compiler."""
    varying = [name for name, value in model.parameter_values().items() if callable(value)]
    if varying:
        raise InputError(f"parameter(s) {', '.join(varying)} vary with time (a Python function of t), which an FMU "
                         "cannot contain: give them constant values (an input parameter becomes an FMU input)")
    if model.backend == "c":
        return model
    if codegen.c_compiler() is None:
        raise CompilerError("FMU export needs a C compiler (gcc or cc on PATH, or $CC) to build the FMU's binary")
    from ...numeric.numeric_model import NumericModel

    return NumericModel(model.equations, {**model.parameter_values(), **model.parameter_definitions()},
                        backend="c", rank_rtol=model.rank_rtol)


def _start_state(model: NumericModel, q0, qd0) -> np.ndarray:
    q = model.state_vector(np.zeros(model.m) if q0 is None else q0, "q0")
    qd = model.state_vector(np.zeros(model.m) if qd0 is None else qd0, "qd0")
    if not (np.isfinite(q).all() and np.isfinite(qd).all()):
        raise InputError("q0 and qd0 must be finite")
    residual = float(np.max(np.abs(model.Phi(q)), initial=0.0))
    if residual > _START_RESIDUAL * (1.0 + float(np.max(np.abs(q), initial=0.0))):
        raise InputError(f"q0 = {np.array2string(q, precision=6)} violates the constraints (max |Phi| = "
                         f"{residual:.3g}): give an assembled start state (q0, qd0 = model.assemble(...))")
    return np.concatenate([q, qd])


def _inputs(model: NumericModel, inputs: Iterable[str] | None) -> tuple[str, ...]:
    if inputs is None:
        return input_parameters(model)
    chosen = tuple(inputs)
    if isinstance(inputs, str):
        raise InputError(f"inputs must be a sequence of parameter names, got the string {inputs!r}")
    defined = model.parameter_definitions()
    for name in chosen:
        if name not in model.parameter_names:
            raise InputError(f"inputs: {name!r} is not a parameter of the model "
                             f"(parameters: {', '.join(model.parameter_names)})")
        if name in defined:
            raise InputError(f"inputs: {name!r} is defined by an expression of other parameters ({defined[name]}); "
                             "it cannot be an input")
    return chosen


def _kinds(kinds: Sequence[str] | str) -> tuple[str, ...]:
    chosen = (kinds,) if isinstance(kinds, str) else tuple(kinds)
    unknown = [kind for kind in chosen if kind not in KINDS]
    if unknown or not chosen:
        raise InputError(f"kinds must be one or both of {', '.join(map(repr, KINDS))}, got {kinds!r}")
    return chosen


def _checked(value: float, name: str, *, zero: bool = False) -> float:
    """``value`` as a finite float, positive (or zero with ``zero``); InputError naming ``name`` otherwise."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if not (np.isfinite(number) and (number > 0 or (zero and number == 0))):
        raise InputError(f"{name} must be a {'non-negative' if zero else 'positive'} number, got {value!r}")
    return number


def export_fmu(model: NumericModel, path: str | Path, *, q0=None, qd0=None, inputs: Iterable[str] | None = None,
               fmi_version: str = "2.0", kinds: Sequence[str] | str = KINDS, stop_time: float = 1.0,
               tolerance: float = 1e-8, alpha: float = 10.0, beta: float = 10.0,
               drift_tolerance: float = 1e-6, model_identifier: str | None = None,
               units: Mapping[str, str] | None = None) -> Path:
    """Write ``model`` as an FMU (FMI 2.0 or 3.0) compiled for this platform.

    The FMU has the states ``q`` and ``qd`` (outputs; start values ``q0``, ``qd0``, projected onto the
    constraints when initialization ends), every parameter (tunable; those defined by an expression of
    others, ``I1 = m1*l1**2/12``, are calculated parameters computed from them), the input parameters as
    inputs, and the outputs ``lambda[<constraint>]``, the joint reactions ``<joint>.Fx, .Fy[, .Fz]``,
    ``.Mz`` (or ``.Mx, .My, .Mz``) in the world frame, ``kinetic_energy``, ``potential_energy`` and
    ``energy``.  Model Exchange integrates the Baumgarte index-1 ODE ``[q, qd]' = [qd, qdd]`` and
    projects the states at a step event when the drift exceeds ``drift_tolerance``; Co-Simulation runs
    CVODE (Adams) as ``kronlag.simulate``'s compiled method, its relative tolerance the importer's
    (``fmi2SetupExperiment``) or ``tolerance``, with the state projected at every communication point.

    Parameters
    ----------
    model : NumericModel
        Without time-varying parameters; rebuilt with the C backend if it has the Python one.
    path : str or Path
        The ``.fmu`` file to write.
    q0, qd0 : array_like, shape (m,), optional
        Start state: an assembled one (``model.assemble``); zeros by default.
    inputs : iterable of str, optional
        The parameters that become FMU inputs; by default :func:`input_parameters`, those entering
        only the generalized forces.
    fmi_version : {"2.0", "3.0"}
    kinds : "model-exchange", "co-simulation" or both (the default)
    stop_time, tolerance : float
        The ``DefaultExperiment``; ``tolerance`` is also co-simulation's relative tolerance when the
        importer gives none (its absolute one is ``tolerance / 100``).
    alpha, beta : float
        Baumgarte's parameters (1/s; tunable in the FMU as ``kronlag.alpha``, ``kronlag.beta``).
    drift_tolerance : float
        Constraint residual that triggers a projection in model exchange (``kronlag.drift_tolerance``).
    model_identifier : str, optional
        Default: the system's name as a C identifier.
    units : mapping of str to str, optional
        Units of coordinates and parameters by name (and ``"energy"``), as a model file gives them
        (``kronlag.app.workflows.model_units`` and ``ModelFile.units``); the speeds get ``<unit>/s``.
        Reactions are in ``N`` and ``N*m``, energies in ``J`` unless given.  Units pint does not
        know are left out.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        A time-varying parameter, a start state off the constraints, an unknown input, an FMI version
        or platform not supported, FMPy (the FMI headers) not installed.
    CompilerError
        No C compiler, or it failed.
    """
    if fmi_version not in STANDARDS:
        raise InputError(f"fmi_version={fmi_version!r}: kronlag writes FMI {' and '.join(STANDARDS)} FMUs")
    standard = STANDARDS[fmi_version]
    target = Path(path)
    if target.suffix != ".fmu":
        raise InputError(f"{target}: an FMU file name ends with .fmu")
    chosen_kinds = _kinds(kinds)
    settings = (_checked(alpha, "alpha", zero=True), _checked(beta, "beta", zero=True),
                _checked(drift_tolerance, "drift_tolerance"))
    tolerance, stop_time = _checked(tolerance, "tolerance"), _checked(stop_time, "stop_time")
    model = _c_model(model)
    start = _start_state(model, q0, qd0)
    input_names = _inputs(model, inputs)
    system = model.equations.system
    identifier = model_identifier or _identifier(system.name)
    if _identifier(identifier) != identifier:
        raise InputError(f"model_identifier {identifier!r} is not a C identifier")
    calculated = tuple(model.parameter_definitions())
    try:
        tool = f"kronlag {version('kronlag')}"
    except PackageNotFoundError:
        tool = "kronlag"
    speeds = tuple(symbol.name for symbol in model.equations.speeds)
    digest = hashlib.sha256("\0".join((model.c_source, *model.parameter_names, *input_names, repr(start.tolist()),
                                       repr(model.parameter_vector().tolist()), repr(settings), tool)).encode())
    guid = "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"
    reactions_code, reaction_names, reaction_units = reactions(model)
    layout = Layout(tuple(model.coordinate_names), speeds, tuple(model.parameter_names),
                    tuple(multiplier_labels(system, with_units=False)), tuple(reaction_names))
    source = c_source(model, standard, layout_macros=layout.c_macros(), reactions_code=reactions_code, guid=guid,
                      start_state=start, calculated=calculated, settings=settings, rtol=tolerance,
                      max_steps=_MAX_STEPS)
    variables = layout.variables(start_state=start, parameter_values=model.parameter_vector(),
                                 calculated=calculated, inputs=input_names, settings=settings, units=units or {},
                                 reaction_units=reaction_units, independent_time=standard.version == "3.0")
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    description = model_description(standard.version, model_name=system.name, identifier=identifier, guid=guid,
                                    description=f"{system.name}: kronlag multibody model", tool=tool, date=now,
                                    variables=variables, source_file=f"{identifier}.c", stop_time=stop_time,
                                    tolerance=tolerance, kinds=chosen_kinds)
    with temporary_directory() as work:
        root = Path(work)
        binaries = root / "binaries" / standard.platform
        compile_fmu(source, standard, identifier, binaries, root / "sources")
        libraries = [library.name for library in sorted(binaries.iterdir()) if library.name != f"{identifier}.so"]
        (root / "sources" / "buildDescription.xml").write_text(build_description(identifier, libraries, standard))
        (root / "modelDescription.xml").write_text(description)
        target.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as archive:
            for file in sorted(root.rglob("*")):
                if file.is_file():
                    archive.write(file, file.relative_to(root).as_posix())
    return target
