"""Canonical models: one place that feeds tests, docs, examples and the CLI.

Every function returns a fresh :class:`kronlag.System` whose symbols carry the
names given in its docstring, so scripts can rely on them.
"""

from __future__ import annotations

from collections.abc import Callable

import sympy as sp

from .joints import free_body, mechanism
from .system import PlanarBody, PointMass, RigidBody, RotationSequence, System, coordinates

__all__ = [
    "four_bar",
    "quick_return",
    "closed_chain",
    "double_pendulum",
    "slider_crank",
    "slider_crank_engine",
    "five_bar",
    "heavy_top",
    "chaplygin_sleigh",
    "pendulum_cartesian",
    "n_four_bar",
    "andrews_squeezer",
    "bricard",
    "flyball_governor",
    "ur5",
    "panda",
    "BUILTIN_MODELS",
    "IFTOMM",
]

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
    joint angles relative to the previous link (``angles="relative"``).
    """
    if not isinstance(n, int) or n < 2:
        raise ValueError(f"closed_chain needs an integer n >= 2 links, got {n!r}")
    if angles not in ("absolute", "relative"):
        raise ValueError(f"angles must be 'absolute' or 'relative', got {angles!r}")
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


def _rotation_z(angle) -> sp.Matrix:
    return sp.Matrix([[cos(angle), -sin(angle), 0], [sin(angle), cos(angle), 0], [0, 0, 1]])


def _rotation_x(angle) -> sp.Matrix:
    return sp.Matrix([[1, 0, 0], [0, cos(angle), -sin(angle)], [0, sin(angle), cos(angle)]])


def _rotation_y(angle) -> sp.Matrix:
    return sp.Matrix([[cos(angle), 0, sin(angle)], [0, 1, 0], [-sin(angle), 0, cos(angle)]])


#: Elementary rotations by axis name.
_ROTATIONS = {"x": _rotation_x, "y": _rotation_y, "z": _rotation_z}


def heavy_top() -> System:
    """Heavy symmetric top spinning about a fixed point at the origin.

    Coordinates: z-x-z Euler angles ``psi`` (precession), ``theta``
    (nutation), ``phi`` (spin), ``R = Rz(psi) Rx(theta) Rz(phi)``.  Mass ``m``,
    centre of mass at distance ``l`` along the body z-axis, central inertia
    ``diag(Ixx, Ixx, Izz)``, gravity ``g`` along -z.
    """
    psi, theta, phi = coordinates("psi theta phi")
    m, l, g, Ixx, Izz = sp.symbols("m l g Ixx Izz")
    system = System([psi, theta, phi], parameters=[m, l, g, Ixx, Izz], gravity=(0, 0, -g), name="heavy_top")
    euler_angles = RotationSequence([("z", psi), ("x", theta), ("z", phi)])
    rotation = euler_angles.matrix
    system.add_body(RigidBody("top", mass=m, inertia=sp.diag(Ixx, Ixx, Izz),
                              position=rotation * sp.Matrix([0, 0, l]), rotation=euler_angles))
    system.add_drawing_line([(0, 0, 0), rotation * sp.Matrix([0, 0, 2 * l])], name="axis")
    system.add_trace(rotation * sp.Matrix([0, 0, 2 * l]), name="axis tip")
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
        raise ValueError(f"n_four_bar needs an integer number of loops n >= 1, got {n!r}")
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


def _square_rod_inertia(mass, length, side, axis: str) -> sp.Matrix:
    """Central inertia tensor of a rod of square section ``side`` lying along body ``axis``."""
    along, across = mass * side**2 / 6, mass * (length**2 + side**2) / 12
    return sp.diag(*(along if name == axis else across for name in "xyz"))


def bricard() -> System:
    """IFToMM benchmark A04: Bricard's overconstrained mechanism.

    Five rods (length ``L``, mass ``m``, square section ``a``) in a closed
    loop of six revolute joints, O = (0, 0, 0) axis y, P1 = (L, 0, 0) axis z,
    P2 = (L, -L, 0) axis x, P3 = (L, -L, L) axis y, P4 = (0, -L, L) axis z,
    P5 = (0, 0, L) axis x (to the ground); gravity ``g`` along -y.
    Coordinates ``q1..q5``: the joint angles of the serial chain O..P4 about
    the body-fixed joint axes, zero in the configuration above, so rod k
    turns with ``R_k = R_y(q1) R_z(q2) R_x(q3) R_y(q4) R_z(q5)`` (the first k
    factors).  Closure at P5, the chain's tip ``p5(q)`` and rod 5's x-axis
    ``R_5 e_x`` (5 equations)::

        p5(q) - (0, 0, L) = 0,    e_y . R_5 e_x = 0,    e_z . R_5 e_x = 0

    Their Jacobian has rank 4, not 5: the mechanism moves with one degree of
    freedom although ``m - r = 0`` (a redundant constraint).
    """
    q = coordinates("q1 q2 q3 q4 q5")
    L, m, a, g = sp.symbols("L m a g")
    system = System(q, parameters=[L, m, a, g], gravity=(0, -g, 0), name="bricard")
    joint_axes = "yzxyz"
    rod_axes = [("x", 1), ("y", -1), ("z", 1), ("x", -1), ("y", 1)]   # rod k along +-(body axis)
    rotation = sp.eye(3)
    joint = sp.zeros(3, 1)
    joints = [joint]
    for k, (joint_axis, (rod_axis, sign)) in enumerate(zip(joint_axes, rod_axes), start=1):
        rotation = rotation * _ROTATIONS[joint_axis](q[k - 1])
        along = sign * L * rotation[:, "xyz".index(rod_axis)]
        system.add_body(RigidBody(f"rod {k}", mass=m, inertia=_square_rod_inertia(m, L, a, rod_axis),
                                  position=joint + along / 2, rotation=rotation, simplify=False))
        joint = joint + along
        joints.append(joint)
    for axis, value in zip("xyz", (0, 0, L)):
        system.add_constraint(joint["xyz".index(axis)] - value, name=f"P5 {axis}")
    for axis in "yz":
        system.add_constraint(rotation["xyz".index(axis), 0], name=f"joint P5 axis {axis}")
    system.add_drawing_line(joints, name="rods")
    system.add_trace(joints[3], name="P3")
    return system


def flyball_governor() -> System:
    """IFToMM benchmark A05: stiff flyball governor.

    A vertical shaft (length ``L``, mass ``m_shaft``, square section ``w``)
    turns freely about the z-axis (angle ``psi``).  Two rods (length ``L``,
    mass ``m_rod``, section ``w``) hang from pins at height ``L`` and distance
    ``d`` on either side of the axis; each turns about a pin axis normal to
    the shaft's plane (angles ``theta1``, ``theta2`` below the horizontal) and
    carries a ball, a point mass ``m_ball``, at its end.  A cubic slider
    (side ``b``, mass ``m_slider``) turns with the shaft and slides along it
    (height ``s`` of its centre).  The coupler rods of the classical governor
    are replaced by spring-dampers (stiffness ``k``, free length ``l0``,
    damping ``c``) from the middle of each rod to the side of the slider at
    distance ``b/2`` from the axis; gravity ``g`` along -z.  No constraints
    (m = 4, r = 0); the stiff spring-dampers make the equations stiff.

    The data (1 m x 0.01 m x 0.01 m shaft and rods, 0.1 m slider, density
    3000 kg/m^3, 5 kg balls, k = 8e5 N/m, c = 4e4 N s/m, l0 = 0.5 m, s = 0.5 m,
    30 degrees, 2 pi rad/s) are those of the IFToMM library page; its geometry
    (pins 0.05 m off the axis at the shaft's top, springs from rod middles to
    the slider's faces) follows Exudyn's implementation of the benchmark
    (``stiffFlyballGovernor.py``).  In this initial position the springs are
    at their free length.
    """
    psi, theta1, theta2, s = coordinates("psi theta1 theta2 s")
    L, w, b, d, m_shaft, m_rod, m_slider, m_ball, k, c, l0, g = sp.symbols(
        "L w b d m_shaft m_rod m_slider m_ball k c l0 g")
    system = System([psi, theta1, theta2, s], parameters=[L, w, b, d, m_shaft, m_rod, m_slider, m_ball, k, c, l0, g],
                    gravity=(0, 0, -g), name="flyball_governor")
    spin = _rotation_z(psi)
    system.add_body(RigidBody("shaft", mass=m_shaft, inertia=_square_rod_inertia(m_shaft, L, w, "z"),
                              position=(0, 0, L / 2), rotation=spin))
    system.add_body(RigidBody("slider", mass=m_slider, inertia=sp.eye(3) * m_slider * b**2 / 6,
                              position=(0, 0, s), rotation=spin))
    drawing = [[sp.Matrix([0, 0, 0]), sp.Matrix([0, 0, L])]]
    for side, theta in enumerate((theta1, theta2), start=1):
        plane = _rotation_z(psi + (side - 1) * sp.pi)       # the rod's vertical plane
        rotation = plane * _rotation_y(theta)
        pin = plane * sp.Matrix([d, 0, L])
        axis = rotation[:, 0]
        middle, end = pin + L / 2 * axis, pin + L * axis
        system.add_body(RigidBody(f"rod {side}", mass=m_rod, inertia=_square_rod_inertia(m_rod, L, w, "x"),
                                  position=middle, rotation=rotation))
        system.add_body(PointMass(f"ball {side}", mass=m_ball, position=end))
        attachment = plane * sp.Matrix([b / 2, 0, s])
        system.add_spring(middle, attachment, stiffness=k, free_length=l0, name=f"spring {side}")
        system.add_damper(middle, attachment, coefficient=c, name=f"damper {side}")
        drawing.append([pin, end])
        drawing.append([middle, attachment])
        system.add_trace(end, name=f"ball {side}")
    for name, line in zip(["shaft", "rod 1", "spring 1", "rod 2", "spring 2"], drawing):
        system.add_drawing_line(line, name=name)
    return system
def _exact(value) -> sp.Expr:
    """A published decimal as the exact rational it denotes (``0.089159`` -> ``89159/1000000``)."""
    return sp.Rational(repr(float(value))) if isinstance(value, float | sp.Float) else sp.sympify(value)


def _cylinder_inertia(mass: float, radius: float, length: float, axis: str) -> sp.Matrix:
    """Central inertia of a uniform solid cylinder whose axis is the body ``axis`` ("x", "y" or "z")."""
    mass, radius, length = _exact(mass), _exact(radius), _exact(length)
    along, across = mass * radius ** 2 / 2, mass * (3 * radius ** 2 + length ** 2) / 12
    return sp.diag(*[along if name == axis else across for name in "xyz"])


def _tensor(xx, yy, zz, xy, xz, yz) -> sp.Matrix:
    return sp.Matrix([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]).applyfunc(_exact)


def _serial_arm(name: str, convention: str, dh: list[tuple], masses: list, centres: list,
                inertias: list) -> System:
    """A serial arm of revolute joints ``q1..qn`` fixed to the ground at the origin.

    ``dh`` rows are ``(a, d, alpha)`` (joint angle ``q_i``).  ``convention`` is
    ``"standard"`` (frame i: ``T_i = T_{i-1} Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``) or
    ``"modified"`` (Craig: ``T_i = T_{i-1} Rx(alpha_i) Tx(a_i) Rz(q_i) Tz(d_i)``).  Link i
    has its centre of mass at ``centres[i]`` and central inertia ``inertias[i]`` in frame i.
    Gravity ``g`` along -z, joint torques ``tau1..taun``.
    """
    n = len(dh)
    q = coordinates(" ".join(f"q{i + 1}" for i in range(n)))
    g = sp.Symbol("g")
    torques = sp.symbols(" ".join(f"tau{i + 1}" for i in range(n)), seq=True)
    system = System(q, parameters=[g, *torques], gravity=(0, 0, -g), name=name)
    factors: list[tuple[str, sp.Expr]] = []
    rotation, origin = sp.eye(3), sp.zeros(3, 1)
    origins = [origin]

    def turn(axis: str, angle) -> None:
        nonlocal rotation
        if angle != 0:
            factors.append((axis, angle))
            rotation = RotationSequence(factors).matrix

    def move(x, z) -> None:
        nonlocal origin
        origin = origin + rotation * sp.Matrix([x, 0, z])

    for i, (a, d, alpha) in enumerate(dh):
        a, d = _exact(a), _exact(d)
        if convention == "standard":
            turn("z", q[i])
            move(a, d)
            turn("x", alpha)
        else:
            turn("x", alpha)
            move(a, 0)
            turn("z", q[i])
            move(0, d)
        origins.append(origin)
        centre = origin + rotation * sp.Matrix(centres[i]).applyfunc(_exact)
        system.add_body(RigidBody(f"link{i + 1}", mass=_exact(masses[i]), inertia=inertias[i],
                                  position=centre, rotation=RotationSequence(factors)))
    system.add_generalized_force(torques, name="joint torques")
    system.add_drawing_line(origins, name="arm")
    system.add_trace(origins[-1], name="flange")
    return system


def ur5() -> System:
    """Universal Robots UR5 (CB3) serial arm: six revolute joints, standard DH.

    Coordinates ``q1..q6`` (joint angles, zero in the DH home pose), gravity ``g``
    along -z, joint torques ``tau1..tau6``.  Sources:

    * DH parameters (series 3), link masses and centres of mass in the DH frames:
      Universal Robots, "DH parameters for calculations of kinematics and dynamics"
      (universal-robots.com/articles/ur/application-installation/
      dh-parameters-for-calculations-of-kinematics-and-dynamics).
    * Central inertias (UR publishes none for the UR5): the uniform-cylinder model of
      ROS-Industrial ``ur_description`` (``config/ur5/physical_parameters.yaml``: radius and
      length per link, ``I = m r^2/2`` about the cylinder axis, ``m (3 r^2 + L^2)/12``
      across), with the cylinder along the link (DH x) for the upper arm and forearm and
      along the link's own joint axis for the others.
    """
    pi = sp.pi
    dh = [(0, 0.089159, pi / 2), (-0.425, 0, 0), (-0.39225, 0, 0), (0, 0.10915, pi / 2),
          (0, 0.09465, -pi / 2), (0, 0.0823, 0)]
    masses = [3.7, 8.393, 2.33, 1.219, 1.219, 0.1879]
    centres = [(0, -0.02561, 0.00193), (0.2125, 0, 0.11336), (0.15, 0, 0.0265), (0, -0.0018, 0.01634),
               (0, 0.0018, 0.01634), (0, 0, -0.001159)]
    cylinders = [(0.075, 0.178, "y"), (0.06, 0.425, "x"), (0.06, 0.39225, "x"), (0.06, 0.095, "y"),
                 (0.06, 0.085, "y"), (0.0375, 0.0305, "z")]
    inertias = [_cylinder_inertia(mass, *cylinder) for mass, cylinder in zip(masses, cylinders)]
    return _serial_arm("ur5", "standard", dh, masses, centres, inertias)


def panda() -> System:
    """Franka Emika Panda serial arm (links 1-7, no hand): seven revolute joints, modified DH.

    Coordinates ``q1..q7`` (joint angles), gravity ``g`` along -z, joint torques
    ``tau1..tau7``.  Sources:

    * Kinematics (Craig's modified DH: ``a``, ``d``, ``alpha``): Franka Emika,
      "Robot and interface specifications", Denavit-Hartenberg parameters of the Panda.
    * Masses, centres of mass and central inertia tensors in the link (DH) frames: the
      identified, physically feasible parameters of C. Gaz, M. Cognetti, A. Oliva,
      P. Robuffo Giordano, A. De Luca, "Dynamic identification of the Franka Emika Panda
      robot with retrieval of feasible parameters using penalty-based optimization",
      IEEE RA-L 4(4) (2019) 4147-4154, as shipped in ``franka_ros``
      (``franka_description/robots/common/inertial.yaml``).
    """
    pi = sp.pi
    dh = [(0, 0.333, 0), (0, 0, -pi / 2), (0, 0.316, pi / 2), (0.0825, 0, pi / 2), (-0.0825, 0.384, -pi / 2),
          (0, 0, pi / 2), (0.088, 0, pi / 2)]
    masses = [4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 0.735522]
    centres = [(0.003875, 0.002081, -0.04762), (-0.003141, -0.02872, 0.003495),
               (0.027518, 0.039252, -0.066502), (-0.05317, 0.104419, 0.027454),
               (-0.011953, 0.041065, -0.038437), (0.060149, -0.014117, -0.010517),
               (0.010517, -0.004252, 0.061597)]
    inertias = [_tensor(0.70337, 0.70661, 0.009117, -0.000139, 0.006772, 0.019169),
                _tensor(0.007962, 0.02811, 0.025995, -0.003925, 0.010254, 0.000704),
                _tensor(0.037242, 0.036155, 0.01083, -0.004761, -0.011396, -0.012805),
                _tensor(0.025853, 0.019552, 0.028323, 0.007796, -0.001332, 0.008641),
                _tensor(0.035549, 0.029474, 0.008627, -0.002117, -0.004037, 0.000229),
                _tensor(0.001964, 0.004354, 0.005433, 0.000109, -0.001158, 0.000341),
                _tensor(0.012516, 0.010027, 0.004815, -0.000428, -0.001196, -0.000741)]
    return _serial_arm("panda", "modified", dh, masses, centres, inertias)


#: Built-in models by name (the CLI and model files use these names).
BUILTIN_MODELS: dict[str, Callable[[], System]] = {
    "four_bar": four_bar,
    "quick_return": quick_return,
    "double_pendulum": double_pendulum,
    "slider_crank": slider_crank,
    "slider_crank_engine": slider_crank_engine,
    "five_bar": five_bar,
    "heavy_top": heavy_top,
    "chaplygin_sleigh": chaplygin_sleigh,
    "pendulum_cartesian": pendulum_cartesian,
    "n_four_bar": n_four_bar,
    "andrews_squeezer": andrews_squeezer,
    "bricard": bricard,
    "flyball_governor": flyball_governor,
    "ur5": ur5,
    "panda": panda,
}

#: The IFToMM benchmark problems A01-A05 (references in :mod:`kronlag.benchmarks.iftomm`).
IFTOMM: dict[str, Callable[..., System]] = {
    "A01": pendulum_cartesian,
    "A02": n_four_bar,
    "A03": andrews_squeezer,
    "A04": bricard,
    "A05": flyball_governor,
}
