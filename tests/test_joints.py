"""Joints (kronlag.joints): constraint rows against hand derivations, the motions each
spatial joint allows, the paper's four-bar and quick-return written as bodies + joints,
and single joints against sympy.physics.mechanics PinJoint, PrismaticJoint, SphericalJoint."""


import numpy as np
import pytest
import sympy as sp
from helpers import four_bar_by_joints, quick_return_by_joints
from helpers import numeric_by_joints as numeric
from sympy.physics import mechanics as me

import kronlag
from kronlag.core.errors import ModelError
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.model.rotations import euler_sequence

cos, sin = sp.cos, sp.sin



def two_planar_bodies():
    a, b = free_body("a", mass=1, inertia=1), free_body("b", mass=1, inertia=1)
    return mechanism([a, b], parameters=sp.symbols("s1 s2 s3 s4 u1 u2 beta"), gravity=(0, 0)), a, b


def rows(system, joint):
    return [system.constraints[[c.name for c in system.constraints].index(name)].expression
            for name in joint.constraint_names]


def test_planar_joint_rows_match_hand_derivations():
    system, a, b = two_planar_bodies()
    xa, ya, ta = a.coordinates
    xb, yb, tb = b.coordinates
    s1, s2, s3, s4, u1, u2, beta = system.parameters
    pa = sp.Matrix([xa + cos(ta) * s1 - sin(ta) * s2, ya + sin(ta) * s1 + cos(ta) * s2])
    pb = sp.Matrix([xb + cos(tb) * s3 - sin(tb) * s4, yb + sin(tb) * s3 + cos(tb) * s4])
    normal = sp.Matrix([-sin(ta) * u1 - cos(ta) * u2, cos(ta) * u1 - sin(ta) * u2])  # R_A (-u2, u1)
    expected = {
        "revolute": [pb[0] - pa[0], pb[1] - pa[1]],
        "pin_in_slot": [(normal.T * (pb - pa))[0]],
        "prismatic": [(normal.T * (pb - pa))[0], tb - ta - beta],
        "rigid": [pb[0] - pa[0], pb[1] - pa[1], tb - ta - beta],
    }
    suffixes = {"revolute": ["x", "y"], "pin_in_slot": ["normal"], "prismatic": ["normal", "angle"],
                "rigid": ["x", "y", "angle"]}
    options = {"revolute": {}, "pin_in_slot": {"axis": (u1, u2)}, "prismatic": {"axis": (u1, u2), "angle": beta},
               "rigid": {"angle": beta}}
    for kind, hand in expected.items():
        joint = system.add_joint(kind, "a", "b", at_a=(s1, s2), at_b=(s3, s4), **options[kind])
        assert joint.name == f"a_b_{kind}"
        assert joint.constraint_names == tuple(f"a_b_{kind}.{s}" for s in suffixes[kind])
        assert [sp.simplify(x - y) for x, y in zip(rows(system, joint), hand)] == [0] * len(hand)


def test_named_points_serve_as_joint_points():
    system, _, _ = two_planar_bodies()
    s1, s2 = system.parameters[:2]
    system.add_point("pin", "a", (s1, s2))
    system.add_point("hole", "b", (0, s2))
    by_name = system.add_joint("revolute", "a", "b", at_a="pin", at_b="hole", name="by name")
    by_value = system.add_joint("revolute", "a", "b", at_a=(s1, s2), at_b=(0, s2), name="by value")
    assert rows(system, by_name) == rows(system, by_value)
    with pytest.raises(ModelError, match="point 'hole' is on 'b', not on 'a'"):
        system.add_joint("revolute", "a", "b", at_a="hole")


