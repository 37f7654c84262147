"""Built-in planar models: the mechanisms of Van Khang (2011), closed chains, pendulums,
slider-cranks, a five-bar robot, the Chaplygin sleigh and IFToMM A01-A03."""

from __future__ import annotations

import sympy as sp

from ...core.errors import ModelError
from ..bodies import PlanarBody, PointMass
from ..free_bodies import free_body, mechanism
from ..symbols import coordinates
from ..system import System

__all__ = ["four_bar", "quick_return", "closed_chain", "double_pendulum", "slider_crank", "slider_crank_engine",
           "five_bar", "chaplygin_sleigh", "pendulum_cartesian", "n_four_bar", "andrews_squeezer"]

cos, sin = sp.cos, sp.sin


def _bar(name: str, mass, inertia, start, length, angle) -> PlanarBody:
    """A uniform bar from ``start`` along ``angle``; centre of mass at its middle."""
    centre = (start[0] + length / 2 * cos(angle), start[1] + length / 2 * sin(angle))
    return PlanarBody(name, mass=mass, inertia=inertia, position=centre, angle=angle)


def four_bar() -> System:
    """Planar four-bar mechanism of Van Khang (2011), Section 4.1.

    Coordinates ``q1, q2, q3``: angles of crank AB (``l1``), coupler BC (``l2``)
    and follower DC (``l3``) from the x-axis; ground pivots A = (0, 0) and
    D = (``l4``, 0).  Uniform links (``m1..m3``, central inertias ``I1..I3``),
    gravity ``g`` along -y, torque ``tau`` on the crank.  Loop closure (Eq. 24)::

        f1 = l1 cos q1 + l2 cos q2 - l3 cos q3 - l4 = 0
        f2 = l1 sin q1 + l2 sin q2 - l3 sin q3 = 0
    """
    q1, q2, q3 = coordinates("q1 q2 q3")
    l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau = sp.symbols("l1 l2 l3 l4 m1 m2 m3 I1 I2 I3 g tau")
    system = System([q1, q2, q3], parameters=[l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau],
                    gravity=(0, -g), name="four_bar")
    system.add_body(_bar("crank", m1, I1, (0, 0), l1, q1))
    system.add_body(_bar("coupler", m2, I2, (l1 * cos(q1), l1 * sin(q1)), l2, q2))
    system.add_body(_bar("follower", m3, I3, (l4, 0), l3, q3))
    system.add_constraint(l1 * cos(q1) + l2 * cos(q2) - l3 * cos(q3) - l4, name="loop x")
    system.add_constraint(l1 * sin(q1) + l2 * sin(q2) - l3 * sin(q3), name="loop y")
    system.add_torque("crank", tau, name="drive")
    B = (l1 * cos(q1), l1 * sin(q1))
    system.add_drawing_line([(0, 0), B, (l4 + l3 * cos(q3), l3 * sin(q3)), (l4, 0)], name="linkage")
    system.add_trace((B[0] + l2 / 2 * cos(q2), B[1] + l2 / 2 * sin(q2)), name="coupler midpoint")
    return system


