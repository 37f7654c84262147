"""The formats of model-file entries: how body fields and loads are read and written.

- :data:`FIELD_KINDS`: for each kind of body field (:class:`~kronlag.model.bodies.Field`), how its
  value is read from a file and written to one.  The body types themselves come from
  :data:`~kronlag.model.bodies.BODY_TYPES` by their ``type``, and a body's fields from its class:
  a new body type whose fields are of these kinds needs nothing here.
- :data:`LOAD_FORMATS`: for each array of tables of loads (a load type's ``file_table``:
  ``[[springs]]``, ...), the fields of an entry, how it is added to a system and how a load is written.

The readers and writers take the file reader and writer of :mod:`.reader` and :mod:`.writer`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import sympy as sp

from ..rotations import MAX_ROTATION_FACTORS, RotationSequence

if TYPE_CHECKING:
    from ..bodies import Body
    from ..loads import BodyTorque, Damper, GeneralizedForce, PointForce, Potential, Spring
    from ..system import System
    from .reader import _Reader
    from .writer import _Writer

__all__ = ["FieldKind", "FIELD_KINDS", "LoadFormat", "LOAD_FORMATS", "read_rotation"]


# -- body fields ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class FieldKind:
    """How a body field of one kind is read, ``read(reader, value, entry, body_type)``, and
    written, ``write(writer, value) -> TOML value``."""

    read: Callable[[_Reader, Any, str, type[Body]], Any]
    write: Callable[[_Writer, Any], Any]


def _read_inertia_tensor(reader: _Reader, value, entry: str) -> sp.Matrix:
    """A 3x3 tensor, or 3 principal moments on the diagonal."""
    if isinstance(value, list) and len(value) == 3 and not any(isinstance(row, list) for row in value):
        return sp.diag(*reader.vector(value, entry, (3,)))
    return sp.Matrix(reader.matrix(value, entry, 3, 3))


def read_rotation(reader: _Reader, value, entry: str) -> sp.Matrix | RotationSequence:
    """A 3x3 matrix, or ``{axes = "zxz", angles = [...]}``: ``R = R_a1(angle1) R_a2(angle2) ...``
    (a :class:`~kronlag.model.rotations.RotationSequence`, at most ``MAX_ROTATION_FACTORS`` axes)."""
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


def _write_rotation(writer: _Writer, rotation: sp.MatrixBase | RotationSequence) -> list | dict[str, Any]:
    """``{axes, angles}`` for a sequence of rotations about x, y, z; else the matrix."""
    if isinstance(rotation, RotationSequence):
        if None not in rotation.axis_names:
            return {"axes": "".join(rotation.axis_names),
                    "angles": [writer.expression(angle) for _, angle in rotation.factors]}
        rotation = rotation.matrix
    return writer.matrix(rotation)


#: The kinds of body fields (:attr:`kronlag.model.bodies.Field.kind`).
FIELD_KINDS: dict[str, FieldKind] = {
    "expression": FieldKind(lambda reader, value, entry, _: reader.expression(value, entry),
                            lambda writer, value: writer.expression(value)),
    "point": FieldKind(lambda reader, value, entry, body_type: reader.point(value, entry, body_type.dimensions),
                       lambda writer, value: writer.vector(value)),
    "tensor": FieldKind(lambda reader, value, entry, _: _read_inertia_tensor(reader, value, entry),
                        lambda writer, value: writer.matrix(value)),
    "rotation": FieldKind(lambda reader, value, entry, _: read_rotation(reader, value, entry), _write_rotation),
    "flag": FieldKind(lambda reader, value, entry, _: reader.flag(value, entry), lambda writer, value: value),
}


# -- loads ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LoadFormat:
    """The entries of one array of tables of loads.

    Attributes
    ----------
    required, optional : tuple of str
        The entry's fields besides the optional ``name``.
    read : callable
        ``read(reader, system, entry, table, name)`` adds the entry's load to the system.
    write : callable
        ``write(writer, load) -> dict``: the fields of a load's entry after its ``name``.
    """

    required: tuple[str, ...]
    optional: tuple[str, ...]
    read: Callable[[_Reader, System, str, dict, str | None], None]
    write: Callable[[_Writer, Any], dict[str, Any]]


def _read_potential(reader: _Reader, system: System, entry: str, table: dict, name: str | None) -> None:
    system.add_potential(reader.expression(table["expression"], f"{entry}.expression"), name=name)


def _write_potential(writer: _Writer, potential: Potential) -> dict[str, Any]:
    return {"expression": writer.expression(potential.expression)}


def _ends(reader: _Reader, entry: str, table: dict) -> tuple[list, list]:
    """The two points of a spring or a damper."""
    return reader.point(table["point_a"], f"{entry}.point_a"), reader.point(table["point_b"], f"{entry}.point_b")


def _write_ends(writer: _Writer, load: Spring | Damper) -> dict[str, Any]:
    return {"point_a": writer.vector(load.point_a), "point_b": writer.vector(load.point_b)}


def _read_spring(reader: _Reader, system: System, entry: str, table: dict, name: str | None) -> None:
    system.add_spring(*_ends(reader, entry, table),
                      stiffness=reader.expression(table["stiffness"], f"{entry}.stiffness"),
                      free_length=reader.expression(table.get("free_length", 0), f"{entry}.free_length"), name=name)


def _write_spring(writer: _Writer, spring: Spring) -> dict[str, Any]:
    return {**_write_ends(writer, spring), "stiffness": writer.expression(spring.stiffness),
            "free_length": writer.expression(spring.free_length)}


def _read_damper(reader: _Reader, system: System, entry: str, table: dict, name: str | None) -> None:
    system.add_damper(*_ends(reader, entry, table),
                      coefficient=reader.expression(table["coefficient"], f"{entry}.coefficient"), name=name)


def _write_damper(writer: _Writer, damper: Damper) -> dict[str, Any]:
    return {**_write_ends(writer, damper), "coefficient": writer.expression(damper.coefficient)}


def _read_force(reader: _Reader, system: System, entry: str, table: dict, name: str | None) -> None:
    point = reader.point(table["point"], f"{entry}.point")
    system.add_force(point, reader.vector(table["force"], f"{entry}.force", (len(point),)), name=name)


def _write_force(writer: _Writer, force: PointForce) -> dict[str, Any]:
    return {"point": writer.vector(force.point), "force": writer.vector(force.value)}


def _read_torque(reader: _Reader, system: System, entry: str, table: dict, name: str | None) -> None:
    value = table["torque"]
    torque = (reader.vector(value, f"{entry}.torque", (3,)) if isinstance(value, list)
              else reader.expression(value, f"{entry}.torque"))
    system.add_torque(reader.string(table["body"], f"{entry}.body"), torque,
                      frame=reader.string(table.get("frame", "world"), f"{entry}.frame"), name=name)


def _write_torque(writer: _Writer, torque: BodyTorque) -> dict[str, Any]:
    components = writer.vector(torque.value)
    entry = {"body": torque.body.name, "torque": components[0] if len(components) == 1 else components}
    return entry if torque.frame == "world" else {**entry, "frame": torque.frame}


def _read_generalized_force(reader: _Reader, system: System, entry: str, table: dict, name: str | None) -> None:
    force = reader.vector(table["force"], f"{entry}.force", (len(system.coordinates),))
    system.add_generalized_force(force, name=name)


def _write_generalized_force(writer: _Writer, force: GeneralizedForce) -> dict[str, Any]:
    return {"force": writer.vector(force.value)}


#: The load formats by table (:attr:`kronlag.model.loads.Load.file_table`), in the order files hold them.
LOAD_FORMATS: dict[str, LoadFormat] = {
    "potentials": LoadFormat(("expression",), (), _read_potential, _write_potential),
    "springs": LoadFormat(("point_a", "point_b", "stiffness"), ("free_length",), _read_spring, _write_spring),
    "dampers": LoadFormat(("point_a", "point_b", "coefficient"), (), _read_damper, _write_damper),
    "forces": LoadFormat(("point", "force"), (), _read_force, _write_force),
    "torques": LoadFormat(("body", "torque"), ("frame",), _read_torque, _write_torque),
    "generalized_forces": LoadFormat(("force",), (), _read_generalized_force, _write_generalized_force),
}