@pytest.mark.parametrize("arguments, message", [
    (("hinge", "a", "b"), "unknown 2-d joint kind 'hinge'"),
    (("revolute", "a", "ground"), "put the ground first"),
    (("revolute", "a", "a"), "to itself"),
    (("prismatic", "a", "b"), "needs axis"),
    (("revolute", "a", "b", {"axis": (1, 0)}), "a 2-d revolute joint does not use axis"),
    (("rigid", "a", "p"), "point mass without one"),
    (("pin_in_slot", "p", "a", {"axis": (1, 0)}), "fixed in body_a, but 'p' is a point mass"),
    (("revolute", "a", "b", {"at_a": (1, 2, 3)}), "expected 2 entries, got 3"),
])
def test_joint_errors_name_the_joint_and_the_problem(arguments, message):
    system = mechanism([free_body("a", mass=1, inertia=1), free_body("b", mass=1, inertia=1),
                        free_body("p", mass=1)])
    *positional, options = arguments if isinstance(arguments[-1], dict) else (*arguments, {})
    with pytest.raises(ModelError, match=message):
        system.add_joint(*positional, **options)


def test_joint_closing_a_loop_of_joint_angle_coordinates_is_eq_24():
    """The paper's four-bar (joint-angle coordinates) with its loop closed by a revolute joint."""
    system = kronlag.models.four_bar()
    system.constraints.clear()
    l2, l3 = sp.symbols("l2 l3")
    joint = system.add_joint("revolute", "coupler", "follower", at_a=(l2 / 2, 0), at_b=(l3 / 2, 0))
    reference = kronlag.models.four_bar().constraints
    # P_B - P_A = C_follower - C_coupler = -(l1 cos q1 + l2 cos q2 - l3 cos q3 - l4, ...) = -f
    assert [sp.simplify(x + y.expression) for x, y in zip(rows(system, joint), reference)] == [0, 0]


# -- whole mechanisms as bodies + joints ---------------------------------------------------------


def matching_state(model, angles, rates, angle_names):
    """Assemble the bodies+joints model with its body angles and their rates held."""
    guess = np.zeros(model.m)
    for name, value in zip(angle_names, angles):
        guess[model.coordinate_names.index(name)] = value
    return model.assemble(guess, fixed=dict(zip(angle_names, angles)), qd_fixed=dict(zip(angle_names, rates)))


@pytest.mark.parametrize("paper, by_joints, guess, angle_names", [
    (kronlag.models.four_bar, four_bar_by_joints, [1.0, 0.5, 1.5], ["theta_crank", "theta_coupler",
                                                                   "theta_follower"]),
    (kronlag.models.quick_return, quick_return_by_joints, [0.3, 1.4, 0.1], ["theta_crank", "theta_rocker",
                                                                           "theta_link"]),
])
@pytest.mark.parametrize("crank", [0.3, 1.0, 2.5])
def test_mechanism_by_joints_has_the_papers_dynamics(paper, by_joints, guess, angle_names, crank):
    """Same accelerations of the paper's coordinates (the body angles) at consistent states."""
    reference = numeric(paper, paper.__name__)
    model = numeric(by_joints, paper.__name__)
    first = reference.coordinate_names[0]
    guess[0] = crank
    q, qd = reference.assemble(guess, fixed={first: crank}, qd_fixed={first: 4.0})
    Q, QD = matching_state(model, q, qd, angle_names)
    expected = reference.forward_dynamics(q, qd).qdd
    result = model.forward_dynamics(Q, QD).qdd
    angles = [model.coordinate_names.index(name) for name in angle_names]
    assert np.allclose(result[angles], expected, rtol=1e-9, atol=1e-9 * np.max(np.abs(expected)))


def test_four_bar_by_joints_simulates_like_the_paper():
    reference, model = numeric(kronlag.models.four_bar, "four_bar"), numeric(four_bar_by_joints, "four_bar")
    q, qd = reference.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 6.0})
    Q, QD = matching_state(model, q, qd, ["theta_crank", "theta_coupler", "theta_follower"])
    times = np.linspace(0, 0.5, 11)
    options = dict(method="projection", rtol=1e-10, atol=1e-12, t_eval=times)
    a = kronlag.simulate(reference, (0, 0.5), q, qd, **options)
    b = kronlag.simulate(model, (0, 0.5), Q, QD, **options)
    assert a.success and b.success
    assert np.allclose(b.q[:, model.coordinate_names.index("theta_crank")], a.q[:, 0], atol=1e-6)


