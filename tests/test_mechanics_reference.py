"""kronlag against an independent derivation with sympy.physics.mechanics.

Each reference model is built here from scratch (frames, points, bodies,
geometric constraints) and run through ``LagrangesMethod``, whose equations are::

    M qdd - forcing + J^T lam = 0,   J = d(coneqs)/d(qd) = -lam_coeffs

(``lm.eom``; its ``mass_matrix`` augments M with ``lam_coeffs^T``, i.e. uses
``-lam``).  The constraints are formed here from the geometry, so each row of
J is ``±1`` times the matching row of kronlag's ``[Phi_q; A]``; the sign is
recorded per row as ``scales``.
"""

import functools
from dataclasses import dataclass

import pytest
import sympy as sp
from helpers import assert_numerically_equal, derived, state_symbols
from sympy.physics.mechanics import (
    LagrangesMethod,
    Lagrangian,
    Particle,
    Point,
    ReferenceFrame,
    RigidBody,
    dynamicsymbols,
    inertia,
)

t = dynamicsymbols._t


@dataclass(frozen=True)
class Reference:
    method: LagrangesMethod
    coordinates: list  # dynamicsymbols, in kronlag's order
    scales: list[int]  # row j of J = scales[j] * row j of [Phi_q; A]


def planar_bar(name, frame, start, length, mass, moment):
    """A uniform bar from ``start`` along ``frame.x``: its rigid body and its far end."""
    centre = start.locatenew(f"G_{name}", length / 2 * frame.x)
    end = start.locatenew(f"end_{name}", length * frame.x)
    return RigidBody(name, centre, frame, mass, (inertia(frame, 0, 0, moment), centre)), end


def lagranges_method(coordinates, inertial, origin, bodies, forces=(), scales=(), **constraints) -> Reference:
    """Set every velocity from positions relative to the fixed ``origin`` and form the equations."""
    origin.set_vel(inertial, 0)
    for body in bodies:
        point = body.masscenter
        point.set_vel(inertial, point.pos_from(origin).dt(inertial))
    method = LagrangesMethod(Lagrangian(inertial, *bodies), coordinates, forcelist=list(forces) or None,
                             frame=inertial, **constraints)
    method.form_lagranges_equations()
    return Reference(method, coordinates, list(scales))


def four_bar() -> Reference:
    q1, q2, q3 = dynamicsymbols("q1 q2 q3")
    l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau = sp.symbols("l1 l2 l3 l4 m1 m2 m3 I1 I2 I3 g tau")
    N = ReferenceFrame("N")
    frames = [N.orientnew(f"F{k}", "Axis", (q, N.z)) for k, q in enumerate((q1, q2, q3))]
    A = Point("A")
    crank, B = planar_bar("crank", frames[0], A, l1, m1, I1)
    coupler, C = planar_bar("coupler", frames[1], B, l2, m2, I2)
    follower, C_follower = planar_bar("follower", frames[2], A.locatenew("D", l4 * N.x), l3, m3, I3)
    gap = C.pos_from(A) - C_follower.pos_from(A)  # loop closure: equals (f1, f2) of Eq. 24
    bodies = [crank, coupler, follower]
    forces = [(body.masscenter, -body.mass * g * N.y) for body in bodies] + [(frames[0], tau * N.z)]
    return lagranges_method([q1, q2, q3], N, A, bodies, forces, scales=[1, 1],
                            hol_coneqs=[gap.dot(N.x), gap.dot(N.y)])


def quick_return() -> Reference:
    phi1, phi2, phi3 = dynamicsymbols("phi1 phi2 phi3")
    l_BC, l_AB, l_AE, l_EF, l_AH = sp.symbols("l_BC l_AB l_AE l_EF l_AH")
    m1, m2, m3, m4, m5, I1, I2, I3, g, tau = sp.symbols("m1 m2 m3 m4 m5 I1 I2 I3 g tau")
    N = ReferenceFrame("N")
    crank_frame, rocker_frame, link_frame = (N.orientnew(f"F{k}", "Axis", (q, N.z))
                                             for k, q in enumerate((phi1, phi2, phi3)))
    A = Point("A")
    crank, C = planar_bar("crank", crank_frame, A.locatenew("B", l_AB * N.y), l_BC, m1, I1)
    rocker, E = planar_bar("rocker", rocker_frame, A, l_AE, m2, I2)
    link, F = planar_bar("link", link_frame, E, l_EF, m3, I3)
    slider_D = Particle("slider_D", C, m4)
    slider_G = Particle("slider_G", A.locatenew("G", F.pos_from(A).dot(N.x) * N.x + l_AH * N.y), m5)
    bodies = [crank, rocker, link, slider_D, slider_G]
    forces = [(body.masscenter, -body.mass * g * N.y) for body in bodies] + [(crank_frame, tau * N.z)]
    # F on the guide y = l_AH, and the crank pin C on the line AE: -f1 and -f2 of Eq. 37.
    constraints = [F.pos_from(A).dot(N.y) - l_AH, C.pos_from(A).cross(rocker_frame.x).dot(N.z)]
    return lagranges_method([phi1, phi2, phi3], N, A, bodies, forces, scales=[-1, -1], hol_coneqs=constraints)


