"""Bodies and loads as types that contribute their own terms: kinetic energy, pose, torques, potentials and
generalized forces, their model-file formats, and a new body type and load type added in one place each."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
import sympy as sp

import kronlag
from kronlag import frames
from kronlag.model.bodies import BODY_TYPES, Body, Field, PlanarBody, PointMass, Pose, RigidBody
from kronlag.model.contributions import KineticTerm
from kronlag.model.frames import Frame
from kronlag.model.loads import (
    AppliedForce,
    BodyTorque,
    Damper,
    GeneralizedForce,
    Load,
    PointForce,
    Potential,
    Spring,
)
from kronlag.model.modelfile import loads_model, to_toml
from kronlag.model.modelfile.formats import LOAD_FORMATS
from kronlag.model.rotations import RotationSequence, check_rotation, elementary_rotation, planar_rotation, skew

x, y, th, a, b = sp.symbols("x y th a b")
m, inertia, k, c, L, F = sp.symbols("m I k c L F")
xd, yd, thd, ad, bd = (kronlag.speed_symbol(q) for q in (x, y, th, a, b))


def kinetic_energy(system: kronlag.System) -> sp.Expr:
    """``1/2 qd^T M qd`` of the derived equations."""
    qd = sp.Matrix(system.speeds)
    return (qd.T * kronlag.derive(system).M * qd)[0, 0] / 2


def planar_system(*bodies: Body) -> kronlag.System:
    system = kronlag.System([x, y, th], parameters=[m, inertia, k, c, L, F])
    for body in bodies:
        system.add_body(body)
    return system


# -- bodies ----------------------------------------------------------------------------------------

def test_the_body_types_are_registered_by_their_file_type():
    assert {name: BODY_TYPES[name] for name in ("planar", "rigid", "point")} == {
        "planar": PlanarBody, "rigid": RigidBody, "point": PointMass}
    assert [field.name for field in RigidBody.fields] == ["mass", "inertia", "position", "rotation", "simplify"]


def test_planar_body_and_point_mass_kinetic_energy():
    system = planar_system(PlanarBody("disc", mass=m, inertia=inertia, position=(x, y), angle=th),
                           PointMass("bead", mass=m, position=(x + L * sp.cos(th), y)))
    bead_velocity = (xd - L * sp.sin(th) * thd, yd)
    expected = (m * (xd**2 + yd**2) + inertia * thd**2 + m * sum(v**2 for v in bead_velocity)) / 2
    assert sp.expand(kinetic_energy(system) - expected) == 0


@pytest.mark.parametrize("rotation", [RotationSequence([("z", a), ("x", b)]),
                                      elementary_rotation("z", a) * elementary_rotation("x", b)])
def test_rigid_body_kinetic_energy_is_the_body_frame_rotation(rotation):
    tensor = sp.diag(1, 2, 3)
    system = kronlag.System([a, b], parameters=[m])
    system.add_body(RigidBody("top", mass=m, inertia=tensor, position=(0, 0, 0), rotation=rotation))
    matrix = sp.Matrix(system.bodies[0].rotation)
    spin = matrix.T * (matrix.diff(a) * ad + matrix.diff(b) * bd)
    omega = sp.Matrix([spin[2, 1], spin[0, 2], spin[1, 0]])
    assert sp.simplify(kinetic_energy(system) - (omega.T * tensor * omega)[0, 0] / 2) == 0


def test_pose_frame_and_points_come_from_the_body():
    planar = PlanarBody("disc", mass=m, inertia=inertia, position=(x, y), angle=th)
    assert planar.pose() == Pose(Frame((x, y), planar_rotation(th)), th)
    assert frames.body_frame(planar) == planar.pose().frame
    assert frames.body_point(planar, (L, 0)) == sp.Matrix([x + L * sp.cos(th), y + L * sp.sin(th)])
    rigid = RigidBody("top", mass=m, inertia=sp.eye(3), position=(x, y, 0), rotation=elementary_rotation("z", th))
    assert rigid.pose() == Pose(Frame((x, y, 0), elementary_rotation("z", th)))
    particle = PointMass("bead", mass=m, position=(x, y))
    assert particle.pose().frame.rotation == sp.eye(2) and not particle.oriented
    with pytest.raises(kronlag.ModelError, match="point mass 'bead' has no extent"):
        particle.point((L, 0))


@pytest.mark.parametrize("body", [
    PlanarBody("disc", mass=m, inertia=inertia, position=(x, y), angle=th),
    RigidBody("top", mass=m, inertia=sp.diag(1, 2, 2), position=(x, y, 0), rotation=RotationSequence([("z", th)])),
    RigidBody("box", mass=m, inertia=sp.eye(3), position=(x, y, 0), rotation=elementary_rotation("x", th),
              simplify=False),
    PointMass("bead", mass=m, position=(x, y, th)),
])
def test_arguments_make_the_body_again_and_name_its_expressions(body):
    assert type(body)(body.name, **body.arguments()) == body
    assert [field for field, _, _ in body.expressions()] == [f.name for f in body.fields if f.is_expression]


def test_torque_components_and_their_generalized_force():
    with pytest.raises(kronlag.ModelError, match="torque 't' acts on point mass 'bead', which cannot take a torque"):
        PointMass("bead", mass=m, position=(x, y)).torque_components(F, "torque 't'")
    with pytest.raises(kronlag.ModelError, match="on planar body 'disc' must be a scalar"):
        PlanarBody("disc", mass=m, inertia=inertia, position=(x, y), angle=th).torque_components((F, F), "torque")

    def with_torque(torque, frame: str) -> sp.Matrix:
        system = kronlag.System([a, b], parameters=[m, F])
        system.add_body(RigidBody("top", mass=m, inertia=sp.eye(3), position=(0, 0, 0),
                                  rotation=RotationSequence([("z", a), ("x", b)])))
        system.add_torque("top", torque, frame=frame)
        return kronlag.derive(system).f_Q

    world = sp.Matrix([F * b, 0, F])
    in_body = RotationSequence([("z", a), ("x", b)]).matrix.T * world
    assert sp.simplify(with_torque(world, "world") - with_torque(in_body, "body")) == sp.zeros(2, 1)


# -- a new body type: one class ----------------------------------------------------------------------

@dataclass(frozen=True)
class _Rod(Body):
    """A uniform slender rod in the plane: a planar body of inertia ``m L^2 / 12``."""

    name: str
    mass: sp.Expr
    length: sp.Expr
    position: sp.ImmutableMatrix
    angle: sp.Expr

    fields = (Field("mass", "expression"), Field("length", "expression"), Field("position", "point", varies=True),
              Field("angle", "expression", varies=True))
    dimensions = (2,)
    kind = "rod"

    def __post_init__(self):
        object.__setattr__(self, "position", sp.ImmutableMatrix(self.position))

    def kinetic_terms(self, calculus) -> tuple[KineticTerm, ...]:
        return (*super().kinetic_terms(calculus),
                KineticTerm(self.angular_velocity(calculus), calculus.scalar(self.mass * self.length**2 / 12)))

    def angular_velocity(self, calculus):
        return calculus.velocity(sp.ImmutableMatrix([self.angle]))

    def pose(self) -> Pose:
        return Pose(Frame(self.position, planar_rotation(self.angle)), self.angle)

    def torque_components(self, torque, what: str) -> sp.ImmutableMatrix:
        return sp.ImmutableMatrix([torque])


@pytest.fixture
def rod_type():
    """A ``_Rod`` that model files hold as ``type = "rod"`` (its ``file_type`` enters it in BODY_TYPES),
    for one test."""

    class Rod(_Rod):
        file_type = "rod"

    assert BODY_TYPES["rod"] is Rod
    yield Rod
    del BODY_TYPES["rod"]


def test_a_new_body_type_is_one_class(rod_type):
    def pendulum(body: Body) -> kronlag.System:
        system = kronlag.System([x, y, th], parameters=[m, L, F], gravity=(0, -9.81), name="rod")
        system.add_body(body)
        system.add_joint("revolute", "ground", body.name, at_b=(-L / 2, 0))
        system.add_torque(body.name, F)
        return system

    as_rod = pendulum(rod_type("rod", mass=m, length=L, position=(x, y), angle=th))
    as_planar = pendulum(PlanarBody("rod", mass=m, inertia=m * L**2 / 12, position=(x, y), angle=th))
    rod, planar = kronlag.derive(as_rod), kronlag.derive(as_planar)
    for name in ("M", "C", "g", "f_Q", "Phi_q"):
        assert sp.simplify(getattr(rod, name) - getattr(planar, name)) == sp.zeros(*getattr(rod, name).shape), name
    text = to_toml(as_rod)
    assert 'type = "rod"' in text and "length = " in text
    again = loads_model(text).system
    assert again.bodies == as_rod.bodies
    with pytest.raises(kronlag.ModelError, match="expected one of planar, rigid, point, rod, got 'bar'"):
        loads_model(text.replace('type = "rod"', 'type = "bar"'))


def test_a_body_type_without_a_file_type_is_not_written():
    system = kronlag.System([th], parameters=[m, L])
    system.add_body(_Rod("rod", mass=m, length=L, position=(sp.cos(th), 0), angle=th))
    with pytest.raises(kronlag.ModelError, match="cannot write the body 'rod' \\(_Rod\\)"):
        to_toml(system)


# -- loads -----------------------------------------------------------------------------------------

def loaded_system() -> kronlag.System:
    system = planar_system(PlanarBody("disc", mass=m, inertia=inertia, position=(x, y), angle=th))
    system.add_spring((x, y), (0, 0), stiffness=k, free_length=L, name="spring")
    system.add_damper((x, y), (0, L), coefficient=c, name="damper")
    system.add_potential(k * th**2 / 2, name="torsion")
    system.add_generalized_force((0, 0, F * kronlag.t), name="drive")
    system.add_force((x, y), (F, 0), name="push")
    system.add_torque("disc", F * thd, name="spin")
    return system


def test_every_load_is_a_type_with_its_file_table():
    system = loaded_system()
    assert [type(load) for load in system.loads] == [Spring, Damper, Potential, GeneralizedForce, PointForce,
                                                      BodyTorque]
    assert {load.file_table for load in system.loads} == set(LOAD_FORMATS)
    assert (system.springs, system.dampers, system.potentials) == tuple((load,) for load in system.loads[:3])
    assert system.forces == tuple(system.loads[3:]) and all(isinstance(f, AppliedForce) for f in system.forces)
    assert system.forces[2].body is system.body("disc")


def test_loads_contribute_their_potential_and_generalized_force():
    equations = kronlag.derive(loaded_system())
    distance = sp.sqrt(x**2 + y**2)
    potential = k * (distance - L) ** 2 / 2 + k * th**2 / 2
    assert sp.simplify(equations.potential_energy - potential) == 0
    separation = sp.Matrix([x, y - L])
    length = sp.sqrt((separation.T * separation)[0, 0])
    rate = (length.diff(x) * xd + length.diff(y) * yd)
    damper = -c * rate * sp.Matrix([length.diff(x), length.diff(y), 0])
    expected = damper + sp.Matrix([F, 0, F * kronlag.t + F * thd])
    assert sp.simplify(equations.f_Q - expected) == sp.zeros(3, 1)


def test_every_load_type_reads_back_from_its_model_file():
    system = loaded_system()
    again = loads_model(to_toml(system)).system
    assert [type(load) for load in again.loads] == [Potential, Spring, Damper, PointForce, BodyTorque,
                                                     GeneralizedForce]
    by_name = {load.name: load for load in again.loads}
    for load in system.loads:
        copy = by_name[load.name]
        if isinstance(load, BodyTorque):
            assert (copy.value, copy.body, copy.frame) == (load.value, load.body, load.frame)
        else:
            assert copy == load


@dataclass(frozen=True)
class _Torsion(Load):
    """A torsion spring ``1/2 k th^2`` on the angle ``th``, not known to model files."""

    name: str

    def potential(self) -> sp.Expr:
        return k * th**2 / 2


def test_a_new_load_type_enters_the_derivation_through_its_methods():
    system = planar_system(PlanarBody("disc", mass=m, inertia=inertia, position=(x, y), angle=th))
    system.loads.append(_Torsion("torsion"))
    assert kronlag.derive(system).g == sp.Matrix([0, 0, k * th])
    with pytest.raises(kronlag.ModelError, match="cannot write the load 'torsion' \\(_Torsion\\)"):
        to_toml(system)


# -- rotations -------------------------------------------------------------------------------------

def test_one_elementary_rotation_and_skew_in_the_plane():
    assert planar_rotation(th) == elementary_rotation("z", th)[:2, :2]
    assert skew((th,)) * sp.Matrix([x, y]) == sp.Matrix([-th * y, th * x])
    assert skew((1, 2, 3)) * sp.Matrix([x, y, th]) == sp.Matrix([1, 2, 3]).cross(sp.Matrix([x, y, th]))


def test_check_rotation_evaluates_large_matrices_numerically():
    angles = sp.symbols("q1:7")
    rotation = sp.ImmutableMatrix(RotationSequence(list(zip("zyxzyx", angles))).matrix)
    check_rotation(rotation, "arm")  # too large to simplify: checked at random points
    skewed = sp.ImmutableMatrix(rotation + sp.Matrix(3, 3, lambda i, j: angles[0] / 100 if i == j == 0 else 0))
    with pytest.raises(kronlag.ModelError, match=r"arm is not orthogonal: \(R\^T R\)\[\d,\d\] = .* at q1="):
        check_rotation(skewed, "arm")
    with pytest.raises(kronlag.ModelError, match=r"R\^T R = 4 I"):
        check_rotation(sp.ImmutableMatrix(2 * sp.eye(3)), "R")
    with pytest.raises(kronlag.ModelError, match="cannot be evaluated at random values of its symbols th"):
        check_rotation(sp.ImmutableMatrix(sp.sqrt(-1 - th**2) * sp.eye(3)), "R")
    with pytest.raises(kronlag.ModelError, match="cannot be evaluated numerically .* complex constant"):
        check_rotation(sp.ImmutableMatrix(sp.I * sp.eye(3)), "R")
