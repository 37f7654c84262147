"""Built-in spatial models: the heavy top, IFToMM A04 (Bricard) and A05 (flyball governor)."""

from __future__ import annotations

import sympy as sp

from ..bodies import PointMass, RigidBody
from ..rotations import RotationSequence, elementary_rotation
from ..symbols import coordinates
from ..system import System

__all__ = ["heavy_top", "bricard", "flyball_governor"]


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
        rotation = rotation * elementary_rotation(joint_axis, q[k - 1])
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
    spin = elementary_rotation("z", psi)
    system.add_body(RigidBody("shaft", mass=m_shaft, inertia=_square_rod_inertia(m_shaft, L, w, "z"),
                              position=(0, 0, L / 2), rotation=spin))
    system.add_body(RigidBody("slider", mass=m_slider, inertia=sp.eye(3) * m_slider * b**2 / 6,
                              position=(0, 0, s), rotation=spin))
    drawing = [[sp.Matrix([0, 0, 0]), sp.Matrix([0, 0, L])]]
    for side, theta in enumerate((theta1, theta2), start=1):
        plane = elementary_rotation("z", psi + (side - 1) * sp.pi)       # the rod's vertical plane
        rotation = plane * elementary_rotation("y", theta)
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
