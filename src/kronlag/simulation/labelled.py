"""Labelled arrays of a result: the names of its multipliers and an :class:`xarray.Dataset` with units.

A multiplier is named by its constraint, ``lambda[<constraint>]`` and ``mu[<constraint>]``, as the
plots' legends name it (:func:`kronlag.numeric.reactions.multiplier_labels`).  A dataset has the
dimension ``time`` and a dimension per kind of label (``coordinate``, ``constraint``,
``nonholonomic``, ``joint``, ...), whose coordinates are the names.

Units travel in each variable's ``units`` attribute.  They come from a mapping of units by name, as
``plot(units=...)`` takes it (:func:`kronlag.app.workflows.model_units` gives the units a model file
determines: its coordinates', ``"t"`` and ``"energy"``): a rate is per time unit (``rad/s``,
``rad/s^2``), and multipliers and joint reactions are in SI units (:mod:`kronlag.numeric.reactions`)
when the energy is in ``J``.  A variable whose entries along its labelled dimension have different
units (the angle and the length of a slider-crank) has them in a coordinate ``<variable>_units``
along that dimension instead (``""`` where unknown); a unit that cannot be told is left out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..numeric.reactions import REACTION_UNITS, joint_reaction, multiplier_labels, multiplier_units

if TYPE_CHECKING:
    import xarray

    from ..model.system import System
    from ..numeric.numeric_model import NumericModel

__all__ = ["multiplier_columns", "rate_unit", "LabelledArrays"]

#: The unit of a variable: one for all its entries, one per label of its last dimension, or unknown.
Unit = str | Sequence[str | None] | None


def multiplier_columns(system: System) -> list[str]:
    """The names of the multipliers, ``lambda[<constraint>]`` then ``mu[<nonholonomic constraint>]``."""
    return (multiplier_labels(system, with_units=False)
            + [f"mu[{constraint.name}]" for constraint in system.nonholonomic_constraints])


def rate_unit(unit: str | None, units: Mapping[str, str], order: int = 1) -> str | None:
    """The unit of a time derivative of order ``order`` of a quantity in ``unit``: ``unit/s`` or
    ``unit/s^2`` with the time unit ``units["t"]``; ``None`` unless both are known."""
    return f"{unit}/{units['t']}{'' if order == 1 else f'^{order}'}" if unit and "t" in units else None


def _xarray():
    try:
        import xarray
    except ImportError as error:
        raise ImportError("to_xarray needs xarray: pip install xarray (or 'kronlag[xarray]')") from error
    return xarray


class LabelledArrays:
    """The variables and labelled dimensions of a dataset being built (xarray is imported first, so
    that a missing xarray is reported before any work).

    Parameters
    ----------
    t : (N,)
        The times, the dimension ``time`` (in ``units["t"]``).
    units : mapping of str to str, optional
        Units by name: coordinates, ``"t"``, ``"energy"`` (see the module notes).
    """

    def __init__(self, t: np.ndarray, units: Mapping[str, str] | None):
        self._xarray = _xarray()
        self.units = dict(units or {})
        #: Multipliers and reactions are in SI units when the model is (its energy in joules).
        self.si = self.units.get("energy") == "J"
        self.coords: dict[str, Any] = {}
        self.data_vars: dict[str, Any] = {}
        self.dimension("time", np.asarray(t, dtype=float), unit=self.units.get("t"))

    def dimension(self, name: str, labels: Sequence[Any] | np.ndarray, *, unit: str | None = None) -> None:
        """A dimension ``name`` whose coordinate is ``labels``."""
        self.coords[name] = (name, np.asarray(labels), {"units": unit} if unit else {})

    def variable(self, name: str, dims: tuple[str, ...], values: np.ndarray, unit: Unit = None) -> None:
        """A variable over ``dims``; ``unit`` as :data:`Unit` (a unit per label of ``dims[-1]``
        becomes the ``units`` attribute when they are all the same, else the coordinate
        ``<name>_units``)."""
        attrs: dict[str, str] = {}
        if isinstance(unit, str):
            attrs["units"] = unit
        elif unit is not None:
            known = set(unit)
            if len(known) == 1 and None not in known:
                attrs["units"] = str(unit[0])
            elif known - {None}:
                self.coords[f"{name}_units"] = (dims[-1], [entry or "" for entry in unit])
        self.data_vars[name] = (dims, values, attrs)

    def coordinates(self, names: Sequence[str], q: np.ndarray, qd: np.ndarray, qdd: np.ndarray | None, *,
                    dims: tuple[str, ...] = ("time", "coordinate")) -> None:
        """The dimension ``coordinate`` and the variables ``q``, ``qd`` (and ``qdd``) over ``dims``."""
        own = [self.units.get(name) for name in names]
        self.dimension("coordinate", names)
        self.variable("q", dims, q, own)
        self.variable("qd", dims, qd, [rate_unit(unit, self.units) for unit in own])
        if qdd is not None:
            self.variable("qdd", dims, qdd, [rate_unit(unit, self.units, 2) for unit in own])

    def multipliers(self, system: System | None, lam: np.ndarray, mu: np.ndarray) -> None:
        """The dimensions ``constraint`` and ``nonholonomic`` (labelled by number without a system)
        and the variables ``lambda`` and ``mu``."""
        if system is None:
            self.dimension("constraint", np.arange(1, lam.shape[1] + 1))
            self.dimension("nonholonomic", np.arange(1, mu.shape[1] + 1))
            units: dict[str, str] = {}
        else:
            self.dimension("constraint", [constraint.name for constraint in system.constraints])
            self.dimension("nonholonomic", [constraint.name for constraint in system.nonholonomic_constraints])
            units = multiplier_units(system, self.units) if self.si else {}
        self.variable("lambda", ("time", "constraint"), lam,
                      [units.get(name) for name in self.coords["constraint"][1]])
        self.variable("mu", ("time", "nonholonomic"), mu)

    def reactions(self, model: NumericModel, t: np.ndarray, q: np.ndarray, lam: np.ndarray) -> None:
        """The dimensions ``joint``, ``axis`` and ``couple_axis`` and the variables ``reaction_force``
        (time, joint, axis) and ``reaction_couple`` (time, joint, couple_axis): the wrench that each
        joint's body A exerts on its body B, world components (:mod:`kronlag.numeric.reactions`)."""
        joints = model.equations.system.joints
        if not joints:
            return
        reactions = [joint_reaction(model, joint.name, t, q, lam) for joint in joints]
        force = np.stack([reaction.force for reaction in reactions], axis=1)
        couple = np.stack([reaction.torque for reaction in reactions], axis=1)
        self.dimension("joint", [joint.name for joint in joints])
        self.dimension("axis", list("xyz"[:force.shape[2]]))
        self.dimension("couple_axis", ["z"] if couple.shape[2] == 1 else list("xyz"))
        self.variable("reaction_force", ("time", "joint", "axis"), force,
                      REACTION_UNITS["force"] if self.si else None)
        self.variable("reaction_couple", ("time", "joint", "couple_axis"), couple,
                      REACTION_UNITS["couple"] if self.si else None)

    def dataset(self, attrs: Mapping[str, Any]) -> xarray.Dataset:
        """The :class:`xarray.Dataset` of the variables, with the dataset attributes ``attrs``; a
        dimension without labels (``nonholonomic`` of a system without such constraints) is left out
        with its variables, as the columns leave them out."""
        empty = {name for name, (_, labels, *_) in self.coords.items() if name != "time" and len(labels) == 0}
        data_vars = {name: item for name, item in self.data_vars.items() if not empty & set(item[0])}
        coords = {name: item for name, item in self.coords.items() if not empty & {item[0]}}
        return self._xarray.Dataset(data_vars, coords=coords, attrs=dict(attrs))
