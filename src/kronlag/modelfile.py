"""Model files: a mechanism, its parameter values and run settings in TOML.

:func:`load_model` reads a file into a :class:`ModelFile` (the
:class:`~kronlag.System` plus numbers for running it) and :func:`to_toml` /
:func:`dump_model` write one.  Expressions are text read by
:func:`kronlag.expressions.parse_expression`, which admits arithmetic, the
functions ``sin cos tan asin acos atan atan2 sinh cosh tanh sqrt exp log abs``
and ``pi`` only; nothing in a file is executed.  Every error names the file,
the entry (``bodies[2].position[1]``, indices from 0) and the problem.

Format (every table but ``coordinates`` is optional)::

    name = "four_bar"
    description = "Planar four-bar mechanism"
    coordinates = ["q1", "q2", "q3"]
    gravity = [0, "-g"]                         # 2 or 3 entries

    [parameters]                                # number, expression of other parameters,
    l1 = {value = 0.2, unit = "m"}              # or {value = ..., unit = "...", description = "..."};
    I1 = {value = "m1*l1**2/12", unit = "kg*m^2"}   # a parameter without value: {unit = "m"}
    tau = 0

    [points]                                    # named points, usable wherever a point is; their
    B = ["l1*cos(q1)", "l1*sin(q1)"]            # coordinates B_x, B_y (B_z) in any later expression

    [[bodies]]                                  # type = "planar" | "rigid" | "point"
    name = "crank"
    type = "planar"
    mass = "m1"
    inertia = "I1"                              # rigid: 3x3 matrix or 3 principal moments
    position = ["l1/2*cos(q1)", "l1/2*sin(q1)"]
    angle = "q1"                                # rigid: rotation = 3x3 matrix or
                                                # {axes = "zxz", angles = ["psi", "theta", "phi"]}
    points = {B = ["l1/2", 0]}                  # named points in body coordinates (from the centre
                                                # of mass, body axes), usable wherever a point is
    [[joints]]                                  # kronlag.joints: type, body_a ("ground" or a body),
    type = "revolute"                           # body_b; optional name, at_a, at_b (body coordinates
    body_a = "crank"                            # or the name of a point of that body), axis, axis_b,
    body_b = "coupler"                          # angle, rotation; adds the rows "<name>.x", ...
    at_a = "B"
    at_b = ["-l2/2", 0]

    [[constraints]]                             # f(q) = 0, or f(q, t) = 0 (a drive in every run)
    name = "loop x"
    expression = "l1*cos(q1) + l2*cos(q2) - l3*cos(q3) - l4"

    [[nonholonomic_constraints]]                # linear in the speeds q1d, q2d, ...
    [[springs]]        # name, point_a, point_b, stiffness, free_length
    [[dampers]]        # name, point_a, point_b, coefficient
    [[potentials]]     # name, expression
    [[forces]]         # name, point, force (vector; may use t and speeds)
    [[torques]]        # name, body, torque (scalar for planar bodies, 3-vector otherwise), frame
    [[generalized_forces]]   # name, force (one entry per coordinate)

    [initial]
    q = {q1 = 1.0, q2 = "pi/4"}                 # assembly guess (missing coordinates: 0)
    fixed = ["q1"]                              # held at the guess while assembling
    qd = {q1 = 2.0}                             # speed guess
    qd_fixed = ["q1"]

    [simulation]
    t_end = 2.0
    method = "auto"
    rtol = 1e-8
    atol = 1e-10

    [[drives]]                                  # prescribed motion for kinematics and inverse dynamics
    coordinate = "q1"                           # or target = "<expression of q>", e.g. "P_x" of a point P
    motion = "1 + 2*pi*t"                       # optional name (default "drive <target>")

    [[drawing]]                                 # name, points (list of points)
    [[traces]]                                  # name, point
"""

from __future__ import annotations

import functools
import json
import keyword
import math
import re
import tomllib
import unicodedata
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import pint
import sympy as sp
from sympy.printing.str import StrPrinter

from .expressions import RESERVED_NAMES, ExpressionError, parse_expression
from .system import (
    MAX_ROTATION_FACTORS,
    ModelError,
    PlanarBody,
    PointMass,
    RigidBody,
    RotationSequence,
    System,
    drive_name,
    speed_symbol,
    t,
)

__all__ = [
    "ModelFileError",
    "ModelFile",
    "PrescribedMotion",
    "SimulationSettings",
    "load_model",
    "loads_model",
    "to_toml",
    "dump_model",
    "example_path",
    "example_names",
    "load_example",
    "resolve_model",
    "elementary_rotation",
]

_EXAMPLES = "examples"
_BODY_TYPES = ("planar", "rigid", "point")


