"""Rotations, frames and body points (kronlag.frames) against independent references:
sympy.physics.vector orientations, direct differentiation in time, finite differences."""

import numpy as np
import pytest
import sympy as sp
from helpers import assert_numerically_equal
from sympy.physics.mechanics import ReferenceFrame, dynamicsymbols

import kronlag
from kronlag import frames
from kronlag.core.errors import ModelError

a, b, c = sp.symbols("a b c")


def is_rotation(R) -> bool:
    return sp.simplify(R.T * R - sp.eye(R.rows)) == sp.zeros(R.rows) and sp.simplify(R.det()) == 1


@pytest.mark.parametrize("axis", "xyz")
def test_elementary_rotations_match_sympy_vector(axis):
    N = ReferenceFrame("N")
    B = N.orientnew("B", "Axis", (a, getattr(N, axis)))
    # sympy's dcm(N) maps N components to B components; kronlag's R maps body to world: R = B.dcm(N)^T
    assert sp.simplify(frames.elementary_rotation(axis, a) - B.dcm(N).T) == sp.zeros(3)
    assert is_rotation(frames.elementary_rotation(axis, a))


def test_axis_angle_matches_sympy_vector_for_a_skew_axis():
    N = ReferenceFrame("N")
    B = N.orientnew("B", "Axis", (a, (N.x + 2 * N.y - 2 * N.z) / 3))
    assert_numerically_equal(frames.axis_angle((1, 2, -2), a), B.dcm(N).T, {a})
    with pytest.raises(ModelError, match="zero vector"):
        frames.axis_angle((0, 0, 0), a)


@pytest.mark.parametrize("axes", ["zxz", "xyz", "zyx", "yzy"])
def test_euler_sequences_match_sympy_vector(axes):
    N = ReferenceFrame("N")
    intrinsic = N.orientnew("B", "Body", (a, b, c), axes.upper())
    extrinsic = N.orientnew("C", "Space", (a, b, c), axes.upper())
    assert_numerically_equal(frames.euler_sequence(axes, (a, b, c)), intrinsic.dcm(N).T, {a, b, c})
    assert_numerically_equal(frames.euler_sequence(axes, (a, b, c), extrinsic=True), extrinsic.dcm(N).T,
                             {a, b, c})


def test_euler_sequence_errors_name_the_problem():
    with pytest.raises(ModelError, match="x, y, z"):
        frames.euler_sequence("xw", (a, b))
    with pytest.raises(ModelError, match="need 3 angles, got 2"):
        frames.euler_sequence("zxz", (a, b))


def test_euler_parameters_are_the_half_angle_quaternion_of_axis_angle():
    u = sp.Matrix([2, -1, 2]) / 3
    e0, e1, e2, e3 = sp.cos(a / 2), *(sp.sin(a / 2) * u)
    assert_numerically_equal(frames.euler_parameters(e0, e1, e2, e3), frames.axis_angle(u, a), {a})
    assert sp.simplify(frames.euler_parameter_constraint(e0, e1, e2, e3)) == 0
    N = ReferenceFrame("N")
    B = N.orientnew("B", "Quaternion", (e0, e1, e2, e3))
    assert_numerically_equal(frames.euler_parameters(e0, e1, e2, e3), B.dcm(N).T, {a})


def test_frame_composition_and_inverse():
    parent = kronlag.Frame((1, a, 0), frames.elementary_rotation("z", b))
    child = kronlag.Frame((c, 0, 2), frames.elementary_rotation("x", a))
    local = sp.Matrix([1, 2, 3])
    assert sp.simplify((parent * child).point(local) - parent.point(child.point(local))) == sp.zeros(3, 1)
    assert sp.simplify((parent * parent.inverse()).origin) == sp.zeros(3, 1)
    assert sp.simplify((parent * parent.inverse()).rotation) == sp.eye(3)
    with pytest.raises(ModelError, match="2-d frame"):
        _ = parent * kronlag.Frame((0, 0))


