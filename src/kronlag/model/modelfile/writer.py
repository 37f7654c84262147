"""Writing model files: a :class:`~kronlag.model.modelfile.model_file.ModelFile` (or a bare
:class:`~kronlag.model.system.System`) as TOML text that reads back to the same model."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import sympy as sp
from sympy.printing.str import StrPrinter

from ...core.errors import ExpressionError, ModelError
from ..bodies import BODY_TYPES, Body
from ..expressions import parse_expression
from ..symbols import t
from ..system import System
from .controller import write_controller
from .formats import FIELD_KINDS, LOAD_FORMATS
from .model_file import ModelFile

__all__ = ["to_toml", "dump_model"]


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
                              for key, value in joint.geometry},
                           **({"friction": {key: value if key == "law" else writer.expression(value)
                                            for key, value in joint.friction.as_table().items()}}
                              if joint.friction is not None else {})} for joint in system.joints]
    joint_rows = {row for joint in system.joints for row in joint.constraint_names}
    for key, items in (("constraints", [c for c in system.constraints if c.name not in joint_rows]),
                       ("nonholonomic_constraints", system.nonholonomic_constraints)):
        document[key] = [{"name": item.name, "expression": writer.expression(item.expression)} for item in items]
    document.update({key: [] for key in LOAD_FORMATS})
    for load in system.loads:
        if load.file_table not in LOAD_FORMATS:
            raise ModelError(f"cannot write the load {load.name!r} ({type(load).__name__}): model files have no "
                             "table for it")
        document[load.file_table].append({"name": load.name, **LOAD_FORMATS[load.file_table].write(writer, load)})
    document["limits"] = [{"name": limit.name, "expression": writer.expression(limit.value),
                           **{key: writer.expression(getattr(limit, key)) for key in ("lower", "upper")
                              if getattr(limit, key) is not None},
                           "restitution": writer.expression(limit.restitution)} for limit in system.limits]
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
    if model.controller is not None:
        document["controller"] = write_controller(model.controller)
    return document


def _body_document(writer: _Writer, body: Body) -> dict[str, Any]:
    if BODY_TYPES.get(body.file_type) is not type(body):
        raise ModelError(f"cannot write the body {body.name!r} ({type(body).__name__}): model files have no type "
                         "for it (a body type is written under its own file_type)")
    arguments = body.arguments()
    return {"name": body.name, "type": body.file_type,
            **{field.name: FIELD_KINDS[field.kind].write(writer, arguments[field.name]) for field in body.fields}}


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
