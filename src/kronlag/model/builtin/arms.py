"""Built-in serial arms from published data: the UR5 and the Franka Emika Panda."""

from __future__ import annotations

import sympy as sp

from ..bodies import RigidBody
from ..rotations import RotationSequence
from ..symbols import coordinates
from ..system import System

__all__ = ["ur5", "panda"]


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