class ModelFileError(ModelError):
    """A model file is invalid; the message names the file, the entry and the problem."""


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
        parameters (``"m1*l1**2/12"``); see :meth:`numeric_values`.
    units : dict of str to str
        SI units of the parameters (a file's units are parsed with ``pint`` and its values
        converted to SI base units: ``300`` in ``"mm"`` is stored as 0.3 in ``"m"``).
    q_guess, qd_guess : dict of str to sympy.Expr
        Assembly guesses by coordinate name (may use parameters); missing
        coordinates default to 0.
    fixed, qd_fixed : tuple of str
        Coordinates whose position / speed assembly keeps at the guess.
    simulation : SimulationSettings
    drives : dict of str to PrescribedMotion
        Prescribed motions by drive name (``target(q) = motion(t)``) for
        kinematic analysis and inverse dynamics; they become drives
        (:meth:`kronlag.System.add_drive`) in :func:`kronlag.workflows.driven_model`.
    source : str or None
        The file the model was read from.
    """

    system: System
    description: str = ""
    values: dict[str, sp.Expr] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    q_guess: dict[str, sp.Expr] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()
    qd_guess: dict[str, sp.Expr] = field(default_factory=dict)
    qd_fixed: tuple[str, ...] = ()
    simulation: SimulationSettings = field(default_factory=SimulationSettings)
    drives: dict[str, PrescribedMotion] = field(default_factory=dict)
    source: str | None = None

    def numeric_values(self) -> dict[str, float]:
        """Parameter values as floats, resolving values written in terms of other parameters.

        Raises
        ------
        ModelError
            A value depends on a parameter without a value, or values depend on
            each other in a cycle.
        """
        resolved: dict[str, float] = {}
        pending = {name: sp.sympify(value, strict=True) for name, value in self.values.items()}
        while pending:
            ready = [name for name, value in pending.items()
                     if {symbol.name for symbol in value.free_symbols} <= resolved.keys()]
            if not ready:
                missing = sorted({s.name for value in pending.values() for s in value.free_symbols}
                                 - pending.keys() - resolved.keys())
                if missing:
                    raise ModelError(f"parameter values use parameters without a value: {', '.join(missing)}")
                raise ModelError(f"parameter values depend on each other in a cycle: {', '.join(sorted(pending))}")
            for name in ready:
                resolved[name] = _to_float(pending.pop(name), resolved, f"value of parameter {name}")
        return resolved

    def guess_vectors(self) -> tuple[list[float], list[float]]:
        """The assembly guesses ``(q, qd)`` as lists in coordinate order (0 where not given)."""
        values = self.numeric_values()
        names = [q.name for q in self.system.coordinates]
        return ([_to_float(self.q_guess.get(name, 0), values, f"initial q of {name}") for name in names],
                [_to_float(self.qd_guess.get(name, 0), values, f"initial qd of {name}") for name in names])


def _to_float(expression, values: Mapping[str, float], what: str) -> float:
    expr = sp.sympify(expression, strict=True)
    unknown = sorted(s.name for s in expr.free_symbols if s.name not in values)
    if unknown:
        raise ModelError(f"{what} uses symbols without a value: {', '.join(unknown)}")
    number = expr.subs({s: values[s.name] for s in expr.free_symbols}).evalf()
    if not number.is_real or not math.isfinite(float(number)):
        raise ModelError(f"{what} is not a finite real number: {number}")
    return float(number)


def elementary_rotation(axis: str, angle) -> sp.Matrix:
    """The rotation matrix about the ``"x"``, ``"y"`` or ``"z"`` axis by ``angle``."""
    c, s = sp.cos(angle), sp.sin(angle)
    matrices = {
        "x": [[1, 0, 0], [0, c, -s], [0, s, c]],
        "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
        "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]],
    }
    if axis not in matrices:
        raise ModelError(f"rotation axis must be 'x', 'y' or 'z', got {axis!r}")
    return sp.Matrix(matrices[axis])


# -- reading ------------------------------------------------------------------------


class _Reader:
    """Reads one parsed TOML document, naming the file and the entry in every error."""

    def __init__(self, source: str):
        self.source = source
        self.symbols: dict[str, sp.Symbol] = {}
        self.points: dict[str, list[sp.Expr]] = {}
        # ``<point>_x``, ``<point>_y``, ``<point>_z`` in expressions: placeholders and their values
        self.point_symbols: dict[str, sp.Symbol] = {}
        self.point_values: dict[sp.Symbol, sp.Expr] = {}

    def add_point(self, name: str, position: list[sp.Expr], entry: str) -> None:
        """Register a named point, and its coordinates ``<name>_x, ...`` for expressions."""
        if name in self.points:
            raise self.error(entry, f"the point name {name!r} is used twice")
        components = {f"{name}_{axis}": value for axis, value in zip("xyz", position)}
        clash = [key for key in components if key in self.symbols]
        if clash:
            raise self.error(entry, f"the coordinate names {', '.join(clash)} of point {name!r} are already "
                                    "declared symbols; rename the point")
        self.points[name] = position
        for key, value in components.items():
            placeholder = sp.Dummy(key)
            self.point_symbols[key] = placeholder
            self.point_values[placeholder] = value

    def error(self, entry: str, problem: str) -> ModelFileError:
        return ModelFileError(f"{self.source}: {entry}: {problem}")

    @contextmanager
    def entry(self, entry: str) -> Iterator[None]:
        """Re-raise a :class:`ModelError` of the API (not already located) with file and entry."""
        try:
            yield
        except (ModelFileError, ExpressionError):
            raise
        except ModelError as error:
            raise self.error(entry, str(error)) from None

    def table(self, value, entry: str, *, required: Sequence[str] = (), optional: Sequence[str] = ()) -> dict:
        if not isinstance(value, dict):
            raise self.error(entry, f"expected a table, got {_kind(value)}")
        allowed = (*required, *optional)
        for key in value:
            if key not in allowed:
                raise self.error(f"{entry}.{key}" if entry else key,
                                 f"unknown field; expected one of {', '.join(allowed)}")
        for key in required:
            if key not in value:
                raise self.error(entry or "file", f"missing field {key!r}")
        return value

    def tables(self, document: dict, key: str, **fields) -> list[tuple[str, dict]]:
        """The entries of an array of tables ``[[key]]`` as ``(entry name, table)``."""
        items = document.get(key, [])
        if not isinstance(items, list):
            raise self.error(key, f"expected an array of tables ([[{key}]]), got {_kind(items)}")
        return [(f"{key}[{i}]", self.table(item, f"{key}[{i}]", **fields)) for i, item in enumerate(items)]

    def string(self, value, entry: str) -> str:
        if not isinstance(value, str):
            raise self.error(entry, f"expected a string, got {_kind(value)}")
        return value

    def name(self, value, entry: str) -> str:
        name = self.string(value, entry)
        if unicodedata.normalize("NFKC", name) != name:
            raise self.error(entry, f"{name!r} is not plain text: expressions would read it as "
                                    f"{unicodedata.normalize('NFKC', name)!r} (its NFKC form)")
        if not name.isidentifier() or keyword.iskeyword(name) or name in RESERVED_NAMES or name == "t":
            raise self.error(entry, f"{name!r} cannot be a symbol name: use letters, digits and '_' "
                                    "(not starting with a digit), and not a function name, pi, t or a keyword")
        return name

    def names(self, value, entry: str, *, known: Sequence[str]) -> tuple[str, ...]:
        if not isinstance(value, list):
            raise self.error(entry, f"expected a list of names, got {_kind(value)}")
        names = tuple(self.string(item, f"{entry}[{i}]") for i, item in enumerate(value))
        for i, name in enumerate(names):
            if name not in known:
                raise self.error(f"{entry}[{i}]", f"unknown coordinate {name!r}; coordinates are {', '.join(known)}")
        return names

    def number(self, value, entry: str, *, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.error(entry, f"expected a finite number, got {_kind(value)}")
        if positive and value <= 0:
            raise self.error(entry, f"expected a positive number, got {value}")
        return float(value)

    def expression(self, value, entry: str, symbols: Mapping[str, sp.Symbol] | None = None) -> sp.Expr:
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise self.error(entry, f"expected a number or an expression string, got {_kind(value)}")
        if isinstance(value, int):
            return sp.Integer(value)
        if isinstance(value, float):
            if not math.isfinite(value):
                raise self.error(entry, f"expected a finite number, got {value}")
            return sp.Float(value)
        if symbols is not None:
            return parse_expression(value, symbols, what=f"{self.source}: {entry}")
        expression = parse_expression(value, self.symbols | self.point_symbols, what=f"{self.source}: {entry}")
        return expression.xreplace(self.point_values)

    def vector(self, value, entry: str, lengths: Sequence[int]) -> list[sp.Expr]:
        expected = " or ".join(map(str, lengths))
        if not isinstance(value, list):
            raise self.error(entry, f"expected a list of {expected} expressions, got {_kind(value)}")
        if len(value) not in lengths:
            raise self.error(entry, f"expected {expected} entries, got {len(value)}")
        return [self.expression(item, f"{entry}[{i}]") for i, item in enumerate(value)]

    def matrix(self, value, entry: str, rows: int, cols: int) -> list[list[sp.Expr]]:
        if not isinstance(value, list) or len(value) != rows or not all(isinstance(row, list) for row in value):
            raise self.error(entry, f"expected a {rows}x{cols} matrix (a list of {rows} rows), got {_shape(value)}")
        return [self.vector(row, f"{entry}[{i}]", (cols,)) for i, row in enumerate(value)]

    def point(self, value, entry: str, lengths: Sequence[int] = (2, 3)) -> list[sp.Expr]:
        """A point: a list of expressions, or the name of an entry of ``[points]``."""
        if not isinstance(value, str):
            return self.vector(value, entry, lengths)
        if value not in self.points:
            known = ", ".join(self.points) or "none are defined"
            raise self.error(entry, f"unknown point {value!r} (named points: {known})")
        point = self.points[value]
        if len(point) not in lengths:
            raise self.error(entry, f"expected {' or '.join(map(str, lengths))} entries, "
                                    f"but point {value!r} has {len(point)}")
        return point


def _kind(value) -> str:
    """How an error message describes a TOML value."""
    if isinstance(value, dict | list):
        return "a table" if isinstance(value, dict) else "a list"
    names = {bool: "a boolean", str: "a string", int: "an integer", float: "a number"}
    return f"{names.get(type(value), type(value).__name__)} ({value!r})"


def _shape(value) -> str:
    if isinstance(value, list):
        lengths = [len(row) if isinstance(row, list) else "scalar" for row in value]
        return f"a list of {len(value)} entries ({lengths})"
    return _kind(value)


def _read(document: dict, source: str) -> ModelFile:
    reader = _Reader(source)
    reader.table(document, "", required=("coordinates",), optional=(
        "name", "description", "gravity", "parameters", "points", "bodies", "constraints",
        "nonholonomic_constraints", "springs", "dampers", "potentials", "forces", "torques",
        "generalized_forces", "initial", "simulation", "drives", "drawing", "traces", "joints"))
    name = reader.string(document.get("name", Path(source).stem), "name")
    description = reader.string(document.get("description", ""), "description")
    coordinate_list = document["coordinates"]
    if not isinstance(coordinate_list, list) or not coordinate_list:
        raise reader.error("coordinates", f"expected a non-empty list of names, got {_kind(coordinate_list)}")
    coordinates = [sp.Symbol(reader.name(item, f"coordinates[{i}]")) for i, item in enumerate(coordinate_list)]
    parameter_table = document.get("parameters", {})
    if not isinstance(parameter_table, dict):
        raise reader.error("parameters", f"expected a table, got {_kind(parameter_table)}")
    parameters = [sp.Symbol(reader.name(key, f"parameters.{key}")) for key in parameter_table]
    reader.symbols = {s.name: s for s in (*coordinates, *map(speed_symbol, coordinates), *parameters, t)}
    values, units = _read_parameters(reader, parameter_table, {s.name: s for s in parameters})
    gravity = reader.vector(document["gravity"], "gravity", (2, 3)) if "gravity" in document else None
    with reader.entry("coordinates, parameters, gravity"):
        system = System(coordinates, parameters=parameters, gravity=gravity, name=name)

    points = document.get("points", {})
    if not isinstance(points, dict):
        raise reader.error("points", f"expected a table of named points, got {_kind(points)}")
    for key, value in points.items():
        reader.add_point(key, reader.vector(value, f"points.{key}", (2, 3)), f"points.{key}")

    _read_items(reader, system, document)
    model = ModelFile(system=system, description=description, values=values, units=units, source=source)
    _read_settings(reader, document, model)
    with reader.entry("parameters"):
        model.numeric_values()
    with reader.entry("initial"):
        model.guess_vectors()
    return model


#: Longest accepted unit text, in characters.
MAX_UNIT_LENGTH = 100


@functools.cache
def _unit_registry() -> pint.UnitRegistry:
    return pint.UnitRegistry()


def _si_unit(reader: _Reader, text: str, entry: str) -> tuple[pint.Quantity, str]:
    """``(one unit in SI base units, the SI unit as text)`` for a unit written in a file."""
    if len(text) > MAX_UNIT_LENGTH:
        raise reader.error(entry, f"the unit is longer than {MAX_UNIT_LENGTH} characters")
    registry = _unit_registry()
    try:
        unit = registry.Unit(text)
        one = registry.Quantity(1, unit).to_base_units()
        zero = registry.Quantity(0, unit).to_base_units()
    except Exception as error:  # pint's parser fails in many ways on text that is not a unit
        raise reader.error(entry, f"unknown unit {text!r} ({type(error).__name__}: {error})") from None
    if zero.magnitude != 0:
        raise reader.error(entry, f"the unit {text!r} has an offset (like degC); give the value in kelvin")
    return one, f"{one.units:~}"


def _read_parameters(reader: _Reader, table: dict, symbols: dict[str, sp.Symbol]
                     ) -> tuple[dict[str, sp.Expr], dict[str, str]]:
    """Values converted to SI base units (``300`` with unit ``"mm"`` is 0.3, unit ``"m"``;
    ``90 deg`` is pi/2 rad); the units returned are the SI ones, so that writing the file
    back and reading it again gives the same numbers."""
    values: dict[str, sp.Expr] = {}
    units: dict[str, str] = {}
    for key, item in table.items():
        entry = f"parameters.{key}"
        factor = None
        if isinstance(item, dict):
            reader.table(item, entry, optional=("value", "unit", "description"))
            if "unit" in item:
                one, units[key] = _si_unit(reader, reader.string(item["unit"], f"{entry}.unit"), f"{entry}.unit")
                factor = one.magnitude
            if "description" in item:
                reader.string(item["description"], f"{entry}.description")
            if "value" not in item:
                continue
            entry, item = f"{entry}.value", item["value"]
        value = reader.expression(item, entry, symbols)
        if key in {s.name for s in value.free_symbols}:
            raise reader.error(entry, "the value refers to the parameter itself")
        if factor is not None and factor != 1:
            if value.free_symbols:
                raise reader.error(entry, f"a value computed from other parameters uses their SI values, so its "
                                          f"unit must be the SI unit {units[key]!r}")
            value = value * sp.Float(factor)
        values[key] = value
    return values, units


def _body(reader: _Reader, entry: str, table: dict) -> PlanarBody | RigidBody | PointMass:
    kind = reader.string(table.get("type", ""), f"{entry}.type")
    if kind not in _BODY_TYPES:
        raise reader.error(f"{entry}.type", f"expected one of {', '.join(_BODY_TYPES)}, got {kind!r}")
    fields = {"planar": ("inertia", "angle"), "rigid": ("inertia", "rotation"), "point": ()}[kind]
    reader.table(table, entry, required=("name", "type", "mass", "position", *fields),
                 optional=("points", "simplify") if kind == "rigid" else ("points",))
    name = reader.string(table["name"], f"{entry}.name")
    mass = reader.expression(table["mass"], f"{entry}.mass")
    with reader.entry(entry):
        if kind == "planar":
            return PlanarBody(name, mass=mass, inertia=reader.expression(table["inertia"], f"{entry}.inertia"),
                              position=reader.point(table["position"], f"{entry}.position", (2,)),
                              angle=reader.expression(table["angle"], f"{entry}.angle"))
        if kind == "point":
            return PointMass(name, mass=mass, position=reader.point(table["position"], f"{entry}.position"))
        simplify = table.get("simplify", True)
        if not isinstance(simplify, bool):
            raise reader.error(f"{entry}.simplify", f"expected true or false, got {_kind(simplify)}")
        return RigidBody(name, mass=mass, inertia=_inertia_tensor(reader, table["inertia"], f"{entry}.inertia"),
                         position=reader.point(table["position"], f"{entry}.position", (3,)),
                         rotation=_rotation(reader, table["rotation"], f"{entry}.rotation"), simplify=simplify)


def _inertia_tensor(reader: _Reader, value, entry: str) -> sp.Matrix:
    """A 3x3 tensor, or 3 principal moments on the diagonal."""
    if isinstance(value, list) and len(value) == 3 and not any(isinstance(row, list) for row in value):
        return sp.diag(*reader.vector(value, entry, (3,)))
    return sp.Matrix(reader.matrix(value, entry, 3, 3))


def _rotation(reader: _Reader, value, entry: str) -> sp.Matrix | RotationSequence:
    """A 3x3 matrix, or ``{axes = "zxz", angles = [...]}``: ``R = R_a1(angle1) R_a2(angle2) ...``
    (a :class:`~kronlag.system.RotationSequence`, at most ``MAX_ROTATION_FACTORS`` axes)."""
    if not isinstance(value, dict):
        return sp.Matrix(reader.matrix(value, entry, 3, 3))
    reader.table(value, entry, required=("axes", "angles"))
    axes = reader.string(value["axes"], f"{entry}.axes")
    if not axes or any(axis not in "xyz" for axis in axes):
        raise reader.error(f"{entry}.axes", f"expected a sequence of the letters x, y, z, got {axes!r}")
    if len(axes) > MAX_ROTATION_FACTORS:
        raise reader.error(f"{entry}.axes", f"{len(axes)} elementary rotations; at most {MAX_ROTATION_FACTORS} "
                                            "are allowed")
    angles = reader.vector(value["angles"], f"{entry}.angles", (len(axes),))
    with reader.entry(entry):
        return RotationSequence(list(zip(axes, angles)))


def _read_items(reader: _Reader, system: System, document: dict) -> None:
    """Bodies, constraints, force elements and drawing, in file order within each kind."""
    for entry, table in reader.tables(document, "bodies", required=("name", "type", "mass", "position"),
                                      optional=("inertia", "angle", "rotation", "simplify", "points")):
        body = _body(reader, entry, table)
        with reader.entry(entry):
            system.add_body(body)
        _read_body_points(reader, system, table.get("points", {}), body.name, f"{entry}.points")
    _read_joints(reader, system, document)
    scalar_items: list[tuple[str, Callable]] = [
        ("constraints", system.add_constraint),
        ("nonholonomic_constraints", system.add_nonholonomic_constraint),
        ("potentials", system.add_potential),
    ]
    for key, add in scalar_items:
        for entry, table in reader.tables(document, key, required=("expression",), optional=("name",)):
            expression = reader.expression(table["expression"], f"{entry}.expression")
            with reader.entry(entry):
                add(expression, name=_optional_name(reader, table, entry))
    for entry, table in reader.tables(document, "springs", required=("point_a", "point_b", "stiffness"),
                                      optional=("name", "free_length")):
        with reader.entry(entry):
            system.add_spring(reader.point(table["point_a"], f"{entry}.point_a"),
                              reader.point(table["point_b"], f"{entry}.point_b"),
                              stiffness=reader.expression(table["stiffness"], f"{entry}.stiffness"),
                              free_length=reader.expression(table.get("free_length", 0), f"{entry}.free_length"),
                              name=_optional_name(reader, table, entry))
    for entry, table in reader.tables(document, "dampers", required=("point_a", "point_b", "coefficient"),
                                      optional=("name",)):
        with reader.entry(entry):
            system.add_damper(reader.point(table["point_a"], f"{entry}.point_a"),
                              reader.point(table["point_b"], f"{entry}.point_b"),
                              coefficient=reader.expression(table["coefficient"], f"{entry}.coefficient"),
                              name=_optional_name(reader, table, entry))
    for entry, table in reader.tables(document, "forces", required=("point", "force"), optional=("name",)):
        point = reader.point(table["point"], f"{entry}.point")
        with reader.entry(entry):
            system.add_force(point, reader.vector(table["force"], f"{entry}.force", (len(point),)),
                             name=_optional_name(reader, table, entry))
    for entry, table in reader.tables(document, "torques", required=("body", "torque"), optional=("name", "frame")):
        value = table["torque"]
        torque = (reader.vector(value, f"{entry}.torque", (3,)) if isinstance(value, list)
                  else reader.expression(value, f"{entry}.torque"))
        with reader.entry(entry):
            system.add_torque(reader.string(table["body"], f"{entry}.body"), torque,
                              frame=reader.string(table.get("frame", "world"), f"{entry}.frame"),
                              name=_optional_name(reader, table, entry))
    m = len(system.coordinates)
    for entry, table in reader.tables(document, "generalized_forces", required=("force",), optional=("name",)):
        force = reader.vector(table["force"], f"{entry}.force", (m,))
        with reader.entry(entry):
            system.add_generalized_force(force, name=_optional_name(reader, table, entry))
    for entry, table in reader.tables(document, "drawing", required=("points",), optional=("name",)):
        points = table["points"]
        if not isinstance(points, list):
            raise reader.error(f"{entry}.points", f"expected a list of points, got {_kind(points)}")
        vertices = [reader.point(point, f"{entry}.points[{i}]") for i, point in enumerate(points)]
        with reader.entry(entry):
            system.add_drawing_line(vertices, name=_optional_name(reader, table, entry))
    for entry, table in reader.tables(document, "traces", required=("point",), optional=("name",)):
        point = reader.point(table["point"], f"{entry}.point")
        with reader.entry(entry):
            system.add_trace(point, name=_optional_name(reader, table, entry))


def _read_body_points(reader: _Reader, system: System, table, body: str, entry: str) -> None:
    """``points = {name = [body coordinates], ...}`` of a body: system points, and named points of the file."""
    if not isinstance(table, dict):
        raise reader.error(entry, f"expected a table of named points, got {_kind(table)}")
    for key, value in table.items():
        if key in reader.points:
            raise reader.error(f"{entry}.{key}", f"the point name {key!r} is used twice")
        local = reader.vector(value, f"{entry}.{key}", (system.dimension,))
        with reader.entry(f"{entry}.{key}"):
            point = system.add_point(key, body, local)
        reader.add_point(key, list(point.position), f"{entry}.{key}")


def _read_joints(reader: _Reader, system: System, document: dict) -> None:
    dimension = system.dimension
    for entry, table in reader.tables(document, "joints", required=("type", "body_a", "body_b"),
                                      optional=("name", "at_a", "at_b", "axis", "axis_b", "angle", "rotation")):
        options: dict[str, Any] = {}
        for key in ("at_a", "at_b"):
            if key in table:
                value = table[key]
                options[key] = value if isinstance(value, str) else reader.vector(value, f"{entry}.{key}",
                                                                                  (dimension,))
        for key in ("axis", "axis_b"):
            if key in table:
                options[key] = reader.vector(table[key], f"{entry}.{key}", (dimension,))
        if "angle" in table:
            options["angle"] = reader.expression(table["angle"], f"{entry}.angle")
        if "rotation" in table:
            options["rotation"] = _rotation(reader, table["rotation"], f"{entry}.rotation")
        with reader.entry(entry):
            system.add_joint(reader.string(table["type"], f"{entry}.type"),
                             reader.string(table["body_a"], f"{entry}.body_a"),
                             reader.string(table["body_b"], f"{entry}.body_b"),
                             name=_optional_name(reader, table, entry), **options)


def _optional_name(reader: _Reader, table: dict, entry: str) -> str | None:
    return reader.string(table["name"], f"{entry}.name") if "name" in table else None


def _read_settings(reader: _Reader, document: dict, model: ModelFile) -> None:
    """``[initial]``, ``[simulation]`` and ``[[drives]]``."""
    names = [q.name for q in model.system.coordinates]
    parameter_symbols = {s.name: s for s in model.system.parameters}
    initial = reader.table(document.get("initial", {}), "initial", optional=("q", "fixed", "qd", "qd_fixed"))
    for key, target in (("q", model.q_guess), ("qd", model.qd_guess)):
        guesses = reader.table(initial.get(key, {}), f"initial.{key}", optional=names)
        target.update({name: reader.expression(value, f"initial.{key}.{name}", parameter_symbols)
                       for name, value in guesses.items()})
    model.fixed = reader.names(initial.get("fixed", []), "initial.fixed", known=names)
    model.qd_fixed = reader.names(initial.get("qd_fixed", []), "initial.qd_fixed", known=names)

    settings = reader.table(document.get("simulation", {}), "simulation",
                            optional=("t_end", "method", "rtol", "atol"))
    defaults = SimulationSettings()
    model.simulation = SimulationSettings(
        t_end=reader.number(settings.get("t_end", defaults.t_end), "simulation.t_end", positive=True),
        method=reader.string(settings.get("method", defaults.method), "simulation.method"),
        rtol=reader.number(settings.get("rtol", defaults.rtol), "simulation.rtol", positive=True),
        atol=reader.number(settings.get("atol", defaults.atol), "simulation.atol", positive=True))

    drive_symbols = {**parameter_symbols, "t": t}
    for entry, table in reader.tables(document, "drives", required=("motion",),
                                      optional=("coordinate", "target", "name")):
        if ("coordinate" in table) == ("target" in table):
            raise reader.error(entry, "give either coordinate (a coordinate name) or target (an expression of "
                                      "the coordinates, e.g. a point's end_effector_x), not both or neither")
        if "coordinate" in table:
            coordinate = reader.string(table["coordinate"], f"{entry}.coordinate")
            if coordinate not in names:
                raise reader.error(f"{entry}.coordinate", f"unknown coordinate {coordinate!r}; "
                                                          f"coordinates are {', '.join(names)}")
            target = reader.symbols[coordinate]
        else:
            target = reader.expression(table["target"], f"{entry}.target")
            if not target.free_symbols & set(model.system.coordinates) or t in target.free_symbols:
                raise reader.error(f"{entry}.target", "must be an expression of the coordinates (not of t: "
                                                      "the motion gives the time dependence)")
        name = (reader.string(table["name"], f"{entry}.name") if "name" in table else drive_name(target))
        if name in model.drives:
            raise reader.error(entry, f"the drive {name!r} is given twice")
        model.drives[name] = PrescribedMotion(target, reader.expression(table["motion"], f"{entry}.motion",
                                                                        drive_symbols))


def loads_model(text: str, *, source: str = "<string>") -> ModelFile:
    """Read a model from TOML text; ``source`` names it in error messages."""
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ModelFileError(f"{source}: not valid TOML: {error}") from None
    return _read(document, source)


def load_model(path: str | Path) -> ModelFile:
    """Read a model file (TOML; the format is described in the module docstring).

    Raises
    ------
    ModelError
        The file cannot be read or is invalid; the message names the file, the
        entry and the problem.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ModelFileError(f"{path}: cannot read the file: {error}") from None
    return loads_model(text, source=str(path))