def test_body_point_velocity_and_acceleration_are_time_derivatives():
    """Theorem 1 against differentiating r(q(t)) in time directly."""
    q1, q2 = kronlag.coordinates("q1 q2")
    l, m, inertia = sp.symbols("l m I")
    body = kronlag.PlanarBody("bar", mass=m, inertia=inertia, position=(q1, l * sp.sin(q2)), angle=q2)
    r = frames.body_point(body, (l / 2, l / 3))
    v, acc = frames.point_velocity(r, [q1, q2]), frames.point_acceleration(r, [q1, q2])
    f1, f2 = dynamicsymbols("f1 f2")
    in_time = {q1: f1, q2: f2}
    direct_v = r.subs(in_time).diff(dynamicsymbols._t)
    direct_a = direct_v.diff(dynamicsymbols._t)
    back = {f1.diff(dynamicsymbols._t, 2): sp.Symbol("q1dd"), f2.diff(dynamicsymbols._t, 2): sp.Symbol("q2dd"),
            f1.diff(dynamicsymbols._t): sp.Symbol("q1d"), f2.diff(dynamicsymbols._t): sp.Symbol("q2d"),
            f1: q1, f2: q2}
    assert sp.simplify(v - direct_v.subs(back)) == sp.zeros(2, 1)
    assert sp.simplify(acc - direct_a.subs(back)) == sp.zeros(2, 1)


def test_point_on_a_point_mass_must_be_its_position():
    particle = kronlag.PointMass("p", mass=1, position=(a, b))
    assert frames.body_point(particle, (0, 0)) == sp.Matrix([a, b])
    with pytest.raises(ModelError, match="no extent"):
        frames.body_point(particle, (1, 0))


def test_named_points_numerically_against_finite_differences():
    system = kronlag.models.four_bar()
    l1, l2 = sp.symbols("l1 l2")
    system.add_point("coupler tip", "coupler", (l2 / 2, 0))
    system.add_point("pivot D", "ground", (sp.Symbol("l4"), 0))
    with pytest.raises(ModelError, match="duplicate point"):
        system.add_point("pivot D", "ground", (0, 0))
    with pytest.raises(ModelError, match="no body named 'shaft'"):
        system.add_point("x", "shaft", (0, 0))
    values = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1, m2=3, m3=2.5, I1=0.0033, I2=0.09, I3=0.052, g=9.81,
                  tau=0.0)
    model = kronlag.derive(system).numeric(values, backend="python")
    q, qd, qdd = np.array([1.0, 0.5, 1.5]), np.array([0.3, -0.7, 1.1]), np.array([2.0, 0.4, -1.0])
    state = model.point_state("coupler tip", q, qd, qdd)
    tip = lambda x: np.array([0.2 * np.cos(x[0]) + 0.6 * np.cos(x[1]), 0.2 * np.sin(x[0]) + 0.6 * np.sin(x[1])])
    assert np.allclose(state["position"], tip(q), atol=1e-14)
    h = 1e-5
    path = lambda s: tip(q + s * qd + s ** 2 / 2 * qdd)
    assert np.allclose(state["velocity"], (path(h) - path(-h)) / (2 * h), atol=1e-8)
    assert np.allclose(state["acceleration"], (path(h) - 2 * path(0) + path(-h)) / h ** 2, atol=1e-4)
    assert np.allclose(model.point_position("pivot D", q), [0.5, 0.0])


@pytest.mark.parametrize("seed", range(6))
def test_euler_parameters_of_inverts_euler_parameters(seed):
    rng = np.random.default_rng(seed)
    e = rng.normal(size=4)
    e[rng.integers(4)] *= 20  # each of e0..e3 the largest in turn (rotations near 180 degrees too)
    e = e / np.linalg.norm(e) * np.sign(e[0])
    R = np.array(frames.euler_parameters(*e), dtype=float)
    assert np.allclose(frames.euler_parameters_of(R), e, atol=1e-12)
    with pytest.raises(ModelError, match="rotation matrix"):
        frames.euler_parameters_of(2 * R)
