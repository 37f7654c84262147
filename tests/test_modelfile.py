"""Model files: every shipped example derives the equations of its Python model,
files survive a write/read round trip, and errors name the file and the entry."""

from __future__ import annotations

import re

import numpy as np
import pytest
import sympy as sp
from helpers import assert_numerically_equal, derived, state_symbols

import kronlag
from kronlag import models
from kronlag.core.errors import ModelFileError
from kronlag.model.builtin import example_names, example_path, load_example, resolve_model
from kronlag.model.modelfile.model_file import ModelFile
from kronlag.model.modelfile.reader import load_model, loads_model
from kronlag.model.modelfile.writer import to_toml

#: Example file -> the conftest name of its Python model.
EXAMPLES = {
    "four_bar": "four_bar",
    "quick_return": "quick_return",
    "double_pendulum": "double_pendulum",
    "slider_crank": "slider_crank",
    "slider_crank_engine": "slider_crank_engine",
    "five_bar": "five_bar",
    "heavy_top": "heavy_top",
    "chaplygin_sleigh": "chaplygin_sleigh",
    "closed_chain_4": "closed_chain_4_absolute",
    "pendulum_cartesian": "pendulum_cartesian",
    "n_four_bar": "n_four_bar",
    "andrews_squeezer": "andrews_squeezer",
    "bricard": "bricard",
    "flyball_governor": "flyball_governor",
}
COMPARED = ("M", "C", "g", "Phi_q", "A", "b", "f_Q")
#: Examples whose symbolic C is too large to evaluate at 30 digits in a test (Bricard's: 2 MB of
#: text); tests/test_iftomm.py compares their file and Python models numerically instead.
NUMERIC_COMPARISON_ONLY = {"bricard"}


def assert_same_equations(actual: kronlag.Equations, expected: kronlag.Equations) -> None:
    assert [q.name for q in actual.coordinates] == [q.name for q in expected.coordinates]
    for name in COMPARED:
        assert_numerically_equal(getattr(actual, name), getattr(expected, name), state_symbols(expected))


#: Serial-arm example files, compared with their Python model numerically (their symbolic
#: matrices are too large for the 30-digit comparison of ``assert_same_equations``).
ARMS = ("ur5", "panda")


def test_every_builtin_and_example_is_shipped():
    assert sorted(example_names()) == sorted([*EXAMPLES, *ARMS])
    assert set(models.BUILTIN_MODELS) <= {*EXAMPLES, *ARMS}


@pytest.mark.parametrize("name", sorted(set(EXAMPLES) - NUMERIC_COMPARISON_ONLY))
def test_example_derives_the_python_model(name):
    model = load_model(example_path(name), apply_drives=False)
    assert model.description
    assert_same_equations(kronlag.derive(model.system), derived(EXAMPLES[name]))