# -- spatial joints: the relative motions they allow ---------------------------------------------


AXIS = sp.Matrix([1, 2, 2]) / 3
CROSS = sp.Matrix([2, -2, 1]) / 3  # perpendicular to AXIS


def spatial_joint(kind):
    body = free_body("b", mass=1, inertia=sp.eye(3), dimension=3, rotation="xyz", simplify=False)
    system = mechanism([body], gravity=(0, 0, -1))
    at_a, at_b = (0.2, -0.1, 0.3), (0.5, 0.1, -0.2)
    options = {"universal": dict(axis=AXIS, axis_b=CROSS)}.get(kind, dict(axis=AXIS) if kind != "spherical" and
                                                                 kind != "rigid" else {})
    system.add_joint(kind, "ground", "b", at_a=at_a, at_b=at_b, **options)
    return system, body, sp.Matrix(at_b)


def assembled(system, seed=1):
    """Newton on Phi(q) = 0 from a start where the body frame is near the ground's."""
    q = list(system.coordinates)
    phi = sp.Matrix([c.expression for c in system.constraints])
    f, jac = sp.lambdify([q], phi, "numpy"), sp.lambdify([q], phi.jacobian(q), "numpy")
    x = np.random.default_rng(seed).normal(scale=0.3, size=len(q))
    for _ in range(100):
        x = x - np.linalg.lstsq(jac(x), f(x).ravel(), rcond=None)[0]
    assert np.max(np.abs(f(x))) < 1e-12
    return x, jac(x)


#: kind -> (degrees of freedom, conditions on the twist (v of B's joint point, omega) in world components)
ALLOWED = {
    "spherical": (3, lambda v, w, R: [v]),
    "revolute": (1, lambda v, w, R: [v, np.cross(w, AXIS_N)]),
    "cylindrical": (2, lambda v, w, R: [np.cross(v, AXIS_N), np.cross(w, AXIS_N)]),
    "prismatic": (1, lambda v, w, R: [np.cross(v, AXIS_N), w]),
    "universal": (2, lambda v, w, R: [v, [w @ np.cross(AXIS_N, R @ CROSS_N)]]),
    "rigid": (0, lambda v, w, R: [v, w]),
}
AXIS_N = np.array(AXIS, dtype=float).ravel()
CROSS_N = np.array(CROSS, dtype=float).ravel()


@pytest.mark.parametrize("kind", list(ALLOWED))
def test_spatial_joint_allows_exactly_its_relative_motion(kind):
    system, body, at_b = spatial_joint(kind)
    x, jacobian = assembled(system)
    dof, conditions = ALLOWED[kind]
    _, singular, vt = np.linalg.svd(jacobian)
    rank = int(np.sum(singular > 1e-9))
    assert 6 - rank == dof
    q = list(system.coordinates)
    rotation = sp.Matrix(body.body.rotation)
    point = sp.Matrix(body.body.position) + rotation * at_b
    R = np.array(sp.lambdify([q], rotation)(x), dtype=float)
    point_jacobian = np.array(sp.lambdify([q], point.jacobian(q))(x), dtype=float)
    rotation_derivatives = [np.array(sp.lambdify([q], rotation.diff(qk))(x), dtype=float) for qk in q]
    for direction in vt[rank:]:
        v = point_jacobian @ direction
        spin = sum(d * dR for d, dR in zip(direction, rotation_derivatives)) @ R.T
        w = np.array([spin[2, 1], spin[0, 2], spin[1, 0]])
        for residual in conditions(v, w, R):
            assert np.allclose(residual, 0, atol=1e-9)