def quick_return() -> System:
    """Quick-return mechanism of Van Khang (2011), Section 4.2.

    Coordinates ``phi1, phi2, phi3``: crank BC (pivot B = (0, ``l_AB``), length
    ``l_BC``), rocker AE (pivot A = (0, 0), length ``l_AE``) and link EF
    (``l_EF``).  Uniform bars (``m1..m3``, ``I1..I3``); slider D is a point mass
    ``m4`` at the crank pin C; slider G is a point mass ``m5`` on the guide
    ``y = l_AH`` (Eq. 36 fixes its height, so its weight does not enter the
    equations).  Torque ``tau`` on the crank, gravity ``g`` along -y.
    Constraints (Eq. 37)::

        f1 = l_AH - l_AE sin phi2 - l_EF sin phi3 = 0    (F on the guide)
        f2 = l_AB cos phi2 - l_BC sin(phi2 - phi1) = 0   (D on the line AE)
    """
    phi1, phi2, phi3 = coordinates("phi1 phi2 phi3")
    l_BC, l_AB, l_AE, l_EF, l_AH = sp.symbols("l_BC l_AB l_AE l_EF l_AH")
    m1, m2, m3, m4, m5, I1, I2, I3, g, tau = sp.symbols("m1 m2 m3 m4 m5 I1 I2 I3 g tau")
    system = System([phi1, phi2, phi3],
                    parameters=[l_BC, l_AB, l_AE, l_EF, l_AH, m1, m2, m3, m4, m5, I1, I2, I3, g, tau],
                    gravity=(0, -g), name="quick_return")
    system.add_body(_bar("crank", m1, I1, (0, l_AB), l_BC, phi1))
    system.add_body(_bar("rocker", m2, I2, (0, 0), l_AE, phi2))
    system.add_body(_bar("link", m3, I3, (l_AE * cos(phi2), l_AE * sin(phi2)), l_EF, phi3))
    system.add_body(PointMass("slider D", mass=m4, position=(l_BC * cos(phi1), l_AB + l_BC * sin(phi1))))
    system.add_body(PointMass("slider G", mass=m5, position=(l_AE * cos(phi2) + l_EF * cos(phi3), l_AH)))
    system.add_constraint(l_AH - l_AE * sin(phi2) - l_EF * sin(phi3), name="F on guide")
    system.add_constraint(l_AB * cos(phi2) - l_BC * sin(phi2 - phi1), name="D on AE")
    system.add_torque("crank", tau, name="drive")
    C = (l_BC * cos(phi1), l_AB + l_BC * sin(phi1))
    E = (l_AE * cos(phi2), l_AE * sin(phi2))
    F = (E[0] + l_EF * cos(phi3), E[1] + l_EF * sin(phi3))
    system.add_drawing_line([(0, l_AB), C], name="crank")
    system.add_drawing_line([(0, 0), E, F], name="rocker and link")
    system.add_trace(F, name="slider G")
    return system


def closed_chain(n: int, angles: str = "absolute") -> System:
    """Closed planar chain of ``n`` uniform links (a four-bar for ``n = 3``).

    Links have lengths ``l1..ln``, masses ``m1..mn`` and central inertias
    ``I1..In``; the first is pinned at the origin, the tip of the last at the
    ground point (``xg``, ``yg``); gravity ``g`` along -y.  Coordinates
    ``q1..qn`` are the links' absolute angles (``angles="absolute"``) or the
    joint angles relative to the previous link (``angles="relative"``); a
    relative chain declares its kinematic tree (:meth:`System.add_tree_link`),
    so that its ``M`` and ``C qd + g`` are computed recursively.
    """
    if not isinstance(n, int) or n < 2:
        raise ModelError(f"closed_chain needs an integer n >= 2 links, got {n!r}")
    if angles not in ("absolute", "relative"):
        raise ModelError(f"angles must be 'absolute' or 'relative', got {angles!r}")
    q = coordinates(" ".join(f"q{i}" for i in range(1, n + 1)))
    lengths = sp.symbols(f"l1:{n + 1}")
    masses = sp.symbols(f"m1:{n + 1}")
    inertias = sp.symbols(f"I1:{n + 1}")
    xg, yg, g = sp.symbols("xg yg g")
    system = System(q, parameters=[*lengths, *masses, *inertias, xg, yg, g], gravity=(0, -g),
                    name=f"closed_chain_{n}_{angles}")
    joint = (sp.Integer(0), sp.Integer(0))
    joints = [joint]
    angle = sp.Integer(0)
    for i in range(n):
        angle = q[i] if angles == "absolute" else angle + q[i]
        system.add_body(_bar(f"link {i + 1}", masses[i], inertias[i], joint, lengths[i], angle))
        if angles == "relative":  # a serial chain in joint angles: M and C qd + g may be recursive
            system.add_tree_link(f"link {i + 1}", q[i], parent="ground" if i == 0 else f"link {i}",
                                 origin=(0, 0) if i == 0 else (lengths[i - 1], 0), centre=(lengths[i] / 2, 0))
        joint = (joint[0] + lengths[i] * cos(angle), joint[1] + lengths[i] * sin(angle))
        joints.append(joint)
    system.add_constraint(joint[0] - xg, name="tip x")
    system.add_constraint(joint[1] - yg, name="tip y")
    system.add_drawing_line(joints, name="chain")
    return system


