"""Inputs are checked: rotations orthogonal with determinant +1, bodies physical at the numeric
stage, model-file units converted to SI, sizes bounded, identifiers written plainly."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag import ModelError, PlanarBody, PointMass, RigidBody, RotationSequence, System, models
from kronlag.core.errors import ExpressionError
from kronlag.model.bodies import check_parameter_values
from kronlag.model.builtin import example_path
from kronlag.model.expressions import MAX_DEPTH, parse_expression
from kronlag.model.modelfile.reader import load_model, loads_model
from kronlag.model.modelfile.writer import to_toml
from kronlag.model.rotations import MAX_ROTATION_FACTORS

a, b, l, m = sp.symbols("a b l m")
c, s = sp.cos(a), sp.sin(a)
ROTATION_Z = sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rigid(rotation, *, mass=1, inertia=sp.eye(3), name="link") -> RigidBody:
    return RigidBody(name, mass=mass, inertia=inertia, position=(0, 0, 0), rotation=rotation)


# -- rotation matrices -----------------------------------------------------------------

def test_orthogonal_rotations_are_accepted():
    rigid(ROTATION_Z)
    rigid(sp.Matrix(RotationSequence([("z", a), ("x", b), ("z", a + b)]).matrix))  # checked numerically
    rigid(RotationSequence([((0, sp.Rational(3, 5), sp.Rational(4, 5)), a)]))


def test_sign_typo_names_body_and_entry():
    typo = ROTATION_Z.copy()
    typo[0, 1] = s  # should be -sin(a)
    with pytest.raises(ModelError, match=r"body 'link' rotation is not orthogonal: \(R\^T R\)\[0,1\] = "
                                         r"-?\d.* expected 0 .*at a="):
        rigid(typo)


def test_reflection_is_refused():
    mirror = ROTATION_Z.copy()
    mirror[2, 2] = -1
    with pytest.raises(ModelError, match="body 'link' rotation has determinant -1 .*reflection"):
        rigid(mirror)


def test_constant_scale_is_refused():
    with pytest.raises(ModelError, match=r"R\^T R = 4 I"):
        rigid(2 * ROTATION_Z)


def test_euler_parameter_rotation_is_accepted_off_its_normalization():
    """``R(e)`` of Euler parameters is a rotation only on e.e = 1 (a constraint the user adds):
    R^T R = (e.e)^2 I there varies with the coordinates and is accepted."""
    e0, e1, e2, e3 = sp.symbols("e0 e1 e2 e3")
    e = sp.Matrix([e1, e2, e3])
    skew = sp.Matrix([[0, -e3, e2], [e3, 0, -e1], [-e2, e1, 0]])
    rotation = (e0 ** 2 - (e.T * e)[0, 0]) * sp.eye(3) + 2 * e * e.T + 2 * e0 * skew
    rigid(rotation)
    broken = rotation.copy()
    broken[1, 2] = -broken[1, 2]
    with pytest.raises(ModelError, match="not orthogonal"):
        rigid(broken)


def test_rotation_sequence_limits():
    with pytest.raises(ModelError, match=f"at most {MAX_ROTATION_FACTORS}"):
        RotationSequence([("x", a)] * (MAX_ROTATION_FACTORS + 1))
    with pytest.raises(ModelError, match="factor 0: the axis .* is not a unit vector"):
        RotationSequence([((1, 1, 0), a)])
    with pytest.raises(ModelError, match="factor 1: axis must be 'x', 'y', 'z'"):
        RotationSequence([("x", a), ("w", b)])


HEAVY_TOP = example_path("heavy_top").read_text()


def test_model_file_rotation_errors_are_located(tmp_path):
    path = tmp_path / "top.toml"
    path.write_text(HEAVY_TOP.replace('rotation = {axes = "zxz", angles = ["psi", "theta", "phi"]}',
                                      'rotation = [["cos(psi)", "sin(psi)", 0], ["sin(psi)", "cos(psi)", 0], [0, 0, 1]]'))
    with pytest.raises(ModelError) as caught:
        load_model(path)
    assert str(caught.value).startswith(f"{path}: bodies[0]: body 'top' rotation is not orthogonal: (R^T R)[0,1]")
    axes = "xyz" * (MAX_ROTATION_FACTORS // 3 + 1)
    path.write_text(HEAVY_TOP.replace('axes = "zxz", angles = ["psi", "theta", "phi"]',
                                      f'axes = "{axes}", angles = {["psi"] * len(axes)}'.replace("'", '"')))
    with pytest.raises(ModelError) as caught:
        load_model(path)
    assert str(caught.value).startswith(f"{path}: bodies[0].rotation.axes: {len(axes)} elementary rotations")


# -- physical parameter values -----------------------------------------------------------

def spatial_system(inertia) -> System:
    x = sp.Symbol("x")
    system = System([x], parameters=[m], gravity=(0, 0, -9.81))
    system.add_body(RigidBody("disc", mass=m, inertia=inertia, position=(x, 0, 0), rotation=sp.eye(3)))
    return system


@pytest.mark.parametrize("inertia, values, problem", [
    (sp.diag(1, 1, 1), {"m": -2.0}, "body 'disc': mass = -2 (m); a mass must not be negative"),
    (sp.diag(1, 1, 1), {"m": float("nan")}, "body 'disc': mass = nan"),
    (sp.Matrix([[1, 2, 0], [2, 1, 0], [0, 0, 1]]), {"m": 1.0}, "body 'disc': the inertia tensor is not positive"),
    (sp.diag(1, 1, 3), {"m": 1.0}, "body 'disc': the principal moments of inertia 1, 1, 3 violate the triangle"),
])
def test_unphysical_bodies_are_refused_at_the_numeric_stage(inertia, values, problem):
    equations = kronlag.derive(spatial_system(inertia))
    with pytest.raises(ModelError) as caught:
        equations.numeric(values, backend="python")
    assert problem in str(caught.value)


def test_physical_bodies_pass():
    check_parameter_values(spatial_system(sp.diag(1, 1, 2)), {"m": 1.0})  # a thin disc: I1 + I2 = I3
    x = sp.Symbol("x")
    system = System([x], parameters=[m, l])
    system.add_body(PlanarBody("bar", mass=m, inertia=m * l ** 2 / 12, position=(x, 0), angle=0))
    system.add_body(PointMass("bead", mass=m, position=(x, l)))
    check_parameter_values(system, {"m": 2.0, "l": 1.0})
    with pytest.raises(ModelError, match="body 'bar': mass = -2"):
        check_parameter_values(system, {"m": -2.0, "l": 1.0})


def test_every_builtin_model_is_physical_with_its_file_values():
    for name in models.BUILTIN_MODELS:
        model = kronlag.model.builtin.load_example(name, apply_drives=False)
        check_parameter_values(model.system, model.numeric_values())


# -- units -------------------------------------------------------------------------------------

PENDULUM = """
coordinates = ["x"]
[parameters]
{parameter}
[[bodies]]
name = "bob"
type = "point"
mass = 1
position = ["x", "0"]
"""


@pytest.mark.parametrize("parameter, value, unit", [
    ('L = {value = 300, unit = "mm"}', 0.3, "m"),
    ('a = {value = 90, unit = "deg"}', np.pi / 2, "rad"),
    ('J = {value = 2, unit = "g*cm^2"}', 2e-7, "kg * m ** 2"),
    ('w = {value = 60, unit = "rpm"}', 2 * np.pi, "rad / s"),
    ('g = {value = 9.81, unit = "m/s^2"}', 9.81, "m / s ** 2"),
])
def test_units_are_converted_to_si(parameter, value, unit):
    model = loads_model(PENDULUM.format(parameter=parameter), source="units.toml")
    (name, number), = model.numeric_values().items()
    assert number == pytest.approx(value, rel=1e-12)
    assert model.units[name] == unit
    again = loads_model(to_toml(model), source="again.toml")
    assert again.numeric_values()[name] == pytest.approx(value, rel=1e-12)


@pytest.mark.parametrize("parameter, entry, problem", [
    ('L = {value = 1, unit = "furlongs_per_fortnightx"}', "parameters.L.unit", "unknown unit"),
    ('T = {value = 20, unit = "degC"}', "parameters.T.unit", "has an offset"),
    ('L = {value = 1, unit = "__import__(\'os\')"}', "parameters.L.unit", "unknown unit"),
    ('L = {value = "2*d", unit = "mm"}\nd = 1', "parameters.L.value", "must be the SI unit 'm'"),
])
def test_unit_errors_are_located(parameter, entry, problem):
    with pytest.raises(ModelError) as caught:
        loads_model(PENDULUM.format(parameter=parameter), source="units.toml")
    message = str(caught.value)
    assert message.startswith(f"units.toml: {entry}: "), message
    assert problem in message, message


# -- expressions ----------------------------------------------------------------------------

SYMBOLS = {"m1": sp.Symbol("m1"), "x": sp.Symbol("x")}


def test_fullwidth_identifier_is_refused():
    with pytest.raises(ExpressionError, match="'ｍ1' is not plain text: Python reads it as 'm1'"):
        parse_expression("ｍ1 + x", SYMBOLS, what="f.toml: bodies[0].mass")
    with pytest.raises(ModelError) as caught:
        loads_model(PENDULUM.format(parameter='"ｍ1" = 1'), source="units.toml")
    assert str(caught.value).startswith("units.toml: parameters.ｍ1: 'ｍ1' is not plain text")


def test_flat_sums_and_products_are_one_level():
    terms = 500
    assert parse_expression(" + ".join(["x"] * terms), SYMBOLS) == terms * SYMBOLS["x"]
    assert parse_expression(" - ".join(["m1"] * 61), SYMBOLS) == -59 * SYMBOLS["m1"]
    assert parse_expression(" * ".join(["x"] * 70) + " / m1", SYMBOLS) == SYMBOLS["x"] ** 70 / SYMBOLS["m1"]
    with pytest.raises(ExpressionError, match=f"nested more than {MAX_DEPTH} levels"):
        parse_expression("sin(" * (MAX_DEPTH + 2) + "x" + ")" * (MAX_DEPTH + 2), SYMBOLS)


def test_chains_keep_the_order_of_operations():
    x, m1 = SYMBOLS["x"], SYMBOLS["m1"]
    assert parse_expression("x - m1 - x", SYMBOLS) == -m1
    assert parse_expression("x / m1 / x", SYMBOLS) == 1 / m1
    assert parse_expression("x - m1 * x / 2 + 3", SYMBOLS) == x - m1 * x / 2 + 3
    with pytest.raises(ExpressionError, match="division by zero"):
        parse_expression("x / m1 / (x - x)", SYMBOLS)
