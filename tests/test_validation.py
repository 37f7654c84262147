"""Every validation of kronlag.System raises ModelError naming the offending item."""

import pytest
import sympy as sp

import kronlag
from kronlag import ModelError, PlanarBody, PointMass, RigidBody, System

cos, sin = sp.cos, sp.sin
q1, q2 = sp.symbols("q1 q2")
q1d, q2d = sp.symbols("q1d q2d")
m, l, g, inertia = sp.symbols("m l g inertia")


def planar_system(**keywords) -> System:
    """A pendulum-like system with coordinates q1, q2 and parameters m, l, g, inertia."""
    return System([q1, q2], parameters=[m, l, g, inertia], **keywords)


def rod(name: str = "rod", **changes) -> PlanarBody:
    fields = {"mass": m, "inertia": inertia, "position": (l * cos(q1), l * sin(q1)), "angle": q1} | changes
    return PlanarBody(name, **fields)


def with_rod() -> System:
    system = planar_system()
    system.add_body(rod())
    return system


def with_bob() -> System:
    """A system with the point mass 'bob'."""
    system = planar_system()
    system.add_body(PointMass("bob", mass=m, position=(q1, q2)))
    return system


def with_constraint(name: str) -> System:
    system = planar_system()
    system.add_constraint(q1 - q2, name=name)
    return system


INVALID = {
    "undeclared symbol in a body position":
        (lambda: planar_system().add_body(rod(position=(l * cos(q1), sp.Symbol("z")))),
         r"body 'rod' position uses a symbol that is neither a coordinate nor a declared parameter.*: z"),
    "speed in a body position":
        (lambda: planar_system().add_body(rod(position=(l * q1d, 0))),
         r"body 'rod' position may not depend on the speeds"),
    "mass depending on q":
        (lambda: planar_system().add_body(rod(mass=m * q1)), r"body 'rod' mass may not depend on the coordinates: q1"),
    "inertia depending on q":
        (lambda: planar_system().add_body(rod(inertia=inertia * cos(q2))),
         r"body 'rod' inertia may not depend on the coordinates: q2"),
    "string instead of an expression":
        (lambda: rod(mass="m"), r"body 'rod' mass: got the string 'm'"),
    "planar body position of length 3":
        (lambda: rod(position=(q1, q2, 0)), r"body 'rod' position: expected a vector of length 2, got length 3"),
    "gravity of length 4":
        (lambda: planar_system(gravity=(0, 0, -g, 0)), r"gravity: expected a vector of length 2 or 3, got length 4"),
    "gravity depending on q":
        (lambda: planar_system(gravity=(0, -g * q1)), r"gravity may not depend on the coordinates: q1"),
    "2-D body with 3-D gravity":
        (lambda: planar_system(gravity=(0, 0, -g)).add_body(rod()),
         r"body 'rod' is 2-dimensional but the system is 3-dimensional"),
    "3-D body beside a 2-D body":
        (lambda: with_rod().add_body(PointMass("bob", mass=m, position=(q1, q2, 0))),
         r"body 'bob' is 3-dimensional but the system is 2-dimensional"),
    "duplicate body names":
        (lambda: with_rod().add_body(rod()), r"duplicate body name 'rod'"),
    "non-symmetric inertia tensor":
        (lambda: RigidBody("top", mass=m, inertia=sp.Matrix([[1, 2, 0], [0, 1, 0], [0, 0, 1]]),
                           position=(0, 0, l), rotation=sp.eye(3)),
         r"body 'top' inertia tensor is not symmetric: entry \[0,1\]"),
    "inertia tensor of the wrong shape":
        (lambda: RigidBody("top", mass=m, inertia=sp.eye(2), position=(0, 0, l), rotation=sp.eye(3)),
         r"body 'top' inertia tensor: expected shape \(3, 3\)"),
    "constraint not depending on q":
        (lambda: planar_system().add_constraint(l - 1, name="fixed"),
         r"constraint 'fixed' does not depend on any coordinate"),
    "holonomic constraint containing speeds":
        (lambda: planar_system().add_constraint(q1 - q1d, name="rolling"), r"constraint 'rolling' contains speeds"),
    "drive motion depending on the coordinates":
        (lambda: planar_system().add_drive("q1", q2 * kronlag.t, name="driven"),
         r"drive 'driven' motion may not depend on the coordinates: q2"),
    "drive of an unknown coordinate":
        (lambda: planar_system().add_drive("q9", kronlag.t), r"drive of 'q9': no such coordinate"),
    "nonholonomic constraint not linear in qd":
        (lambda: planar_system().add_nonholonomic_constraint(q1d * q2d + q1d, name="knife"),
         r"nonholonomic constraint 'knife' is not linear in the speeds: its coefficient of q1d is q2d \+ 1"),
    "nonholonomic constraint with a nonlinear function of qd":
        (lambda: planar_system().add_nonholonomic_constraint(sin(q1d), name="knife"),
         r"nonholonomic constraint 'knife' is not linear in the speeds"),
    "nonholonomic constraint without speeds":
        (lambda: planar_system().add_nonholonomic_constraint(q1 - q2, name="knife"),
         r"nonholonomic constraint 'knife' does not depend on any speed"),
    "duplicate constraint names":
        (lambda: with_constraint("c").add_constraint(q2, name="c"), r"duplicate constraint name 'c'"),
    "torque on a point mass":
        (lambda: with_bob().add_torque("bob", g, name="spin"), r"torque 'spin' acts on point mass 'bob'"),
    "torque on an unknown body":
        (lambda: with_rod().add_torque("crank", g), r"no body named 'crank'"),
    "vector torque on a planar body":
        (lambda: with_rod().add_torque("rod", (0, 0, g), name="spin"),
         r"torque 'spin' on planar body 'rod' must be a scalar"),
    "generalized force of the wrong length":
        (lambda: planar_system().add_generalized_force((g, g, g), name="push"),
         r"generalized force 'push': expected a vector of length 2, got length 3"),
    "parameter named like a generated speed":
        (lambda: System([q1], parameters=[sp.Symbol("q1d")]), r"the name 'q1d' is used twice: speed of coordinate q1"),
    "parameter named like a generated acceleration":
        (lambda: System([q1], parameters=[sp.Symbol("q1dd")]), r"the name 'q1dd' is used twice"),
    "parameter named t":
        (lambda: System([q1], parameters=[sp.Symbol("t")]), r"the name 't' is used twice: the time symbol"),
    "reserved holonomic multiplier name":
        (lambda: System([q1], parameters=[sp.Symbol("lambda1")]), r"parameter lambda1: the name 'lambda1' is reserved"),
    "reserved nonholonomic multiplier name":
        (lambda: System([sp.Symbol("mu2")]), r"coordinate mu2: the name 'mu2' is reserved"),
    "duplicate coordinate":
        (lambda: System([q1, q1]), r"the name 'q1' is used twice"),
    "coordinate that is not a symbol":
        (lambda: System([q1 + q2]), r"coordinate q1 \+ q2 is not a SymPy Symbol"),
    "no coordinates":
        (lambda: System([]), r"at least one coordinate"),
    "coordinate that is a Dummy":
        (lambda: System([sp.Dummy("q1")]), r"coordinate q1 is a Dummy"),
    "symbol with assumptions named like a parameter":
        (lambda: planar_system().add_body(rod(mass=sp.Symbol("m", positive=True))),
         r"body 'rod' mass uses a symbol that has the name of a declared one but other assumptions.*: m"),
}