def double_pendulum() -> System:
    """Double pendulum of two uniform rods, hanging from the origin.

    Coordinates ``q1, q2``: absolute angles of the rods from the downward
    vertical; lengths ``l1, l2``, masses ``m1, m2``, central inertias
    ``I1, I2``, gravity ``g`` along -y.  No constraints (m = n = 2).
    """
    q1, q2 = coordinates("q1 q2")
    l1, l2, m1, m2, I1, I2, g = sp.symbols("l1 l2 m1 m2 I1 I2 g")
    system = System([q1, q2], parameters=[l1, l2, m1, m2, I1, I2, g], gravity=(0, -g), name="double_pendulum")
    # Angle from the downward vertical = angle from the x-axis + pi/2.
    system.add_body(_bar("rod 1", m1, I1, (0, 0), l1, q1 - sp.pi / 2))
    elbow = (l1 * sin(q1), -l1 * cos(q1))
    system.add_body(_bar("rod 2", m2, I2, elbow, l2, q2 - sp.pi / 2))
    tip = (elbow[0] + l2 * sin(q2), elbow[1] - l2 * cos(q2))
    system.add_drawing_line([(0, 0), elbow, tip], name="rods")
    system.add_trace(tip, name="tip")
    return system


def slider_crank() -> System:
    """Slider-crank: crank ``l1`` at the origin, connecting rod ``l2``, slider on the x-axis.

    Coordinates ``q1`` (crank angle), ``q2`` (rod angle), ``x`` (slider
    position); uniform crank and rod (``m1, m2``, ``I1, I2``), slider point
    mass ``m3``; torque ``tau`` on the crank, gravity ``g`` along -y.
    """
    q1, q2, x = coordinates("q1 q2 x")
    l1, l2, m1, m2, m3, I1, I2, g, tau = sp.symbols("l1 l2 m1 m2 m3 I1 I2 g tau")
    system = System([q1, q2, x], parameters=[l1, l2, m1, m2, m3, I1, I2, g, tau], gravity=(0, -g),
                    name="slider_crank")
    system.add_body(_bar("crank", m1, I1, (0, 0), l1, q1))
    system.add_body(_bar("rod", m2, I2, (l1 * cos(q1), l1 * sin(q1)), l2, q2))
    system.add_body(PointMass("slider", mass=m3, position=(x, 0)))
    system.add_constraint(l1 * cos(q1) + l2 * cos(q2) - x, name="pin x")
    system.add_constraint(l1 * sin(q1) + l2 * sin(q2), name="pin y")
    system.add_torque("crank", tau, name="drive")
    system.add_drawing_line([(0, 0), (l1 * cos(q1), l1 * sin(q1)), (x, 0)], name="crank and rod")
    return system