# -- built-in models and example files --------------------------------------------


def example_names() -> list[str]:
    """Names of the example model files shipped with kronlag."""
    folder = resources.files("kronlag") / _EXAMPLES
    return sorted(item.name.removesuffix(".toml") for item in folder.iterdir() if item.name.endswith(".toml"))


def example_path(name: str) -> Path:
    """The path of the shipped example file ``name`` (``"four_bar"`` -> ``.../examples/four_bar.toml``)."""
    if name not in example_names():
        raise ModelError(f"no example model named {name!r}; examples are {', '.join(example_names())}")
    return Path(str(resources.files("kronlag") / _EXAMPLES / f"{name}.toml"))


def load_example(name: str) -> ModelFile:
    """A shipped example; for a built-in model (``kronlag.models.BUILTIN_MODELS``) its system
    is the Python model's and the file supplies the numbers."""
    from .models import BUILTIN_MODELS

    model = load_model(example_path(name))
    if name in BUILTIN_MODELS:
        model.system = BUILTIN_MODELS[name]()
    return model


def resolve_model(model: str | Path) -> ModelFile:
    """A model given as a path to a TOML file or as the name of a built-in model or example."""
    path = Path(model)
    if path.suffix == ".toml" or path.exists():
        return load_model(path)
    return load_example(str(model))


