"""Units in model files for the limits' bounds and the joints' friction (issue 18): ``{value, unit}`` tables
as parameters take them, converted to SI, their dimension checked, errors located ``FILE: ENTRY: problem``."""

from __future__ import annotations

import math
import re

import pytest
import sympy as sp
from helpers import (
    PIN_FRICTION_PENDULUM_VALUES,
    pin_friction_pendulum_file,
    rod_on_a_stop_file,
)

from kronlag.core.errors import ModelFileError
from kronlag.model.modelfile import loads_model

#: The rod on a pin with its stop on th, and a slider (coordinate s along x) with a stop ``end`` on s.
STOPS_FILE = rod_on_a_stop_file(name="stops", tables="""
[[bodies]]
name = "slider"
type = "point"
mass = "m"
position = ["s", 0]

[[limits]]
name = "end"
expression = "s"
upper = UPPER
""").replace('coordinates = ["x", "y", "th"]', 'coordinates = ["x", "y", "th", "s"]')


def _stops(lower='"-pi/2"', upper="0.25"):
    text = STOPS_FILE.replace('lower = "-pi/2"', f"lower = {lower}").replace("UPPER", upper)
    return loads_model(text, source="stops.toml")


def _friction(friction: str):
    return loads_model(pin_friction_pendulum_file(friction), source="pendulum.toml").system.joints[0].friction


def test_limit_bounds_in_degrees_and_millimetres_are_converted_to_si():
    stops = _stops(lower='{value = -90, unit = "deg"}', upper='{value = 250, unit = "mm"}')
    angle, end = stops.system.limits
    assert float(angle.lower) == pytest.approx(-math.pi / 2, rel=1e-15)
    assert float(end.upper) == pytest.approx(0.25, rel=1e-15)
    # the SI unit keeps an expression of the parameters as it is
    assert _stops(lower='{value = "-pi/2", unit = "rad"}').system.limits[0].lower == -sp.pi / 2


def test_friction_quantities_with_units_are_converted_to_si():
    friction = _friction('{kinetic = "mu", radius = {value = 10, unit = "mm"}, preload = {value = 0.5, unit = "kN"}, '
                         'static = 0.2, stribeck_velocity = {value = 6, unit = "deg/s"}, '
                         'viscous = {value = 3, unit = "N*m*s/rad"}, smoothing_velocity = {value = 0.06, unit = "rpm"}}')
    assert float(friction.radius) == pytest.approx(0.01, rel=1e-15)
    assert float(friction.preload) == pytest.approx(500.0, rel=1e-15)
    assert float(friction.stribeck_velocity) == pytest.approx(math.radians(6), rel=1e-15)
    assert float(friction.viscous) == pytest.approx(3.0, rel=1e-15)
    assert float(friction.smoothing_velocity) == pytest.approx(0.06 * 2 * math.pi / 60, rel=1e-12)
    assert friction.kinetic == sp.Symbol("mu") and float(friction.static) == 0.2
    # the same pin friction as the file's plain SI numbers
    plain = _friction(f'{{kinetic = "mu", radius = {PIN_FRICTION_PENDULUM_VALUES["r"]}}}')
    assert float(_friction('{kinetic = "mu", radius = {value = 1, unit = "cm"}}').radius) == float(plain.radius)


@pytest.mark.parametrize(("change", "message"), [
    # a limit on an angle given in metres, and on a length in seconds
    ({"lower": '{value = -1, unit = "m"}'},
     "stops.toml: limits[0].lower.unit: 'm' is a length, but the limit's expression th is dimensionless"),
    ({"upper": '{value = 1, unit = "s"}'},
     "stops.toml: limits[1].upper.unit: 's' is a time, but the limit's expression s is a length"),
    ({"lower": '{value = -90, unit = "wibbles"}'}, "stops.toml: limits[0].lower.unit: unknown unit"),
    ({"lower": '{value = -90}'}, "stops.toml: limits[0].lower: missing field 'unit'"),
    ({"lower": '{value = "-L", unit = "deg"}'},
     "stops.toml: limits[0].lower.value: a value computed from other parameters uses their SI values"),
])
def test_a_limit_bound_with_a_wrong_unit_is_a_located_error(change, message):
    with pytest.raises(ModelFileError, match="^" + re.escape(message)):
        _stops(**change)


@pytest.mark.parametrize(("friction", "message"), [
    ('{kinetic = 0.1, radius = {value = 2, unit = "s"}}',
     "joints[0].friction.radius.unit: 's' is a time, but the friction radius of a revolute joint is a length"),
    ('{kinetic = 0.1, radius = 0.01, viscous = {value = 1, unit = "N*s/m"}}',
     ("joints[0].friction.viscous.unit: 'N*s/m' is a damping coefficient (mass/time), but the friction viscous "
      "of a revolute joint is a quantity of dimension mass*length^2/time")),
    ('{kinetic = {value = 0.1, unit = "m"}, radius = 0.01}',
     "joints[0].friction.kinetic.unit: 'm' is a length, but the friction kinetic of a revolute joint is dimensionless"),
    ('{kinetic = 0.1, radius = 0.01, preload = {value = 1, unit = "kg"}}',
     "joints[0].friction.preload.unit: 'kg' is a mass, but the friction preload of a revolute joint is a force"),
    ('{kinetic = 0.1, radius = {value = 1, unit = "wobbles"}}', "joints[0].friction.radius.unit: unknown unit"),
])
def test_a_friction_quantity_with_a_wrong_unit_is_a_located_error(friction, message):
    with pytest.raises(ModelFileError, match="^" + re.escape(f"pendulum.toml: {message}")):
        _friction(friction)