def slider_crank_engine() -> System:
    """Slider-crank engine written as bodies + joints (redundant body coordinates).

    Crank (``m1``, ``I1``, radius ``l1``), connecting rod (``m2``, ``I2``, length
    ``l2``) and piston (``m3``, ``I3``), each with its own coordinates
    ``x_<body>, y_<body>, theta_<body>`` (centre of mass and angle); torque ``tau``
    on the crank, gravity ``g`` along -y.  Named points ``main``, ``crank_pin``
    (crank), ``big_end``, ``small_end`` (rod), ``wrist`` (piston); joints
    ``main_bearing`` (ground-crank), ``crank_pin`` (crank-rod), ``wrist_pin``
    (rod-piston), revolute, and ``cylinder`` (ground-piston, prismatic along x).
    """
    l1, l2, m1, m2, m3, I1, I2, I3, g, tau = sp.symbols("l1 l2 m1 m2 m3 I1 I2 I3 g tau")
    bodies = [free_body("crank", mass=m1, inertia=I1), free_body("rod", mass=m2, inertia=I2),
              free_body("piston", mass=m3, inertia=I3)]
    system = mechanism(bodies, parameters=[l1, l2, m1, m2, m3, I1, I2, I3, g, tau], gravity=(0, -g),
                       name="slider_crank_engine")
    system.add_point("main", "crank", (-l1 / 2, 0))
    system.add_point("crank_pin", "crank", (l1 / 2, 0))
    system.add_point("big_end", "rod", (-l2 / 2, 0))
    system.add_point("small_end", "rod", (l2 / 2, 0))
    system.add_point("wrist", "piston", (0, 0))
    system.add_joint("revolute", "ground", "crank", at_b="main", name="main_bearing")
    system.add_joint("revolute", "crank", "rod", at_a="crank_pin", at_b="big_end", name="crank_pin")
    system.add_joint("revolute", "rod", "piston", at_a="small_end", at_b="wrist", name="wrist_pin")
    system.add_joint("prismatic", "ground", "piston", axis=(1, 0), name="cylinder")
    system.add_torque("crank", tau, name="drive")
    system.add_drawing_line([system.point(name).position for name in ("main", "crank_pin", "wrist")],
                            name="engine")
    return system


def five_bar() -> System:
    """Planar five-bar (5R) parallel robot: two actuated base joints and a closed chain.

    The base joints sit at ``(-d/2, 0)`` and ``(d/2, 0)``; the proximal links
    ``proximal_1``, ``proximal_2`` (length ``l1``, mass ``m1``, central inertia
    ``I1``) turn about them by the joint angles ``theta1``, ``theta2`` (from the
    x axis, the actuated coordinates, each driven by its motor torque ``tau1``,
    ``tau2``); the distal links ``distal_1``, ``distal_2`` (``l2``, ``m2``,
    ``I2``) have their own coordinates ``x_distal_k, y_distal_k, theta_distal_k``
    (centre of mass, angle) and meet at the end effector.  Gravity ``g`` along -y.

    Coordinates, in this order: ``theta1, theta2, x_distal_1, y_distal_1,
    theta_distal_1, x_distal_2, y_distal_2, theta_distal_2`` (m = 8); revolute
    joints ``elbow_1`` (proximal_1-distal_1), ``elbow_2`` (proximal_2-distal_2) and
    ``tip`` (distal_1-distal_2), 6 constraints, 2 degrees of freedom.  Named
    points: ``base_1``, ``base_2`` (ground), ``elbow_1``, ``elbow_2`` (the
    proximal links' outer ends) and ``end_effector`` (the outer end of distal_1,
    where ``tip`` joins distal_2).
    """
    theta1, theta2 = coordinates("theta1 theta2")
    d, l1, l2, m1, m2, I1, I2, g, tau1, tau2 = sp.symbols("d l1 l2 m1 m2 I1 I2 g tau1 tau2")
    distal = [free_body(f"distal_{k}", mass=m2, inertia=I2) for k in (1, 2)]
    system = System([theta1, theta2, *distal[0].coordinates, *distal[1].coordinates],
                    parameters=[d, l1, l2, m1, m2, I1, I2, g, tau1, tau2], gravity=(0, -g), name="five_bar")
    for k, (angle, base, torque) in enumerate(((theta1, -d / 2, tau1), (theta2, d / 2, tau2)), start=1):
        system.add_body(_bar(f"proximal_{k}", m1, I1, (base, 0), l1, angle))
        system.add_point(f"base_{k}", "ground", (base, 0))
        system.add_point(f"elbow_{k}", f"proximal_{k}", (l1 / 2, 0))
        system.add_torque(f"proximal_{k}", torque, name=f"motor_{k}")
    for free in distal:
        system.add_body(free.body)
    system.add_point("end_effector", "distal_1", (l2 / 2, 0))
    system.add_joint("revolute", "proximal_1", "distal_1", at_a="elbow_1", at_b=(-l2 / 2, 0), name="elbow_1")
    system.add_joint("revolute", "proximal_2", "distal_2", at_a="elbow_2", at_b=(-l2 / 2, 0), name="elbow_2")
    system.add_joint("revolute", "distal_1", "distal_2", at_a="end_effector", at_b=(l2 / 2, 0), name="tip")
    system.add_drawing_line([system.point(name).position
                             for name in ("base_1", "elbow_1", "end_effector", "elbow_2", "base_2")], name="robot")
    system.add_trace(system.point("end_effector").position, name="end effector")
    return system