# -- writing ----------------------------------------------------------------------


class _FilePrinter(StrPrinter):
    """Prints expressions in the model-file syntax."""

    def _print_Abs(self, expr) -> str:
        return f"abs({self._print(expr.args[0])})"

    def _print_Exp1(self, expr) -> str:
        return "exp(1)"

    def _print_Float(self, expr) -> str:
        return repr(float(expr))


class _Writer:
    def __init__(self, system: System):
        self.printer = _FilePrinter()
        self.symbols = {s.name: s for s in (*system.coordinates, *system.speeds, *system.parameters, t)}

    def expression(self, value) -> int | float | str:
        expr = sp.sympify(value)
        if expr.is_Integer:
            return int(expr)
        if expr.is_Float:
            return float(expr)
        text = self.printer.doprint(expr)
        try:
            parsed = parse_expression(text, self.symbols)
        except ExpressionError:
            parsed = None
        # Reading may regroup a rational factor over a sum: the same expression, other tree.
        readable = parsed is not None and (parsed == expr or sp.expand(parsed - expr) == 0)
        if not readable:
            raise ModelError(f"cannot write the expression {expr} in the model-file syntax")
        return text

    def vector(self, matrix) -> list:
        return [self.expression(entry) for entry in matrix]

    def matrix(self, matrix: sp.MatrixBase) -> list:
        return [self.vector(matrix.row(i)) for i in range(matrix.rows)]