def test_spatial_axes_must_be_numbers():
    body = free_body("b", mass=1, inertia=sp.eye(3), dimension=3, rotation="xyz")
    system = mechanism([body], parameters=[sp.Symbol("k")])
    with pytest.raises(ModelError, match="must be numbers"):
        system.add_joint("revolute", "ground", "b", axis=(sp.Symbol("k"), 0, 1))


# -- single joints against sympy.physics.mechanics ---------------------------------------------


def mechanics_accelerations(joint, bodies, gravity, values, state):
    """``u'`` of a sympy.physics.mechanics System of one joint at a state (u = q' for these joints)."""
    ground = joint.parent
    system = me.System.from_newtonian(ground)
    system.add_joints(joint)
    system.apply_uniform_gravity(gravity)
    system.form_eoms()
    q, u = list(joint.coordinates), list(joint.speeds)
    substitution = {**values, **dict(zip(q, state[0])), **dict(zip(u, state[1]))}
    M = system.mass_matrix_full.subs(substitution)
    F = system.forcing_full.subs(substitution)
    return np.array(M.LUsolve(F), dtype=float).ravel()[len(q):]


def test_planar_revolute_against_pin_joint():
    m, L, Izz, g = sp.symbols("m L Izz g")
    values = {m: 2.0, L: 0.8, Izz: 0.3, g: 9.81}
    ground, bar = me.RigidBody("ground"), me.RigidBody("bar", mass=m)
    bar.central_inertia = me.inertia(bar.frame, 0, 0, Izz)
    pin = me.PinJoint("P", ground, bar, child_point=L / 2 * bar.frame.x, joint_axis=ground.frame.z)
    expected = mechanics_accelerations(pin, [bar], -g * ground.frame.y, values, ([0.7], [1.3]))

    system = mechanism([free_body("bar", mass=m, inertia=Izz)], parameters=[m, L, Izz, g], gravity=(0, -g))
    system.add_joint("revolute", "ground", "bar", at_b=(L / 2, 0))
    model = kronlag.derive(system).numeric({s.name: v for s, v in values.items()}, backend="python")
    q, qd = model.assemble([0, 0, 0.7], fixed={"theta_bar": 0.7}, qd_fixed={"theta_bar": 1.3})
    assert np.isclose(model.forward_dynamics(q, qd).qdd[2], expected[0], rtol=1e-10)


def test_planar_prismatic_against_prismatic_joint():
    m, Izz, g, beta = sp.symbols("m Izz g beta")
    values = {m: 2.0, Izz: 0.3, g: 9.81, beta: 0.4}
    ground, block = me.RigidBody("ground"), me.RigidBody("block", mass=m)
    block.central_inertia = me.inertia(block.frame, 0, 0, Izz)
    axis = cos(beta) * ground.frame.x + sin(beta) * ground.frame.y
    slider = me.PrismaticJoint("S", ground, block, joint_axis=axis)
    expected = mechanics_accelerations(slider, [block], -g * ground.frame.y, values, ([0.1], [0.5]))

    system = mechanism([free_body("block", mass=m, inertia=Izz)], parameters=[m, Izz, g, beta], gravity=(0, -g))
    system.add_joint("prismatic", "ground", "block", axis=(cos(beta), sin(beta)))
    model = kronlag.derive(system).numeric({s.name: v for s, v in values.items()}, backend="python")
    q, qd = model.assemble([0.1, 0.1, 0.0], qd_guess=[0.5, 0.5, 0])
    direction = np.array([np.cos(0.4), np.sin(0.4)])
    assert np.isclose(model.forward_dynamics(q, qd).qdd[:2] @ direction, expected[0], rtol=1e-10)