def chaplygin_sleigh() -> System:
    """Chaplygin sleigh: a planar body on a knife edge (nonholonomic).

    Coordinates ``x, y`` (centre of mass) and ``theta`` (heading); mass ``m``,
    central inertia ``I``; the blade sits at distance ``a`` behind the centre
    of mass and cannot slide sideways::

        -sin(theta) xd + cos(theta) yd - a thetad = 0
    """
    x, y, theta = coordinates("x y theta")
    m, inertia, a = sp.symbols("m I a")
    system = System([x, y, theta], parameters=[m, inertia, a], name="chaplygin_sleigh")
    system.add_body(PlanarBody("sleigh", mass=m, inertia=inertia, position=(x, y), angle=theta))
    xd, yd, thetad = system.speeds
    system.add_nonholonomic_constraint(-sin(theta) * xd + cos(theta) * yd - a * thetad, name="blade")
    blade = (x - a * cos(theta), y - a * sin(theta))
    system.add_drawing_line([blade, (x, y)], name="body")
    system.add_trace(blade, name="blade")
    return system


# -- the IFToMM multibody benchmark library, problem set A ---------------------------------------


def pendulum_cartesian() -> System:
    """IFToMM benchmark A01: simple pendulum in Cartesian coordinates.

    Coordinates ``x, y``: position of the bob, a point mass ``m`` on a massless
    rod of length ``L`` pinned at the origin; gravity ``g`` along -y.  One
    constraint (r = 1, one degree of freedom)::

        f = x**2 + y**2 - L**2 = 0
    """
    x, y = coordinates("x y")
    m, L, g = sp.symbols("m L g")
    system = System([x, y], parameters=[m, L, g], gravity=(0, -g), name="pendulum_cartesian")
    system.add_body(PointMass("bob", mass=m, position=(x, y)))
    system.add_constraint(x**2 + y**2 - L**2, name="rod")
    system.add_drawing_line([(0, 0), (x, y)], name="rod")
    system.add_trace((x, y), name="bob")
    return system