def _document(model: ModelFile) -> dict[str, Any]:
    """The TOML document of a model as nested dicts and lists."""
    system = model.system
    writer = _Writer(system)
    document: dict[str, Any] = {"name": system.name}
    if model.description:
        document["description"] = model.description
    document["coordinates"] = [q.name for q in system.coordinates]
    if system.gravity is not None:
        document["gravity"] = writer.vector(system.gravity)
    parameters = {}
    for symbol in system.parameters:
        entry = {}
        if symbol.name in model.values:
            entry["value"] = writer.expression(model.values[symbol.name])
        if symbol.name in model.units:
            entry["unit"] = model.units[symbol.name]
        parameters[symbol.name] = entry
    document["parameters"] = parameters
    points = {body: {name: writer.vector(point.local) for name, point in system.points.items() if point.body == body}
              for body in ("ground", *(body.name for body in system.bodies))}
    if points["ground"]:
        document["points"] = points["ground"]
    document["bodies"] = [_body_document(writer, body) for body in system.bodies]
    for entry in document["bodies"]:
        if points[entry["name"]]:
            entry["points"] = points[entry["name"]]
    document["joints"] = [{"name": joint.name, "type": joint.kind, "body_a": joint.body_a, "body_b": joint.body_b,
                           **{key: writer.expression(value) if key == "angle" else
                              writer.matrix(value) if key == "rotation" else writer.vector(value)
                              for key, value in joint.geometry}} for joint in system.joints]
    joint_rows = {row for joint in system.joints for row in joint.constraint_names}
    for key, items in (("constraints", [c for c in system.constraints if c.name not in joint_rows]),
                       ("nonholonomic_constraints", system.nonholonomic_constraints),
                       ("potentials", system.potentials)):
        document[key] = [{"name": item.name, "expression": writer.expression(item.expression)} for item in items]
    document["springs"] = [{"name": s.name, "point_a": writer.vector(s.point_a), "point_b": writer.vector(s.point_b),
                            "stiffness": writer.expression(s.stiffness),
                            "free_length": writer.expression(s.free_length)} for s in system.springs]
    document["dampers"] = [{"name": d.name, "point_a": writer.vector(d.point_a), "point_b": writer.vector(d.point_b),
                            "coefficient": writer.expression(d.coefficient)} for d in system.dampers]
    kinds = {"point": "forces", "body torque": "torques", "generalized": "generalized_forces"}
    for key in kinds.values():
        document[key] = []
    for force in system.forces:
        entry: dict[str, Any] = {"name": force.name}
        if force.kind == "point":
            entry.update(point=writer.vector(force.where), force=writer.vector(force.value))
        elif force.kind == "generalized":
            entry["force"] = writer.vector(force.value)
        else:
            torque = writer.vector(force.value)
            entry.update(body=force.where, torque=torque[0] if len(torque) == 1 else torque)
            if force.frame != "world":
                entry["frame"] = force.frame
        document[kinds[force.kind]].append(entry)
    document["initial"] = {"q": {k: writer.expression(v) for k, v in model.q_guess.items()},
                           "fixed": list(model.fixed),
                           "qd": {k: writer.expression(v) for k, v in model.qd_guess.items()},
                           "qd_fixed": list(model.qd_fixed)}
    settings = model.simulation
    document["simulation"] = {"t_end": settings.t_end, "method": settings.method,
                              "rtol": settings.rtol, "atol": settings.atol}
    document["drives"] = [
        {"name": name, **({"coordinate": drive.target.name} if drive.target in system.coordinates
                          else {"target": writer.expression(drive.target)}),
         "motion": writer.expression(drive.motion)}
        for name, drive in model.drives.items()]
    document["drawing"] = [{"name": line.name, "points": [writer.vector(p) for p in line.points]}
                           for line in system.drawing]
    document["traces"] = [{"name": trace.name, "point": writer.vector(trace.points[0])} for trace in system.traces]
    return document


