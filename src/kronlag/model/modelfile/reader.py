"""Reading model files: TOML parsed into a :class:`~kronlag.model.modelfile.model_file.ModelFile`,
every error located as ``FILE: ENTRY: problem`` (entries indexed from 0)."""

from __future__ import annotations

import keyword
import math
import tomllib
import unicodedata
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import sympy as sp

from ...core.errors import ExpressionError, InputError, ModelError, ModelFileError
from ..bodies import BODY_TYPES, Body
from ..expressions import RESERVED_NAMES, parse_expression
from ..friction import FRICTION_FIELDS, Friction
from ..robot_formats import ROBOT_READERS, load_robot
from ..symbols import speed_symbol, t
from ..system import System, drive_name
from .bounds import check_document, check_text, read_bounded
from .controller import read_controller
from .dimension_check import check_file_dimensions
from .formats import FIELD_KINDS, LOAD_FORMATS, read_rotation
from .model_file import ModelFile, PrescribedMotion, SimulationSettings, settle_drives
from .units import si_unit

__all__ = ["loads_model", "load_model"]


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

    def flag(self, value, entry: str) -> bool:
        """A TOML boolean."""
        if not isinstance(value, bool):
            raise self.error(entry, f"expected true or false, got {_kind(value)}")
        return value

    def optional_name(self, table: dict, entry: str) -> str | None:
        """The entry's ``name``, ``None`` where it has none."""
        return self.string(table["name"], f"{entry}.name") if "name" in table else None

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

    def unit(self, table: dict, entry: str) -> tuple[float, str]:
        """``(SI factor, SI unit)`` of the unit ``table["unit"]`` (``entry`` the table's), errors at ``ENTRY.unit``."""
        try:
            one, unit = si_unit(self.string(table["unit"], f"{entry}.unit"))
        except ValueError as error:
            raise self.error(f"{entry}.unit", str(error)) from None
        return float(one.magnitude), unit

    def in_si(self, value: sp.Expr, factor: float, unit: str, entry: str) -> sp.Expr:
        """``value`` (read at ``entry``) written in a unit of SI factor ``factor``, in SI; an expression of the
        parameters is in SI already (they are), so its unit must be the SI one."""
        if factor == 1:
            return value
        if value.free_symbols:
            raise self.error(entry, f"a value computed from other parameters uses their SI values, so its unit "
                                    f"must be the SI unit {unit!r}")
        return value * sp.Float(factor)

    def quantity(self, value, entry: str) -> sp.Expr:
        """A number or an expression of the parameters (in SI), or ``{value = ..., unit = "..."}`` converted
        to SI (the unit's dimension is checked with the file's, :mod:`.dimension_check`)."""
        if not isinstance(value, dict):
            return self.expression(value, entry)
        self.table(value, entry, required=("value", "unit"))
        factor, unit = self.unit(value, entry)
        return self.in_si(self.expression(value["value"], f"{entry}.value"), factor, unit, f"{entry}.value")

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
        "nonholonomic_constraints", *LOAD_FORMATS, "initial", "simulation", "drives", "drawing", "traces",
        "joints", "limits", "controller"))
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
    values, units, file_units = _read_parameters(reader, parameter_table, {s.name: s for s in parameters})
    gravity = reader.vector(document["gravity"], "gravity", (2, 3)) if "gravity" in document else None
    with reader.entry("coordinates, parameters, gravity"):
        system = System(coordinates, parameters=parameters, gravity=gravity, name=name)

    points = document.get("points", {})
    if not isinstance(points, dict):
        raise reader.error("points", f"expected a table of named points, got {_kind(points)}")
    for key, value in points.items():
        reader.add_point(key, reader.vector(value, f"points.{key}", (2, 3)), f"points.{key}")

    _read_items(reader, system, document)
    model = ModelFile(system=system, description=description, values=values, units=units, file_units=file_units,
                      source=source)
    _read_settings(reader, document, model)
    model.controller = read_controller(reader, document, model)
    with reader.entry("parameters"):
        numbers = model.numeric_values()
    check_file_dimensions(document, model)
    with reader.entry("initial"):
        model.guess_vectors(values=numbers)
    return model



