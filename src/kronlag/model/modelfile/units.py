"""Units of parameter values in model files: parsed with pint, converted to SI base units."""

from __future__ import annotations

import functools

import pint

from ..dimensions import check_si_factor

__all__ = ["MAX_UNIT_LENGTH", "si_unit"]

#: Longest accepted unit text, in characters.
MAX_UNIT_LENGTH = 100


@functools.cache
def _unit_registry() -> pint.UnitRegistry:
    return pint.UnitRegistry()


@functools.lru_cache(maxsize=4096)
def si_unit(text: str) -> tuple[pint.Quantity, str]:
    """``(one unit in SI base units, the SI unit as text)`` for a unit written in a file.

    Raises
    ------
    ValueError
        The text is too long, not a unit, a unit with an offset, or one whose SI factor under- or
        overflows (outside :data:`kronlag.model.dimensions.SI_FACTOR_RANGE`; the reader locates the message).
    """
    if len(text) > MAX_UNIT_LENGTH:
        raise ValueError(f"the unit is longer than {MAX_UNIT_LENGTH} characters")
    registry = _unit_registry()
    try:
        unit = registry.Unit(text)
        one = registry.Quantity(1, unit).to_base_units()
        zero = registry.Quantity(0, unit).to_base_units()
    except OverflowError:
        raise ValueError(f"the unit {text!r} cannot be used: its SI factor overflows") from None
    except Exception as error:  # pint's parser fails in many ways on text that is not a unit
        raise ValueError(f"unknown unit {text!r} ({type(error).__name__}: {error})") from None
    try:
        check_si_factor(float(one.magnitude))
    except ValueError as error:
        raise ValueError(f"the unit {text!r} cannot be used: {error}") from None
    if zero.magnitude != 0:
        raise ValueError(f"the unit {text!r} has an offset (like degC); give the value in kelvin")
    return one, f"{one.units:~}"
