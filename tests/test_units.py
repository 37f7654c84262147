"""Units with dimensions (issue 17): every parameter's unit and every derived parameter's definition
is checked against how the model uses it, in model files (Python and the command line) and for
pint quantities given to ``eom.numeric``; units whose SI factor under- or overflows are refused."""

from __future__ import annotations

import subprocess
import sys

import pint
import pytest
import sympy as sp

import kronlag
from kronlag.core.errors import InputError, ModelFileError
from kronlag.model.builtin import example_names, example_path
from kronlag.model.dimensions import LENGTH, MASS, TIME, Dimension
from kronlag.model.modelfile import load_model, loads_model

#: The pendulum of docs/units.md: a length in mm, a mass in g, an angle in deg, a speed in rpm, a torque in N*cm.
PENDULUM = """coordinates = ["theta"]
gravity = [0, "-g"]
[parameters]
L = {value = 300, unit = "mm", description = "pendulum length"}
m = {value = 250, unit = "g"}
J = {value = "m*L**2/12", unit = "kg*m^2"}
g = {value = 9.81, unit = "m/s^2"}
tilt = {value = 90, unit = "deg"}
speed = {value = 60, unit = "rpm"}
tau = {value = 20, unit = "N*cm"}
[[bodies]]
name = "rod"
type = "planar"
mass = "m"
inertia = "J"
position = ["L/2*sin(theta)", "-L/2*cos(theta)"]
angle = "theta"
[[torques]]
body = "rod"
torque = "tau"
[initial]
q = {theta = "tilt"}
qd = {theta = "speed"}
"""

#: (case, replacements in PENDULUM, the whole message after "pendulum.toml: ").
REFUSED = [
    ("mass in mm", [('m = {value = 250, unit = "g"}', 'm = {value = 0.5, unit = "mm"}')],
     "parameters.m.unit: 'mm' is a length, but m is used as a mass in bodies[0].mass"),
    ("length in g", [('unit = "mm", description', 'unit = "g", description')],
     "parameters.L.unit: 'g' is a mass, but L is used as a length in bodies[0].position[0]"),
    ("length in Hz", [('unit = "mm", description', 'unit = "Hz", description')],
     "parameters.L.unit: 'Hz' is a frequency or an angular speed (1/time), but L is used as a length in "
     "bodies[0].position[0]"),
    ("length in bit", [('unit = "mm", description', 'unit = "bit", description')],
     "parameters.L.unit: 'bit' is dimensionless (an angle or a ratio), but L is used as a length in "
     "bodies[0].position[0]"),
    ("furlong as a mass", [('m = {value = 250, unit = "g"}', 'm = {value = 1, unit = "furlong"}')],
     "parameters.m.unit: 'furlong' is a length, but m is used as a mass in bodies[0].mass"),
    ("inertia m*L declared kg*m^2", [('"m*L**2/12"', '"m*L"')],
     "parameters.J.value: 'm*L' is a quantity of dimension mass*length (from the units of L, m), but "
     "parameters.J.unit 'kg*m^2' is a moment of inertia (mass*length^2)"),
    ("inertia m*L without a unit", [('J = {value = "m*L**2/12", unit = "kg*m^2"}', 'J = "m*L"')],
     "parameters.J: 'm*L' is a quantity of dimension mass*length, but J is used as a moment of inertia "
     "(mass*length^2) in bodies[0].inertia"),
    ("torque in N", [('unit = "N*cm"', 'unit = "N"')],
     "parameters.tau.unit: 'N' is a force (mass*length/time^2), but tau is used as an energy or a torque "
     "(mass*length^2/time^2) in torques[0].torque"),
    ("gravity in m/s", [('unit = "m/s^2"', 'unit = "m/s"')],
     "parameters.g.unit: 'm/s' is a speed (length/time), but g is used as an acceleration (length/time^2) "
     "in gravity[1]"),
    ("angle guess in mm", [('q = {theta = "tilt"}', 'q = {theta = "L"}')],
     "parameters.L.unit: 'mm' is a length, but L is used as dimensionless (an angle or a ratio) in "
     "initial.q.theta, bodies[0].position[0]"),
    ("mm**400", [('unit = "mm", description', 'unit = "mm**400", description')],
     "parameters.L.unit: the unit 'mm**400' cannot be used: its SI factor 0.0 is outside 1e-300..1e+300: "
     "values in this unit would under- or overflow"),
    ("km**400", [('unit = "mm", description', 'unit = "km**400", description')],
     "parameters.L.unit: the unit 'km**400' cannot be used: its SI factor overflows"),
]


def _pendulum(replacements) -> str:
    text = PENDULUM
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new)
    return text


