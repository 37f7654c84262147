"""The ``[controller]`` table of a model file: a controller in the loop of ``kronlag simulate``
(:func:`kronlag.simulate`'s ``controller=``), for the two common cases.

Linear state feedback ``u = -K (x - x_ref)`` on named coordinates and speeds (``q1``, ``q1d``),
continuous or sampled with a period::

    [controller]
    type = "state_feedback"
    input = "u"                                   # a parameter of the model (a force, a torque)
    states = ["x_cart", "theta_pole", "x_cartd", "theta_poled"]
    gains = [-1.0, {value = 30, unit = "N/rad"}, -2.0, 5.0]   # K: numbers (SI) or {value, unit}
    reference = [0, "pi/2", 0, 0]                 # x_ref, optional (zero); numbers or constants
    period = 0.001                                # optional: sampled with a zero-order hold

A PID controller of one coordinate, sampled (``period`` required)::

    [controller]
    type = "pid"
    input = "tau"
    coordinate = "q1"
    setpoint = 0.5
    kp = {value = 20, unit = "N*m/rad"}
    ki = 5.0                                      # SI: the input's unit / (coordinate's unit * s)
    kd = 1.0                                      # SI: the input's unit / (coordinate's unit / s)
    period = 0.001

At sample ``k`` (time ``t_k``), with ``e_k = setpoint - q(t_k)``: ``I_k = I_(k-1) + period e_k``
(``I_(-1) = 0``) and ``u_k = kp e_k + ki I_k - kd qd(t_k)`` (the derivative acts on the measured
speed, not on the error: no kick when the setpoint changes), held until ``t_(k+1)``.

The gains are numbers in SI units (the input's unit per unit of the state), or ``{value, unit}``
converted to SI; a gain with a unit is checked against the dimensions of the input and of the
state (:mod:`.dimension_check`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, cast

import sympy as sp

from ..dimensions import Dimension, DimensionCheck, Place
from ..symbols import speed_symbol, t
from .units import si_unit

if TYPE_CHECKING:
    from .model_file import ModelFile
    from .reader import _Reader

__all__ = ["StateFeedback", "PID", "ControllerSpec", "read_controller", "write_controller",
           "check_controller_dimensions"]


@dataclass(frozen=True)
class Gain:
    """A gain in SI units, and the unit it was written in (None: a plain number)."""

    value: float
    unit: str | None = None
    dimension: Dimension | None = None


@dataclass(frozen=True)
class StateFeedback:
    """``input = -sum_i gains[i] (x_i - reference[i])``, ``x_i`` the coordinate or speed ``states[i]``
    (a speed is the coordinate's name + ``d``); sampled every ``period`` when given."""

    input: str
    states: tuple[str, ...]
    gains: tuple[Gain, ...]
    reference: tuple[float, ...]
    period: float | None = None


@dataclass(frozen=True)
class PID:
    """A sampled PID controller of ``coordinate`` (see the module docstring for the law)."""

    input: str
    coordinate: str
    setpoint: float
    kp: Gain
    ki: Gain
    kd: Gain
    period: float


ControllerSpec = StateFeedback | PID


def _gain(reader: _Reader, value, entry: str) -> Gain:
    if isinstance(value, dict):
        reader.table(value, entry, required=("value", "unit"))
        number = reader.number(value["value"], f"{entry}.value")
        text = reader.string(value["unit"], f"{entry}.unit")
        try:
            one, _ = si_unit(text)
        except ValueError as error:
            raise reader.error(f"{entry}.unit", str(error)) from None
        # pint types an exponent as any scalar; a unit's are rational
        return Gain(number * float(one.magnitude), text, Dimension(cast(Mapping[str, Fraction], one.dimensionality)))
    return Gain(reader.number(value, entry))


def _constant(reader: _Reader, value, entry: str) -> float:
    """A number or a constant expression (``"pi/2"``): no parameters (they may change in a sweep)."""
    expression = reader.expression(value, entry, {})
    number = complex(expression.evalf()) if expression.is_number else complex("nan")
    if number.imag or not sp.Float(number.real).is_finite:
        raise reader.error(entry, f"expected a finite number or a constant expression, got {value!r}")
    return number.real


def _input(reader: _Reader, model: ModelFile, table: dict) -> str:
    name = reader.string(table["input"], "controller.input")
    parameters = [p.name for p in model.system.parameters]
    if name not in parameters:
        raise reader.error("controller.input", f"{name!r} is not a parameter of the model (parameters: "
                                               f"{', '.join(parameters) or 'none'})")
    return name


def read_controller(reader: _Reader, document: dict, model: ModelFile) -> ControllerSpec | None:
    """The ``[controller]`` table of ``document``, or None; errors located ``FILE: controller.<field>: ...``."""
    if "controller" not in document:
        return None
    table = document["controller"]
    kind = reader.string(reader.table(table, "controller", required=("type",), optional=(
        "type", "input", "states", "gains", "reference", "coordinate", "setpoint", "kp", "ki", "kd", "period"))
        ["type"], "controller.type")
    coordinates = [q.name for q in model.system.coordinates]
    if kind == "state_feedback":
        reader.table(table, "controller", required=("type", "input", "states", "gains"),
                     optional=("reference", "period"))
        speeds = [f"{name}d" for name in coordinates]
        states = table["states"]
        if not isinstance(states, list) or not states:
            raise reader.error("controller.states", "expected a non-empty list of coordinate or speed names")
        for i, name in enumerate(states):
            if reader.string(name, f"controller.states[{i}]") not in coordinates + speeds:
                raise reader.error(f"controller.states[{i}]", f"{name!r} is neither a coordinate "
                                                              f"({', '.join(coordinates)}) nor a speed ({', '.join(speeds)})")
        for key in ("gains", "reference"):
            if key in table and (not isinstance(table[key], list) or len(table[key]) != len(states)):
                raise reader.error(f"controller.{key}", f"expected a list of {len(states)} entries, one per state")
        gains = tuple(_gain(reader, value, f"controller.gains[{i}]") for i, value in enumerate(table["gains"]))
        reference = tuple(_constant(reader, value, f"controller.reference[{i}]")
                          for i, value in enumerate(table.get("reference", [0] * len(states))))
        period = reader.number(table["period"], "controller.period", positive=True) if "period" in table else None
        return StateFeedback(_input(reader, model, table), tuple(states), gains, reference, period)
    if kind == "pid":
        reader.table(table, "controller", required=("type", "input", "coordinate", "period"),
                     optional=("setpoint", "kp", "ki", "kd"))
        coordinate = reader.string(table["coordinate"], "controller.coordinate")
        if coordinate not in coordinates:
            raise reader.error("controller.coordinate", f"unknown coordinate {coordinate!r}; coordinates are "
                                                        f"{', '.join(coordinates)}")
        pid_gains = {key: _gain(reader, table.get(key, 0.0), f"controller.{key}") for key in ("kp", "ki", "kd")}
        setpoint = _constant(reader, table.get("setpoint", 0), "controller.setpoint")
        return PID(_input(reader, model, table), coordinate, setpoint,
                   period=reader.number(table["period"], "controller.period", positive=True), **pid_gains)
    raise reader.error("controller.type", f"expected 'state_feedback' or 'pid', got {kind!r}")


def write_controller(spec: ControllerSpec) -> dict:
    """The ``[controller]`` table of ``spec`` (gains with a unit written in SI, so that they read back exactly)."""

    def gain(value: Gain) -> float | dict:
        return value.value if value.unit is None else {"value": value.value, "unit": si_unit(value.unit)[1]}

    if isinstance(spec, PID):
        return {"type": "pid", "input": spec.input, "coordinate": spec.coordinate, "setpoint": spec.setpoint,
                "kp": gain(spec.kp), "ki": gain(spec.ki), "kd": gain(spec.kd), "period": spec.period}
    return {"type": "state_feedback", "input": spec.input, "states": list(spec.states),
            "gains": [gain(value) for value in spec.gains], "reference": list(spec.reference),
            **({} if spec.period is None else {"period": spec.period})}


def check_controller_dimensions(check: DimensionCheck, model: ModelFile) -> None:
    """Each gain written with a unit has the dimension of the input over that of its state
    (raises :class:`~kronlag.model.dimensions.DimensionConflict` naming ``controller.<gain>``)."""
    spec = model.controller
    if spec is None:
        return
    symbols = {q.name: q for q in model.system.coordinates}
    symbols.update({f"{q.name}d": speed_symbol(q) for q in model.system.coordinates})
    input_symbol = next(p for p in model.system.parameters if p.name == spec.input)
    if isinstance(spec, StateFeedback):
        pairs = [(f"controller.gains[{i}]", gain, symbols[name])
                 for i, (gain, name) in enumerate(zip(spec.gains, spec.states))]
    else:
        q = symbols[spec.coordinate]
        pairs = [("controller.kp", spec.kp, q), ("controller.ki", spec.ki, q * t), ("controller.kd", spec.kd, q / t)]
    for entry, gain, state in pairs:
        if gain.dimension is not None:
            # the gain times the state is the input: input / state has the gain's dimension
            check.use(input_symbol / state, gain.dimension, Place(f"{entry}.unit", entry))