def double_pendulum() -> Reference:
    q1, q2 = dynamicsymbols("q1 q2")
    l1, l2, m1, m2, I1, I2, g = sp.symbols("l1 l2 m1 m2 I1 I2 g")
    N = ReferenceFrame("N")
    # H_k.x = (sin q_k, -cos q_k): rod k at the angle q_k from the downward vertical.
    hanging = [N.orientnew(f"H{k}", "Axis", (q - sp.pi / 2, N.z)) for k, q in enumerate((q1, q2))]
    O = Point("O")
    rod1, elbow = planar_bar("rod1", hanging[0], O, l1, m1, I1)
    rod2, _ = planar_bar("rod2", hanging[1], elbow, l2, m2, I2)
    forces = [(body.masscenter, -body.mass * g * N.y) for body in (rod1, rod2)]
    return lagranges_method([q1, q2], N, O, [rod1, rod2], forces)


def heavy_top() -> Reference:
    psi, theta, phi = dynamicsymbols("psi theta phi")
    m, l, g, Ixx, Izz = sp.symbols("m l g Ixx Izz")
    N, B = ReferenceFrame("N"), ReferenceFrame("B")
    B.orient_body_fixed(N, (psi, theta, phi), "zxz")
    O = Point("O")
    P = O.locatenew("P", l * B.z)
    top = RigidBody("top", P, B, m, (inertia(B, Ixx, Ixx, Izz), P))
    return lagranges_method([psi, theta, phi], N, O, [top], [(top.masscenter, -m * g * N.z)])


def chaplygin_sleigh() -> Reference:
    x, y, theta = dynamicsymbols("x y theta")
    m, I, a = sp.symbols("m I a")
    N = ReferenceFrame("N")
    A = N.orientnew("A", "Axis", (theta, N.z))
    O = Point("O")
    P = O.locatenew("P", x * N.x + y * N.y)
    sleigh = RigidBody("sleigh", P, A, m, (inertia(A, 0, 0, I), P))
    blade_velocity = P.locatenew("blade", -a * A.x).pos_from(O).dt(N)
    # The blade cannot slide sideways: -sin(theta) xd + cos(theta) yd - a thetad.
    return lagranges_method([x, y, theta], N, O, [sleigh], scales=[1], nonhol_coneqs=[blade_velocity.dot(A.y)])


REFERENCES = {builder.__name__: functools.cache(builder)
              for builder in (four_bar, quick_return, double_pendulum, heavy_top, chaplygin_sleigh)}


@pytest.fixture(params=list(REFERENCES))
def pair(request):
    """``(kronlag equations, sympy reference, function mapping sympy expressions to kronlag symbols)``."""
    equations, reference = derived(request.param), REFERENCES[request.param]()
    functions = reference.coordinates
    assert [f.name for f in functions] == [q.name for q in equations.coordinates]
    steps = [{f.diff(t, 2): qdd for f, qdd in zip(functions, equations.accelerations)},
             {f.diff(t): qd for f, qd in zip(functions, equations.speeds)},
             dict(zip(functions, equations.coordinates))]

    def to_kronlag(expr):
        for step in steps:
            expr = expr.subs(step)
        return expr

    return equations, reference, to_kronlag


def test_mass_matrix(pair):
    equations, reference, to_kronlag = pair
    m = len(equations.coordinates)
    assert_numerically_equal(equations.M, to_kronlag(reference.method.mass_matrix[:, :m]), state_symbols(equations))


def test_velocity_gravity_and_applied_terms(pair):
    """``C qd + g - f_Q`` is minus sympy's forcing (its equations at qdd = 0 without multipliers)."""
    equations, reference, to_kronlag = pair
    kronlag_terms = equations.C * sp.Matrix(equations.speeds) + equations.g - equations.f_Q
    assert_numerically_equal(kronlag_terms, -to_kronlag(reference.method.forcing), state_symbols(equations))


def test_constraint_jacobian(pair):
    equations, reference, to_kronlag = pair
    kronlag_rows = sp.Matrix.vstack(equations.Phi_q, equations.A)
    assert len(reference.scales) == kronlag_rows.rows
    if not reference.scales:
        return
    sympy_rows = -to_kronlag(reference.method.lam_coeffs)
    assert_numerically_equal(sympy_rows, sp.diag(*reference.scales) * kronlag_rows, state_symbols(equations))


def test_full_equations(pair):
    """sympy's ``eom`` with ``lam_j = scale_j * (lambda_j or mu_j)`` is the dynamic part of Eq. 23."""
    equations, reference, to_kronlag = pair
    multipliers = [*equations.lambdas, *equations.mus]
    lam = reference.method.lam_vec if multipliers else []
    renamed = {lam_j: scale * multiplier for lam_j, scale, multiplier in zip(lam, reference.scales, multipliers)}
    eom = to_kronlag(reference.method.eom.subs(renamed))
    m = len(equations.coordinates)
    assert_numerically_equal(equations.residual[:m, :], eom, state_symbols(equations))