@pytest.mark.parametrize("name", ARMS)
def test_arm_example_file_gives_the_python_model(name):
    model = load_model(example_path(name), apply_drives=False)
    values = model.numeric_values()
    from_file = kronlag.derive(model.system).numeric(values, backend="python")
    python = kronlag.derive(models.BUILTIN_MODELS[name]()).numeric(values, backend="python")
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, qd = rng.uniform(-3, 3, (2, from_file.m))
        np.testing.assert_allclose(from_file.M(q), python.M(q), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(from_file.g(q), python.g(q), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(from_file.Cqd(q, qd), python.Cqd(q, qd), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_example_guess_is_near_an_assembled_configuration(name):
    model = load_model(example_path(name), apply_drives=False)
    values = model.numeric_values()
    q, _ = model.guess_vectors()
    point = {s: values[s.name] for s in model.system.parameters} | dict(zip(model.system.coordinates, q))
    residual = [float(c.expression.subs(point)) for c in model.system.constraints]
    assert np.max(np.abs(residual), initial=0.0) < 1e-3
    assert set(values) == {p.name for p in model.system.parameters}


@pytest.mark.parametrize("name", ["four_bar", "heavy_top", "chaplygin_sleigh"])
def test_written_file_reads_back_the_same_model(name):
    model = load_model(example_path(name), apply_drives=False)
    again = loads_model(to_toml(model), source="written.toml")
    assert_same_equations(kronlag.derive(again.system), kronlag.derive(model.system))
    assert again.numeric_values() == pytest.approx(model.numeric_values())
    assert again.guess_vectors() == model.guess_vectors()
    assert (again.fixed, again.qd_fixed, again.simulation) == (model.fixed, model.qd_fixed, model.simulation)
    assert again.drives == model.drives
    assert again.units == model.units
    assert [line.points for line in again.system.drawing] == [line.points for line in model.system.drawing]


def test_python_model_written_without_numbers_reads_back():
    system = models.quick_return()
    again = loads_model(to_toml(system)).system
    assert_same_equations(kronlag.derive(again), derived("quick_return"))
    assert [body.name for body in again.bodies] == [body.name for body in system.bodies]


def test_all_features_read_and_write():
    text = """
name = "features"
coordinates = ["x", "y", "z"]
gravity = [0, 0, "-g"]
[parameters]
k = 2
c = {value = "k/4"}
g = 9.81
L = {unit = "m"}
[points]
P = ["x", "y", "z"]
[[bodies]]
name = "ball"
type = "point"
mass = 1.5
position = "P"
[[springs]]
point_a = [0, 0, 0]
point_b = "P"
stiffness = "k"
free_length = "L"
[[dampers]]
point_a = [0, 0, 0]
point_b = "P"
coefficient = "c"
[[potentials]]
expression = "k*z**2/2"
[[forces]]
point = "P"
force = ["sin(t)", 0, "-c*zd"]
[[generalized_forces]]
force = [0, "exp(-t)", 0]
[[nonholonomic_constraints]]
expression = "xd - y*zd"
[[constraints]]
expression = "x**2 + y**2 - 1"
"""
    model = loads_model(text)
    system = model.system
    assert (len(system.springs), len(system.dampers), len(system.potentials), len(system.forces)) == (1, 1, 1, 2)
    assert model.numeric_values() == {"k": 2.0, "c": 0.5, "g": 9.81}
    again = loads_model(to_toml(model))
    assert_same_equations(kronlag.derive(again.system), kronlag.derive(system))
    assert again.units == {"L": "m"} and "L" not in again.values


def test_builtin_example_uses_the_python_system():
    model = load_example("four_bar", apply_drives=False)
    assert model.values["l1"] == sp.Float(0.2)
    assert model.system.name == "four_bar" and model.system.drawing[0].name == "linkage"
    assert resolve_model(str(example_path("slider_crank"))).system.name == "slider_crank"
    with pytest.raises(kronlag.ModelError, match="no example model named 'nope'"):
        resolve_model("nope")


def test_modelfile_numbers_from_python():
    model = ModelFile(system=models.double_pendulum(), values={"l1": 1, "l2": sp.Symbol("l1") * 2})
    assert model.numeric_values() == {"l1": 1.0, "l2": 2.0}
    with pytest.raises(kronlag.ModelError, match="cycle"):
        ModelFile(system=models.double_pendulum(), values={"l1": sp.Symbol("l2"), "l2": sp.Symbol("l1")}
                  ).numeric_values()


FOUR_BAR = example_path("four_bar").read_text()

BROKEN = [
    # (replace this, with this, entry named in the message, problem in the message)
    ('position = ["l1/2*cos(q1)", "l1/2*sin(q1)"]', 'position = ["l1/2*cos(q1)", "l9/2*sin(q1)"]',
     "bodies[0].position[1]", "unknown symbol 'l9'"),
    ('angle = "q2"', 'angle = "q2.real"', "bodies[1].angle", "attribute access"),
    ('angle = "q3"', 'angle = "__import__(\'os\').system(\'echo hacked\')"', "bodies[2].angle", "not allowed"),
    ('mass = "m1"', 'mass = "m1 * q1"', "bodies[0]", "may not depend on the coordinates"),
    ('mass = "m1"\n', '', "bodies[0]", "missing field 'mass'"),
    ('mass = "m1"', 'mas = "m1"', "bodies[0].mas", "unknown field"),
    ('type = "planar"\nmass = "m2"', 'type = "wheel"\nmass = "m2"', "bodies[1].type", "expected one of"),
    ('position = ["l4 + l3/2*cos(q3)", "l3/2*sin(q3)"]', 'position = ["l4"]', "bodies[2].position",
     "expected 2 entries, got 1"),
    ('inertia = "I1"', 'inertia = true', "bodies[0].inertia", "expected a number or an expression"),
    ('expression = "l1*sin(q1) + l2*sin(q2) - l3*sin(q3)"', 'expression = "l1*sin(q1) + q1d"',
     "constraints[1]", "contains speeds"),
    ('expression = "l1*sin(q1) + l2*sin(q2) - l3*sin(q3)"', 'expression = "q1 ^ 2"', "constraints[1].expression",
     "write '**'"),
    ('body = "crank"', 'body = "wheel"', "torques[0]", "no body named 'wheel'"),
    ('fixed = ["q1"]', 'fixed = ["q7"]', "initial.fixed[0]", "unknown coordinate 'q7'"),
    ('t_end = 2.0', 't_end = "long"', "simulation.t_end", "expected a finite number"),
    ('t_end = 2.0', 't_end = -1', "simulation.t_end", "expected a positive number"),
    ('motion = "1 + 2*pi*t"', 'motion = "1 + q2"', "drives[0].motion", "unknown symbol 'q2'"),
    ('points = ["A", "B", "C", "D"]', 'points = ["A", "B", "E"]', "drawing[0].points[2]", "unknown point 'E'"),
    ('m1 = {value = 1.0, unit = "kg"}', 'm1 = {value = 1.0, units = "kg"}', "parameters.m1.units", "unknown field"),
    ('I1 = {value = "m1*l1**2/12"', 'I1 = {value = "m1*l1**2/12 + I1"', "parameters.I1.value", "itself"),
    ('coordinates = ["q1", "q2", "q3"]', 'coordinates = ["q1", "q2", "sin"]', "coordinates[2]",
     "cannot be a symbol name"),
    ('gravity = [0, "-g"]', 'gravity = [0, "-g", 0, 1]', "gravity", "expected 2 or 3 entries"),
    ('[[traces]]', '[[traces]]\n[[traces]]', "traces[0]", "missing field 'point'"),
]


@pytest.mark.parametrize("old, new, entry, problem", BROKEN, ids=[case[2] for case in BROKEN])
def test_errors_name_file_entry_and_problem(tmp_path, capfd, old, new, entry, problem):
    assert old in FOUR_BAR
    path = tmp_path / "broken.toml"
    path.write_text(FOUR_BAR.replace(old, new, 1))
    with pytest.raises(kronlag.ModelError) as caught:
        load_model(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {entry}"), message
    assert problem in message, message
    assert "hacked" not in capfd.readouterr().out


def test_file_level_errors(tmp_path):
    with pytest.raises(ModelFileError, match=re.escape(f"{tmp_path / 'missing.toml'}: cannot read the file")):
        load_model(tmp_path / "missing.toml")
    with pytest.raises(ModelFileError, match="bad.toml: not valid TOML"):
        loads_model("coordinates = [", source="bad.toml")
    with pytest.raises(ModelFileError, match="x.toml: file: missing field 'coordinates'"):
        loads_model("name = 'a'", source="x.toml")
    with pytest.raises(ModelFileError, match="x.toml: initial: initial q of q1 uses symbols without a value: L"):
        loads_model("coordinates = ['q1']\n[parameters]\nL = {unit = 'm'}\n[initial]\nq = {q1 = 'L'}",
                    source="x.toml")


def test_writing_refuses_what_the_syntax_cannot_express():
    system = kronlag.System(kronlag.coordinates("x"), name="odd")
    system.add_potential(sp.Symbol("x") ** 2 * sp.erf(sp.Symbol("x")))
    with pytest.raises(kronlag.ModelError, match="cannot write the expression"):
        to_toml(system)