def n_four_bar(n: int = 2) -> System:
    """IFToMM benchmark A02: N four-bar mechanism (``n`` four-bar loops in a row).

    ``n + 1`` cranks of length ``L`` pinned to the ground at ``x = 0, L, ...,
    n L`` and ``n`` couplers of length ``L`` joining their tips; all bars are
    uniform (mass ``m``, central inertia ``J``), gravity ``g`` along -y.
    Coordinates in chain order ``phi0, psi1, phi1, ..., psin, phin``: absolute
    angles of the cranks (``phi``) and couplers (``psi``) from the x-axis.
    Loop closure of coupler ``k`` (``k = 1..n``), 2 n constraints::

        L cos(phi_{k-1}) + L cos(psi_k) - L cos(phi_k) - L = 0
        L sin(phi_{k-1}) + L sin(psi_k) - L sin(phi_k) = 0

    With cranks of equal length the mechanism has one degree of freedom; where
    every bar is horizontal (``sin phi_k = sin psi_k = 0``) the x-rows of
    ``Phi_q`` vanish and ``Phi_q`` loses rank (a singular configuration, where
    the physical motion, all cranks parallel, meets non-physical branches).
    """
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise ModelError(f"n_four_bar needs an integer number of loops n >= 1, got {n!r}")
    names = ["phi0"] + [name for k in range(1, n + 1) for name in (f"psi{k}", f"phi{k}")]
    q = coordinates(" ".join(names))
    cranks, couplers = q[0::2], q[1::2]
    L, m, J, g = sp.symbols("L m J g")
    system = System(q, parameters=[L, m, J, g], gravity=(0, -g), name=f"n_four_bar_{n}")
    tips = [(k * L + L * cos(phi), L * sin(phi)) for k, phi in enumerate(cranks)]
    for k, phi in enumerate(cranks):
        system.add_body(_bar(f"crank {k}", m, J, (k * L, 0), L, phi))
        system.add_drawing_line([(k * L, 0), tips[k]], name=f"crank {k}")
    for k, psi in enumerate(couplers, start=1):
        system.add_body(_bar(f"coupler {k}", m, J, tips[k - 1], L, psi))
        start = tips[k - 1]
        system.add_constraint(start[0] + L * cos(psi) - tips[k][0], name=f"loop {k} x")
        system.add_constraint(start[1] + L * sin(psi) - tips[k][1], name=f"loop {k} y")
    coupler_joints = [tips[0]] + [(tip[0] + L * cos(psi), tip[1] + L * sin(psi))
                                  for tip, psi in zip(tips, couplers)]
    system.add_drawing_line(coupler_joints, name="couplers")
    system.add_trace(tips[0], name="B0")
    return system