@pytest.mark.parametrize(("case", "replacements", "message"), REFUSED, ids=[case for case, *_ in REFUSED])
def test_a_unit_that_does_not_fit_its_use_is_refused_in_one_located_line(case, replacements, message):
    with pytest.raises(ModelFileError) as error:
        loads_model(_pendulum(replacements), source="pendulum.toml")
    assert str(error.value) == f"pendulum.toml: {message}"


@pytest.mark.parametrize(("case", "replacements", "message"), [REFUSED[0], REFUSED[5], REFUSED[10]],
                         ids=["mass in mm", "inertia m*L", "mm**400"])
@pytest.mark.parametrize("command", [["check"], ["simulate", "--t-end", "0.01"]])
def test_the_command_line_refuses_it_with_exit_2_and_one_line(tmp_path, case, replacements, message, command):
    path = tmp_path / "pendulum.toml"
    path.write_text(_pendulum(replacements))
    done = subprocess.run([sys.executable, "-m", "kronlag", *command, str(path)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines() == [f"kronlag: error: {path}: {message}"]


def test_the_docs_pendulum_with_mm_g_deg_rpm_and_n_cm_is_accepted():
    values = loads_model(PENDULUM, source="pendulum.toml").numeric_values()
    assert values["L"] == pytest.approx(0.3) and values["m"] == pytest.approx(0.25)
    assert values["J"] == pytest.approx(0.25 * 0.3 ** 2 / 12)
    assert values["tau"] == pytest.approx(0.2) and values["speed"] == pytest.approx(2 * 3.141592653589793)


SPATIAL = """coordinates = ["z", "psi"]
gravity = [0, 0, "-g"]
[parameters]
m = {value = 1.5, unit = "kg"}
r = {value = 40, unit = "mm"}
Ia = {value = "m*r**2/2", unit = "kg*m^2"}
It = {value = 3000, unit = "g*cm^2"}
g = {value = 9.81, unit = "m/s^2"}
k = {value = 2, unit = "N/mm"}
c = {value = 5, unit = "N*s/m"}
h = {value = 100, unit = "mm"}
[[bodies]]
name = "disc"
type = "rigid"
mass = "m"
inertia = [["It", 0, 0], [0, "It", 0], [0, 0, "Ia"]]
position = [0, 0, "z"]
rotation = {axes = "z", angles = ["psi"]}
[[springs]]
point_a = [0, 0, "h"]
point_b = [0, 0, "z"]
stiffness = "k"
free_length = "h/2"
[[dampers]]
point_a = [0, 0, "h"]
point_b = [0, 0, "z"]
coefficient = "c"
[initial]
q = {z = "h/4"}
"""


def test_spatial_inertia_and_a_sliding_coordinate_with_units_are_accepted_and_checked():
    values = load_model_text(SPATIAL).numeric_values()
    assert values["It"] == pytest.approx(3e-4) and values["k"] == pytest.approx(2000)
    with pytest.raises(ModelFileError, match=r"parameters\.It\.unit: 'g\*cm' is a quantity of dimension "
                                             r"mass\*length, but It is used as a moment of inertia "
                                             r"\(mass\*length\^2\) in bodies\[0\]\.inertia\[0\]\[0\]"):
        load_model_text(SPATIAL.replace('"g*cm^2"', '"g*cm"'))
    with pytest.raises(ModelFileError, match=r"parameters\.k\.unit: 'N' is a force .* but k is used as a "
                                             r"stiffness \(mass/time\^2\) in springs\[0\]\.stiffness"):
        load_model_text(SPATIAL.replace('"N/mm"', '"N"'))
    with pytest.raises(ModelFileError, match=r"parameters\.c\.unit: 'N\*s' .* damping coefficient"):
        load_model_text(SPATIAL.replace('"N*s/m"', '"N*s"'))


def load_model_text(text: str):
    return loads_model(text, source="model.toml")


def test_a_prismatic_joint_coordinate_is_a_length_and_a_drive_takes_its_targets_dimension():
    text = """coordinates = ["x", "y", "theta"]
[parameters]
m = {value = 2, unit = "kg"}
v = {value = 30, unit = "mm/s"}
[[bodies]]
name = "slider"
type = "planar"
mass = "m"
inertia = 0.01
position = ["x", "y"]
angle = "theta"
[[joints]]
type = "prismatic"
body_a = "ground"
body_b = "slider"
axis = [1, 0]
[[drives]]
coordinate = "x"
motion = "v*t"
"""
    assert load_model_text(text).numeric_values()["v"] == pytest.approx(0.03)
    with pytest.raises(ModelFileError, match=r"parameters\.v\.unit: 'rpm' is a frequency or an angular speed "
                                             r"\(1/time\), but v is used as a speed \(length/time\) in "
                                             r"drives\[0\]\.motion"):
        load_model_text(text.replace("mm/s", "rpm"))


def test_parameters_without_units_take_their_dimension_from_their_use():
    """No units: nothing declared can be wrong, so even an inconsistent use is taken as given (SI)."""
    text = PENDULUM.replace('m = {value = 250, unit = "g"}', "m = 0.25").replace('"-L/2*cos(theta)"',
                                                                                   '"-m*cos(theta)"')
    load_model_text(text.replace('J = {value = "m*L**2/12", unit = "kg*m^2"}', "J = 0.01"))
    # a unitless a used as a length makes m*a a mass*length, which does not fit J's unit
    unfit = PENDULUM.replace('"m*L**2/12"', '"m*a"').replace("[[bodies]]", "[[bodies]]\npoints = {tip = ['a', 0]}") \
        .replace("g = {value", "a = 0.1\ng = {value")
    with pytest.raises(ModelFileError, match=r"parameters\.J\.value: 'm\*a' is a quantity of dimension "
                                             r"mass\*length .* but parameters\.J\.unit 'kg\*m\^2' is a moment"):
        load_model_text(unfit)


@pytest.mark.parametrize("name", sorted(example_names()))
def test_every_builtin_model_file_passes_the_check(name):
    load_model(example_path(name), apply_drives=False)


# -- Python: pint quantities given to eom.numeric --------------------------------------------------

@pytest.fixture(scope="module")
def pendulum_equations():
    theta = sp.Symbol("theta")
    L, m, J, g, tau = sp.symbols("L m J g tau")
    system = kronlag.System([theta], parameters=[L, m, J, g, tau], gravity=[0, -g], name="pendulum")
    system.add_body(kronlag.PlanarBody("rod", mass=m, inertia=J, position=[L / 2 * sp.sin(theta),
                                                                           -L / 2 * sp.cos(theta)], angle=theta))
    system.add_torque("rod", tau, name="motor")
    return kronlag.derive(system)


UNITS = pint.UnitRegistry()
GOOD = {"L": UNITS.Quantity(300, "mm"), "m": UNITS.Quantity(250, "g"), "J": UNITS.Quantity(1875, "g*cm^2"),
        "g": UNITS.Quantity(9.81, "m/s^2"), "tau": 0.2}


def test_quantities_are_converted_to_si(pendulum_equations):
    model = pendulum_equations.numeric(GOOD, backend="python")
    assert list(model.parameter_vector(0.0)) == pytest.approx([0.3, 0.25, 1.875e-4, 9.81, 0.2])


@pytest.mark.parametrize(("name", "value", "message"), [
    ("m", UNITS.Quantity(0.5, "mm"), "parameter m: '0.5 mm' is a length, but m is used as a mass in body 'rod' mass"),
    ("J", UNITS.Quantity(1, "kg*m"), "parameter J: '1 kg * m' is a quantity of dimension mass*length, but J is used "
                                     "as a moment of inertia (mass*length^2) in body 'rod' inertia"),
    ("L", UNITS.Quantity(1, "Hz"), "parameter L: '1 Hz' is a frequency or an angular speed (1/time), but L is used "
                                   "as a length in body 'rod' position[0]"),
    ("tau", UNITS.Quantity(1, "N"), "parameter tau: '1 N' is a force (mass*length/time^2), but tau is used as an "
                                    "energy or a torque (mass*length^2/time^2) in torque 'motor'"),
    ("L", UNITS.Quantity(300, "mm**400"), "parameter L: 300 mm ** 400 cannot be used: its SI factor 0.0 is outside "
                                          "1e-300..1e+300: values in this unit would under- or overflow"),
    ("L", UNITS.Quantity(3, "km**400"), "parameter L: 3 km ** 400 cannot be used: its unit's SI factor overflows"),
])
def test_a_quantity_of_the_wrong_dimension_is_refused_naming_the_parameter_and_its_use(pendulum_equations, name,
                                                                                        value, message):
    with pytest.raises(InputError) as error:
        pendulum_equations.numeric({**GOOD, name: value}, backend="python")
    assert str(error.value) == message


def test_dimensions_combine_and_describe_themselves():
    assert MASS * LENGTH ** 2 / TIME ** 2 == Dimension({"[length]": 2, "[mass]": 1, "[time]": -2})
    assert (MASS * LENGTH ** 2).describe() == "a moment of inertia (mass*length^2)"
    assert (LENGTH ** 3).describe() == "a quantity of dimension length^3"