def test_spatial_spherical_against_spherical_joint():
    m, L, g, Ixx, Iyy, Izz = sp.symbols("m L g Ixx Iyy Izz")
    values = {m: 1.5, L: 0.6, g: 9.81, Ixx: 0.05, Iyy: 0.07, Izz: 0.02}
    angles, rates = [0.3, -0.4, 0.5], [0.7, -0.2, 0.4]
    ground, bar = me.RigidBody("ground"), me.RigidBody("bar", mass=m)
    bar.central_inertia = me.inertia(bar.frame, Ixx, Iyy, Izz)
    ball = me.SphericalJoint("S", ground, bar, child_point=L / 2 * bar.frame.z)  # body-fixed x, y, z angles
    expected = mechanics_accelerations(ball, [bar], -g * ground.frame.z, values, (angles, rates))

    body = free_body("bar", mass=m, inertia=sp.diag(Ixx, Iyy, Izz), dimension=3, rotation="xyz")
    system = mechanism([body], parameters=[m, L, g, Ixx, Iyy, Izz], gravity=(0, 0, -g))
    system.add_joint("spherical", "ground", "bar", at_b=(0, 0, L / 2))
    model = kronlag.derive(system).numeric({s.name: v for s, v in values.items()}, backend="python")
    names = ["phi1_bar", "phi2_bar", "phi3_bar"]
    R = np.array(euler_sequence("xyz", angles), dtype=float)
    guess = np.concatenate([-R @ [0, 0, 0.3], angles])
    q, qd = model.assemble(guess, fixed=dict(zip(names, angles)), qd_fixed=dict(zip(names, rates)))
    assert np.allclose(model.forward_dynamics(q, qd).qdd[3:], expected, rtol=1e-9)


def test_euler_parameter_body_moves_like_the_cardan_angle_body():
    """A body on a spherical joint: Euler parameters (with their normalization constraint) and
    Cardan angles give the same centre-of-mass acceleration from the same orientation and spin."""
    from scipy.spatial.transform import Rotation

    m, L, g = sp.symbols("m L g")
    values = {"m": 1.5, "L": 0.6, "g": 9.81}

    def model(rotation):
        body = free_body("bar", mass=m, inertia=sp.diag(0.05, 0.07, 0.02), dimension=3, rotation=rotation)
        system = mechanism([body], parameters=[m, L, g], gravity=(0, 0, -g))
        system.add_joint("spherical", "ground", "bar", at_b=(0, 0, L / 2))
        return kronlag.derive(system).numeric(values, backend="python")

    cardan, quaternion = model("xyz"), model("euler_parameters")
    assert "bar.normalization" in [c.name for c in quaternion.equations.system.constraints]
    angles, rates = [0.3, -0.4, 0.5], [0.7, -0.2, 0.4]
    R = np.array(euler_sequence("xyz", angles), dtype=float)
    names = ["phi1_bar", "phi2_bar", "phi3_bar"]
    q, qd = cardan.assemble(np.concatenate([-R @ [0, 0, 0.3], angles]), fixed=dict(zip(names, angles)),
                            qd_fixed=dict(zip(names, rates)))
    symbols = sp.symbols("a b c")
    rotation = euler_sequence("xyz", symbols)
    spin = rotation.T * sum((rotation.diff(s) * rate for s, rate in zip(symbols, rates)), sp.zeros(3))
    spin = np.array(spin.subs(dict(zip(symbols, angles))), dtype=float)
    omega = np.array([spin[2, 1], spin[0, 2], spin[1, 0]])  # body components
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    e = np.array([w, x, y, z])
    e_rate = 0.5 * np.array([-e[1:] @ omega, *(e[0] * omega + np.cross(e[1:], omega))])  # e (x) (0, omega) / 2
    parameters = ["e0_bar", "e1_bar", "e2_bar", "e3_bar"]
    Q, QD = quaternion.assemble(np.concatenate([q[:3], e]), fixed=dict(zip(parameters, e)),
                                qd_guess=np.concatenate([qd[:3], e_rate]), qd_fixed=dict(zip(parameters, e_rate)))
    assert np.allclose(quaternion.forward_dynamics(Q, QD).qdd[:3], cardan.forward_dynamics(q, qd).qdd[:3],
                       rtol=1e-9)
