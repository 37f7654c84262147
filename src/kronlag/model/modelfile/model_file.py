"""A model file in memory: the :class:`~kronlag.model.system.System` and the numbers for running it."""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import sympy as sp

from ...core.dependencies import dependency_order
from ...core.errors import DrivesNotAppliedWarning, ModelError
from ..system import System
from .units import si_unit

if TYPE_CHECKING:
    from .controller import ControllerSpec

__all__ = ["ModelFile", "SimulationSettings", "PrescribedMotion", "to_float", "settle_drives"]


@dataclass
class SimulationSettings:
    """Settings of a simulation run (see :func:`kronlag.simulate`)."""

    t_end: float = 1.0
    method: str = "auto"
    rtol: float = 1e-8
    atol: float = 1e-10


@dataclass(frozen=True)
class PrescribedMotion:
    """A drive of a model file: ``target(q) = motion(t)`` (a coordinate or an expression of the
    coordinates; an expression of ``t`` and the parameters)."""

    target: sp.Expr
    motion: sp.Expr


@dataclass
class ModelFile:
    """A system together with the numbers needed to run it.

    Attributes
    ----------
    system : System
    description : str
    values : dict of str to sympy.Expr
        Parameter values as written: numbers, or expressions of other
        parameters (``"m1*l1**2/12"``); see :meth:`numeric_values`.  Given to
        ``Equations.numeric`` as they are, the expressions stay definitions that
        ``NumericModel.with_parameters`` (and sweeps) compute again.
    units : dict of str to str
        SI units of the parameters (a file's units are parsed with ``pint`` and its values
        converted to SI base units: ``300`` in ``"mm"`` is stored as 0.3 in ``"m"``).
    file_units : dict of str to str
        The units as the file writes them (``"mm"``): values given later as text
        (:meth:`parameter_value`, the command line's ``--set`` and ``--grid``) are read in them.
    q_guess, qd_guess : dict of str to sympy.Expr
        Assembly guesses by coordinate name (may use parameters); missing
        coordinates default to 0.
    fixed, qd_fixed : tuple of str
        Coordinates whose position / speed assembly keeps at the guess.
    simulation : SimulationSettings
    drives : dict of str to PrescribedMotion
        Prescribed motions by drive name (``target(q) = motion(t)``) for
        kinematic analysis and inverse dynamics, not yet in ``system``; :meth:`driven`
        adds them (:meth:`kronlag.System.add_drive`).
    source : str or None
        The file the model was read from.
    controller : StateFeedback or PID or None
        The ``[controller]`` table (:mod:`.controller`), for ``simulate(controller=...)``
        (:func:`kronlag.simulation.controllers.file_controller` makes the controller).
    """

    system: System
    description: str = ""
    values: dict[str, sp.Expr] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    file_units: dict[str, str] = field(default_factory=dict)
    q_guess: dict[str, sp.Expr] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()
    qd_guess: dict[str, sp.Expr] = field(default_factory=dict)
    qd_fixed: tuple[str, ...] = ()
    simulation: SimulationSettings = field(default_factory=SimulationSettings)
    drives: dict[str, PrescribedMotion] = field(default_factory=dict)
    source: str | None = None
    controller: ControllerSpec | None = None

    def numeric_values(self) -> dict[str, float]:
        """Parameter values as floats, resolving values written in terms of other parameters.

        Raises
        ------
        ModelError
            A value depends on a parameter without a value, or values depend on
            each other in a cycle.
        """
        pending = {name: sp.sympify(value, strict=True) for name, value in self.values.items()}
        uses = {name: {symbol.name for symbol in value.free_symbols} for name, value in pending.items()}
        missing = sorted(set().union(*uses.values()) - pending.keys())
        if missing:
            raise ModelError(f"parameter values use parameters without a value: {', '.join(missing)}")
        order, unresolved = dependency_order(uses)
        if unresolved:
            raise ModelError(f"parameter values depend on each other in a cycle: {', '.join(sorted(unresolved))}")
        resolved: dict[str, float] = {}
        for name in order:
            resolved[name] = to_float(pending[name], resolved, f"value of parameter {name}")
        return {name: resolved[name] for name in pending}

    def driven(self) -> ModelFile:
        """This model with its ``drives`` added to (a copy of) its system as rheonomic constraints
        (:meth:`kronlag.System.add_drive`), and ``drives`` then empty."""
        system = copy.deepcopy(self.system)
        for name, drive in self.drives.items():
            system.add_drive(drive.target, drive.motion, name=name)
        return dataclasses.replace(self, system=system, drives={})

    def parameter_value(self, name: str, text: str) -> float:
        """A value of ``name`` written as text (``--set``, ``--grid``), in the SI units of :attr:`values`.

        A plain number is in the file's unit of the parameter (``"300"`` for a length the file
        gives in ``"mm"`` is 0.3); a number followed by a unit (``"300mm"``, ``"0.3 m"``) is
        converted from that unit, which must have the dimension of the file's.  A name without a
        unit in the file (a coordinate, a speed, a parameter without ``unit``) takes a plain number.

        Raises
        ------
        ModelError
            Not a number, an unknown unit, a unit of another dimension, or a unit for a name
            without one.
        """
        match = _NUMBER_AND_UNIT.fullmatch(text)
        if not match:
            raise ModelError(f"{name}={text}: expected a number, optionally followed by a unit (0.3, 300mm)")
        number, unit = float(match[1]), match[2]
        declared = self.file_units.get(name) or self.units.get(name)
        if not unit:
            return number * (_unit(name, declared).magnitude if declared else 1.0)
        if not declared:
            raise ModelError(f"{name}={text}: {name} has no unit in the model file; give a plain number")
        one, own = _unit(name, unit), _unit(name, declared)
        if one.dimensionality != own.dimensionality:
            raise ModelError(f"{name}={text}: {unit!r} is not a unit of {name}, which the model file gives "
                             f"in {declared!r} ({own.dimensionality})")
        return number * one.magnitude

    def guess_vectors(self, *, values: Mapping[str, float] | None = None) -> tuple[list[float], list[float]]:
        """The assembly guesses ``(q, qd)`` as lists in coordinate order (0 where not given), with the
        parameter values ``values`` (default: :meth:`numeric_values`)."""
        values = self.numeric_values() if values is None else values
        names = [q.name for q in self.system.coordinates]
        return ([to_float(self.q_guess.get(name, 0), values, f"initial q of {name}") for name in names],
                [to_float(self.qd_guess.get(name, 0), values, f"initial qd of {name}") for name in names])