def _body_document(writer: _Writer, body: PlanarBody | RigidBody | PointMass) -> dict[str, Any]:
    kind = {PlanarBody: "planar", RigidBody: "rigid", PointMass: "point"}[type(body)]
    entry: dict[str, Any] = {"name": body.name, "type": kind, "mass": writer.expression(body.mass)}
    if isinstance(body, PlanarBody):
        entry["inertia"] = writer.expression(body.inertia)
    elif isinstance(body, RigidBody):
        entry["inertia"] = writer.matrix(body.inertia)
    entry["position"] = writer.vector(body.position)
    if isinstance(body, PlanarBody):
        entry["angle"] = writer.expression(body.angle)
    elif isinstance(body, RigidBody):
        entry.update(rotation=_rotation_document(writer, body), simplify=body.simplify)
    return entry


def _rotation_document(writer: _Writer, body: RigidBody) -> list | dict[str, Any]:
    """``{axes, angles}`` for a sequence of rotations about x, y, z; else the matrix."""
    sequence = body.rotation_sequence
    names = {(1, 0, 0): "x", (0, 1, 0): "y", (0, 0, 1): "z"}
    if sequence is not None and all(tuple(axis) in names for axis, _ in sequence.factors):
        return {"axes": "".join(names[tuple(axis)] for axis, _ in sequence.factors),
                "angles": [writer.expression(angle) for _, angle in sequence.factors]}
    return writer.matrix(body.rotation)


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key, ensure_ascii=False)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _is_table_array(value) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(item, dict) for item in value)


def _emit(document: dict[str, Any]) -> str:
    """TOML text: top-level values first, then ``[tables]`` and ``[[arrays of tables]]`` in
    document order; empty lists are left out."""
    lines = [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in document.items()
             if not isinstance(v, dict) and not _is_table_array(v) and v != []]
    for key, value in document.items():
        if isinstance(value, dict):
            lines += ["", f"[{_toml_key(key)}]"]
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items() if v != []]
        elif _is_table_array(value):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def to_toml(model: ModelFile | System) -> str:
    """The model-file text of a model (a bare :class:`System` is written without numbers).

    Raises
    ------
    ModelError
        An expression uses a function the file syntax does not have.
    """
    if isinstance(model, System):
        model = ModelFile(system=model)
    return _emit(_document(model))


def dump_model(model: ModelFile | System, path: str | Path) -> None:
    """Write :func:`to_toml` of ``model`` to ``path``."""
    Path(path).write_text(to_toml(model), encoding="utf-8")