def _read_parameters(reader: _Reader, table: dict, symbols: dict[str, sp.Symbol]
                     ) -> tuple[dict[str, sp.Expr], dict[str, str], dict[str, str]]:
    """Values converted to SI base units (``300`` with unit ``"mm"`` is 0.3, unit ``"m"``;
    ``90 deg`` is pi/2 rad); the units returned are the SI ones, so that writing the file
    back and reading it again gives the same numbers, and the units as written."""
    values: dict[str, sp.Expr] = {}
    units: dict[str, str] = {}
    file_units: dict[str, str] = {}
    for key, item in table.items():
        entry = f"parameters.{key}"
        factor = None
        if isinstance(item, dict):
            reader.table(item, entry, optional=("value", "unit", "description"))
            if "unit" in item:
                factor, units[key] = reader.unit(item, entry)
                file_units[key] = item["unit"]
            if "description" in item:
                reader.string(item["description"], f"{entry}.description")
            if "value" not in item:
                continue
            entry, item = f"{entry}.value", item["value"]
        value = reader.expression(item, entry, symbols)
        if key in {s.name for s in value.free_symbols}:
            raise reader.error(entry, "the value refers to the parameter itself")
        values[key] = value if factor is None else reader.in_si(value, factor, units[key], entry)
    return values, units, file_units


def _body(reader: _Reader, entry: str, table: dict) -> Body:
    """A body of the type ``type`` names (:data:`~kronlag.model.bodies.BODY_TYPES`), its fields read by kind."""
    kind = reader.string(table.get("type", ""), f"{entry}.type")
    if kind not in BODY_TYPES:
        raise reader.error(f"{entry}.type", f"expected one of {', '.join(BODY_TYPES)}, got {kind!r}")
    body_type = BODY_TYPES[kind]
    reader.table(table, entry, required=("name", "type", *(field.name for field in body_type.fields if field.required)),
                 optional=("points", *(field.name for field in body_type.fields if not field.required)))
    name = reader.string(table["name"], f"{entry}.name")
    arguments = {field.name: FIELD_KINDS[field.kind].read(reader, table[field.name], f"{entry}.{field.name}", body_type)
                 for field in body_type.fields if field.name in table}
    with reader.entry(entry):
        return body_type(name, **arguments)


def _read_items(reader: _Reader, system: System, document: dict) -> None:
    """Bodies, constraints, force elements and drawing, in file order within each kind."""
    fields = dict.fromkeys(field.name for body_type in BODY_TYPES.values() for field in body_type.fields)
    for entry, table in reader.tables(document, "bodies", required=("name", "type"), optional=(*fields, "points")):
        body = _body(reader, entry, table)
        with reader.entry(entry):
            system.add_body(body)
        _read_body_points(reader, system, table.get("points", {}), body.name, f"{entry}.points")
    _read_joints(reader, system, document)
    constraints: list[tuple[str, Callable]] = [
        ("constraints", system.add_constraint),
        ("nonholonomic_constraints", system.add_nonholonomic_constraint),
    ]
    for key, add in constraints:
        for entry, table in reader.tables(document, key, required=("expression",), optional=("name",)):
            expression = reader.expression(table["expression"], f"{entry}.expression")
            with reader.entry(entry):
                add(expression, name=reader.optional_name(table, entry))
    for key, form in LOAD_FORMATS.items():
        for entry, table in reader.tables(document, key, required=form.required, optional=("name", *form.optional)):
            with reader.entry(entry):
                form.read(reader, system, entry, table, reader.optional_name(table, entry))
    _read_limits(reader, system, document)
    for entry, table in reader.tables(document, "drawing", required=("points",), optional=("name",)):
        points = table["points"]
        if not isinstance(points, list):
            raise reader.error(f"{entry}.points", f"expected a list of points, got {_kind(points)}")
        vertices = [reader.point(point, f"{entry}.points[{i}]") for i, point in enumerate(points)]
        with reader.entry(entry):
            system.add_drawing_line(vertices, name=reader.optional_name(table, entry))
    for entry, table in reader.tables(document, "traces", required=("point",), optional=("name",)):
        point = reader.point(table["point"], f"{entry}.point")
        with reader.entry(entry):
            system.add_trace(point, name=reader.optional_name(table, entry))