def settle_drives(model: ModelFile, apply_drives: bool | None) -> ModelFile:
    """``model.driven()`` if ``apply_drives``, ``model`` as it is if ``False``; if ``None``, ``model``
    with a :class:`~kronlag.DrivesNotAppliedWarning` when it has drives, saying how to apply them."""
    if apply_drives:
        return model.driven()
    if apply_drives is None and model.drives:
        warnings.warn(f"{model.source or model.system.name}: the [[drives]] ({', '.join(model.drives)}) are not "
                      "in the system: ModelFile.driven() (or load_model(..., apply_drives=True)) adds them; "
                      "apply_drives=False takes the model without them and without this warning",
                      DrivesNotAppliedWarning, stacklevel=3)
    return model


#: A number and an optional unit after it: ``"300mm"``, ``"-1.5e-3 kg*m^2"``.
_NUMBER_AND_UNIT = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*")


def _unit(name: str, text: str):
    """One ``text`` in SI base units (a pint quantity); ModelError naming ``name`` for a bad unit."""
    try:
        return si_unit(text)[0]
    except ValueError as error:
        raise ModelError(f"{name}: {error}") from None


def to_float(expression, values: Mapping[str, float], what: str) -> float:
    expr = sp.sympify(expression, strict=True)
    unknown = sorted(s.name for s in expr.free_symbols if s.name not in values)
    if unknown:
        raise ModelError(f"{what} uses symbols without a value: {', '.join(unknown)}")
    # xreplace, not subs: a fraction of the time, which counts for thousands of parameters
    number = expr.xreplace({s: sp.Float(values[s.name]) for s in expr.free_symbols}).evalf()
    if not number.is_real or not math.isfinite(float(number)):
        raise ModelError(f"{what} is not a finite real number: {number}")
    return float(number)