@pytest.mark.parametrize(("build", "message"), INVALID.values(), ids=INVALID.keys())
def test_invalid_model_raises_model_error(build, message):
    with pytest.raises(ModelError, match=message):
        build()


def test_symbols_keep_their_assumptions():
    """The derived matrices contain the user's own symbols, assumptions included."""
    angle = sp.Symbol("q1", real=True)
    mass, length, gravity = sp.symbols("m l g", positive=True)
    system = System([angle], parameters=[mass, length, gravity], gravity=(0, -gravity))
    system.add_body(kronlag.PointMass("bob", mass=mass, position=(length * cos(angle), length * sin(angle))))
    equations = kronlag.derive(system)
    assert equations.M.diff(mass) != sp.zeros(1, 1)
    assert equations.g[0].free_symbols == {angle, mass, length, gravity}
    assert equations.subs({mass: 2, length: 1, gravity: 3}).g == sp.Matrix([6 * cos(angle)])


def test_time_is_allowed_in_forces():
    """``kronlag.t`` may appear in applied forces and torques, and reaches f_Q."""
    system = with_rod()
    system.add_torque("rod", g * sin(kronlag.t), name="drive")
    system.add_generalized_force((0, m * kronlag.t), name="push")
    system.add_force((l * cos(q1), l * sin(q1)), (g * kronlag.t, 0), name="pull")
    f_Q = kronlag.derive(system).f_Q
    expected = sp.Matrix([g * sin(kronlag.t) - l * sin(q1) * g * kronlag.t, m * kronlag.t])
    assert (f_Q - expected).applyfunc(sp.expand) == sp.zeros(2, 1)


def test_speeds_are_allowed_in_forces():
    system = with_rod()
    system.add_generalized_force((-m * q1d, 0), name="friction")
    assert kronlag.derive(system).f_Q == sp.Matrix([-m * q1d, 0])


def test_valid_nonholonomic_constraint_gives_A_and_b():
    system = with_rod()
    system.add_nonholonomic_constraint(cos(q2) * q1d + l * q2d + sin(q1), name="knife")
    equations = kronlag.derive(system)
    assert equations.A == sp.Matrix([[cos(q2), l]])
    assert equations.b == sp.Matrix([sin(q1)])