def _read_limits(reader: _Reader, system: System, document: dict) -> None:
    """``[[limits]]``: ``expression`` of q bounded by ``lower`` and/or ``upper`` (expressions or ``{value, unit}``
    tables), with ``restitution``."""
    for entry, table in reader.tables(document, "limits", required=("expression",),
                                      optional=("name", "lower", "upper", "restitution")):
        bounds = {key: reader.quantity(table[key], f"{entry}.{key}") for key in ("lower", "upper") if key in table}
        if "restitution" in table:
            bounds["restitution"] = reader.expression(table["restitution"], f"{entry}.restitution")
        if "lower" not in bounds and "upper" not in bounds:
            raise reader.error(entry, "give lower, upper or both")
        expression = reader.expression(table["expression"], f"{entry}.expression")
        with reader.entry(entry):
            system.add_limit(expression, name=reader.optional_name(table, entry), **bounds)


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
                                      optional=("name", "at_a", "at_b", "axis", "axis_b", "angle", "rotation",
                                                "friction")):
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
            options["rotation"] = read_rotation(reader, table["rotation"], f"{entry}.rotation")
        if "friction" in table:
            options["friction"] = _read_friction(reader, table["friction"], f"{entry}.friction")
        with reader.entry(entry):
            system.add_joint(reader.string(table["type"], f"{entry}.type"),
                             reader.string(table["body_a"], f"{entry}.body_a"),
                             reader.string(table["body_b"], f"{entry}.body_b"),
                             name=reader.optional_name(table, entry), **options)


def _read_friction(reader: _Reader, value, entry: str) -> Friction:
    """A joint's ``friction = {kinetic = ..., ...}``: the fields of :class:`Friction`, expressions of the
    parameters or ``{value, unit}`` tables (``law`` a string)."""
    quantities = [field for field in FRICTION_FIELDS if field not in ("kinetic", "law")]
    table = reader.table(value, entry, required=("kinetic",), optional=(*quantities, "law"))
    options: dict[str, Any] = {key: reader.quantity(item, f"{entry}.{key}") for key, item in table.items()
                               if key != "law"}
    if "law" in table:
        options["law"] = reader.string(table["law"], f"{entry}.law")
    with reader.entry(entry):
        return Friction(**options)


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
    """Read a model from TOML text; ``source`` names it in error messages.  The text's size, nesting
    and numbers of entries are limited (:mod:`kronlag.core.limits`)."""
    check_text(text, source)
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ModelFileError(f"{source}: not valid TOML: {error}") from None
    check_document(document, source)
    return _read(document, source)


def load_model(path: str | Path, *, apply_drives: bool | None = None, coordinates: str = "joint",
               floating_base: bool = False) -> ModelFile:
    """Read a model file (TOML; the format is described in the module docstring) or a robot file
    (``.urdf``, ``.xml`` MJCF, ``.sdf``: :func:`~kronlag.model.robot_formats.load_robot`, with its
    options ``coordinates="absolute"`` and, for a URDF, ``floating_base=True``).

    A file's ``[[drives]]`` prescribe motions for kinematic analysis and inverse dynamics;
    they are kept in :attr:`ModelFile.drives`, out of the system, unless ``apply_drives``
    (then the system has them: :meth:`ModelFile.driven`).  With ``apply_drives=None`` (the
    default) a file with drives gives a :class:`~kronlag.DrivesNotAppliedWarning` that says so;
    ``False`` is the same model without the warning.

    Raises
    ------
    ModelError
        The file cannot be read or is invalid; the message names the file, the
        entry and the problem.
    """
    path = Path(path)
    if path.suffix.lower() in ROBOT_SUFFIXES:
        return _robot_model(path, coordinates=coordinates, floating_base=floating_base)
    if coordinates != "joint" or floating_base:
        raise InputError(f"{path}: coordinates= and floating_base= apply to robot files "
                         f"({', '.join(ROBOT_SUFFIXES)}), not to a model file")
    return settle_drives(loads_model(read_bounded(path), source=str(path)), apply_drives)


#: Suffixes :func:`load_model` reads as robot description files (:mod:`kronlag.model.robot_formats`).
ROBOT_SUFFIXES = tuple(ROBOT_READERS)


def _robot_model(path: Path, *, coordinates: str, floating_base: bool) -> ModelFile:
    """A robot file (URDF, MJCF, SDF) as a model file: its system, ``g`` (9.81 or the file's), actuator
    torques 0, the reference pose as the assembly guess."""
    system = load_robot(path, coordinates=coordinates, floating_base=floating_base)
    robot = system.robot
    return ModelFile(system, description=f"{robot.format.upper()} robot {system.name!r} ({path.name})",
                     values={name: sp.Float(value) for name, value in robot.values.items()},
                     q_guess={name: sp.Float(value) for name, value in robot.q_reference.items()}, source=str(path))
