"""The dimensional check of a model file: every parameter's unit and every derived parameter's
definition against how the file uses them (:mod:`kronlag.model.dimensions` infers the dimensions)."""

from __future__ import annotations

from ...core.errors import ModelFileError
from ..dimensions import Dimension, DimensionCheck, DimensionConflict, Place
from ..friction import friction_uses
from ..symbols import speed_symbol
from .controller import check_controller_dimensions
from .model_file import ModelFile
from .units import si_unit

__all__ = ["check_file_dimensions"]


def check_file_dimensions(document: dict, model: ModelFile) -> None:
    """Check the dimensions of a model read from ``document`` (its parsed TOML).

    Raises
    ------
    ModelFileError
        ``FILE: parameters.m3.unit: 'mm' is a length, but m3 is used as a mass in bodies[2].mass``:
        a unit, or a derived parameter's definition, that does not fit the parameter's uses.
    """
    check = DimensionCheck(model.system, in_file=True)
    table = document.get("parameters", {})
    try:
        for name, item in table.items():
            if isinstance(item, dict) and "unit" in item:
                one, _ = si_unit(item["unit"])
                place = Place(f"parameters.{name}.unit", f"parameter {name}")
                check.unit(name, Dimension(one.dimensionality), unit=item["unit"], place=place)
        check.system_uses()
        check_controller_dimensions(check, model)
        for i, drive in enumerate(model.drives.values()):
            check.same(drive.target, drive.motion, Place(f"drives[{i}].motion", f"drives[{i}].motion"))
        for i, limit in enumerate(model.system.limits):
            for key in ("lower", "upper"):
                if getattr(limit, key) is not None:
                    check.same(limit.value, getattr(limit, key), Place(f"limits[{i}].{key}", f"limits[{i}].{key}"))
            check.use(limit.restitution, Dimension(), Place(f"limits[{i}].restitution", f"limits[{i}].restitution"))
        _check_quantity_units(check, document, model)
        coordinates = {q.name: q for q in model.system.coordinates}
        for key, guesses in (("q", model.q_guess), ("qd", model.qd_guess)):
            for name, value in guesses.items():
                symbol = coordinates[name] if key == "q" else speed_symbol(coordinates[name])
                check.same(symbol, value, Place(f"initial.{key}.{name}", f"initial.{key}.{name}"))
        for name, value in model.values.items():
            if value.free_symbols:
                written = table[name]["value"] if isinstance(table[name], dict) else table[name]
                entry = f"parameters.{name}.value" if isinstance(table[name], dict) else f"parameters.{name}"
                check.derived(name, value, text=written, place=Place(entry, f"parameter {name}"))
    except DimensionConflict as conflict:
        raise ModelFileError(f"{model.source}: {conflict.entry}: {conflict.problem}") from None


def _check_unit(item: dict, expected: Dimension | None, entry: str, what: str) -> Dimension:
    """The dimension of the unit of the ``{value, unit}`` table ``item`` (at ``entry``); DimensionConflict at
    ``ENTRY.unit`` when it is not ``expected``, the dimension of ``what`` (None: not known yet)."""
    dimension = Dimension(si_unit(item["unit"])[0].dimensionality)
    if expected is not None and dimension != expected:
        raise DimensionConflict(f"{entry}.unit", f"{item['unit']!r} is {dimension.describe()}, but {what} is "
                                                 f"{expected.describe()}")
    return dimension


def _check_quantity_units(check: DimensionCheck, document: dict, model: ModelFile) -> None:
    """The units of the ``{value, unit}`` tables of limits' bounds (the dimension of the limit's expression,
    as the file's uses and units determine it; entered as a use where they do not) and of joints' friction
    quantities (:func:`~kronlag.model.friction.friction_uses`)."""
    for i, (table, limit) in enumerate(zip(document.get("limits", []), model.system.limits)):
        for key in ("lower", "upper"):
            if isinstance(table.get(key), dict):
                place = Place(f"limits[{i}].{key}.unit", f"limits[{i}].{key}")
                known = check.solver.value(check.form(limit.value, place))
                dimension = _check_unit(table[key], known, f"limits[{i}].{key}", f"the limit's expression {limit.value}")
                check.use(limit.value, dimension, place)
    for j, (table, joint) in enumerate(zip(document.get("joints", []), model.system.joints)):
        friction = table.get("friction", {})
        for key, _, powers in friction_uses(joint):
            if isinstance(friction.get(key), dict):
                _check_unit(friction[key], Dimension(powers), f"joints[{j}].friction.{key}",
                            f"the friction {key} of a {joint.kind} joint")