def andrews_squeezer() -> System:
    """IFToMM benchmark A03: Andrews' squeezing mechanism, seven planar bodies.

    The model of Hairer & Wanner (Solving ODEs II, Sec. VII.7) and of the
    Bari/CWI Test Set for IVP Solvers (problem ``andrews``), with its
    parameter names.  Coordinates ``beta, theta, gamma, phi, delta, Omega,
    epsilon`` (the test set's ``omega`` is ``Omega`` here); no gravity.  Fixed
    points O = (0, 0), A = (``xa``, ``ya``), B = (``xb``, ``yb``), C = (``xc``,
    ``yc``).  Body 1 turns about O (angle ``beta``, centre of mass at ``ra``)
    and carries body 2 at distance ``rr`` (angle ``beta + theta``, centre of
    mass ``da`` behind the pin, length ``d``); body 3 turns about B (angle
    ``gamma``); bodies 5 (``delta``) and 7 (``epsilon``) turn about A and
    carry bodies 4 (``phi + delta``, pinned at distance ``zt``) and 6
    (``Omega + epsilon``, pinned at distance ``u``).  The far ends of bodies
    2, 4 and 6 and the point at ``ss`` on body 3 form one joint E::

        rr cos(beta) - d cos(beta+theta) - ss sin(gamma) - xb = 0
        rr sin(beta) - d sin(beta+theta) + ss cos(gamma) - yb = 0
        rr cos(beta) - d cos(beta+theta) - e sin(phi+delta) - zt cos(delta) - xa = 0
        rr sin(beta) - d sin(beta+theta) + e cos(phi+delta) - zt sin(delta) - ya = 0
        rr cos(beta) - d cos(beta+theta) - zf cos(Omega+epsilon) - u sin(epsilon) - xa = 0
        rr sin(beta) - d sin(beta+theta) - zf sin(Omega+epsilon) + u cos(epsilon) - ya = 0

    A spring (``c0``, free length ``l0``) pulls the point D of body 3 (``sd``
    along and ``sc`` across it) towards C; the torque ``mom`` drives body 1.
    The centres of mass of bodies 3, 5 and 7 sit at ``(sa, sb)``, ``(ta,
    tb)`` and ``(ua, ub)`` from their pivots in the body frames; without
    gravity only their distances enter ``M``, which equals the test set's.
    """
    beta, theta, gamma, phi, delta, Omega, epsilon = coordinates("beta theta gamma phi delta Omega epsilon")
    names = ("m1 m2 m3 m4 m5 m6 m7 xa ya xb yb xc yc c0 I1 I2 I3 I4 I5 I6 I7 d da e ea rr ra l0 "
             "ss sa sb sc sd ta tb u ua ub zf zt fa mom")
    parameters = sp.symbols(names)
    (m1, m2, m3, m4, m5, m6, m7, xa, ya, xb, yb, xc, yc, c0, I1, I2, I3, I4, I5, I6, I7, d, da, e, ea, rr, ra,
     l0, ss, sa, sb, sc, sd, ta, tb, u, ua, ub, zf, zt, fa, mom) = parameters
    system = System([beta, theta, gamma, phi, delta, Omega, epsilon], parameters=parameters,
                    name="andrews_squeezer")

    def direction(angle):
        return sp.Matrix([cos(angle), sin(angle)])

    def normal(angle):  # direction(angle - pi/2)
        return sp.Matrix([sin(angle), -cos(angle)])

    O, A, B, C = sp.Matrix([0, 0]), sp.Matrix([xa, ya]), sp.Matrix([xb, yb]), sp.Matrix([xc, yc])
    P = rr * direction(beta)                      # pin of body 2 on body 1
    E = P - d * direction(beta + theta)           # the common joint
    J4 = A + zt * direction(delta)                # pin of body 4 on body 5
    J6 = A + u * normal(epsilon)                  # pin of body 6 on body 7
    D = B + sd * direction(gamma) + sc * normal(gamma)
    bodies = [
        ("body 1", m1, I1, ra * direction(beta), beta),
        ("body 2", m2, I2, P - da * direction(beta + theta), beta + theta),
        ("body 3", m3, I3, B + sa * normal(gamma) + sb * direction(gamma), gamma),
        ("body 4", m4, I4, J4 + (e - ea) * normal(phi + delta), phi + delta),
        ("body 5", m5, I5, A + ta * direction(delta) - tb * normal(delta), delta),
        ("body 6", m6, I6, J6 + (zf - fa) * direction(Omega + epsilon), Omega + epsilon),
        ("body 7", m7, I7, A + ua * normal(epsilon) + ub * direction(epsilon), epsilon),
    ]
    for name, mass, inertia, centre, angle in bodies:
        system.add_body(PlanarBody(name, mass=mass, inertia=inertia, position=centre, angle=angle))
    far_ends = {"3": B + ss * normal(gamma), "4": J4 + e * normal(phi + delta),
                "6": J6 + zf * direction(Omega + epsilon)}
    for body, end in far_ends.items():
        system.add_constraint((E - end)[0], name=f"E on body {body} x")
        system.add_constraint((E - end)[1], name=f"E on body {body} y")
    system.add_spring(D, C, stiffness=c0, free_length=l0, name="spring")
    system.add_torque("body 1", mom, name="drive")
    system.add_drawing_line([O, P, E], name="bodies 1-2")
    system.add_drawing_line([B, far_ends["3"], D, B], name="body 3")
    system.add_drawing_line([A, J4, far_ends["4"]], name="bodies 5-4")
    system.add_drawing_line([A, J6, far_ends["6"]], name="bodies 7-6")
    system.add_drawing_line([D, C], name="spring")
    system.add_trace(P, name="P")
    return system
