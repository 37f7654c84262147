"""Joint friction from the reactions: :class:`Friction` and the expressions its numeric form reads.

A revolute or prismatic joint (planar or spatial) added with ``friction=Friction(...)`` feels a
friction torque or force along its free motion, against its rate ``v`` (the relative angular
speed about the axis, rad/s; the sliding speed, m/s), proportional to its normal load ``N`` computed
from the joint's reaction ``[F; T] = W(q) lambda_J`` (:mod:`kronlag.model.joints`)::

    revolute:   f = r mu(v) N + c v,   N = |F_radial| + |T_bending| / arm + F0
    prismatic:  f = mu(v) N + c v,     N = |F_normal| + |T| / arm + F0

``F_radial`` (``F_normal``) is the reaction force less its component along the axis (planar
revolute: the whole force); ``T_bending`` is the couple less its component along a spatial
revolute axis (none in the plane); for a prismatic joint ``T`` is the whole couple (bending and
torsion, planar: ``Mz``).  A term ``/ arm`` is left out when no ``arm`` is given.  This follows the
FRICTION statement of Adams Solver (``adams_solver/state_friction.html``: pin radius ``Rp``,
bending reaction arm ``Rb``, preload ``FRICTION_FORCE_PRELOAD``; translational joints add the
bending and torsional moments over the overlap and the friction arm) with one arm for both
moments; Adams' axial term of a revolute joint (``FRICTION_ARM`` times the axial force) is left out.

The coefficient is the smooth law (``law="smooth"``)::

    mu(v) = (mu_k + (mu_s - mu_k) exp(-(v / v_s)^2)) tanh(v / v_eps)

(``v_s``: ``stribeck_velocity``; without it ``mu_s = mu_k``; ``v_eps``: ``smoothing_velocity``), or
the exact law (``law="exact"``): ``sign(v)`` in place of ``tanh``, no Stribeck term without ``v_s``,
and a joint whose rate reaches zero sticks until its holding force exceeds ``r mu_s N``
(:mod:`kronlag.simulation.stiction`; the record's ``mode`` field says which way a run's segment takes).
The generalized force is ``Q_f = -J_rate^T f`` with ``v = J_rate(q) qd``; since ``N`` depends on
the multipliers, forward dynamics solves for ``(qdd, lambda)`` and the friction together
(:mod:`kronlag.numeric.friction`).

Units (SI): ``static``, ``kinetic`` dimensionless; ``viscous`` N*s/m (prismatic) or N*m*s/rad
(revolute); ``stribeck_velocity``, ``smoothing_velocity`` m/s or rad/s (the joint rate's unit);
``radius``, ``arm`` m; ``preload`` N.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import sympy as sp

from ..core.errors import ModelError
from .bodies import Pose
from .frames import GROUND, Frame

if TYPE_CHECKING:
    from .joints import Joint
    from .system import System

__all__ = [
    "FRICTION_FIELDS",
    "FRICTION_KINDS",
    "FRICTION_LAWS",
    "MODE_HELD",
    "MODE_LOCKED",
    "MODE_SIGN",
    "MODE_SMOOTH",
    "RECORD_FIELDS",
    "Friction",
    "check_friction",
    "friction_record",
    "friction_uses",
    "record_size",
    "stick_constraint_name",
]

#: The joint kinds that take friction, by dimension.
FRICTION_KINDS = {2: ("revolute", "prismatic"), 3: ("revolute", "prismatic")}
#: The friction laws available.
FRICTION_LAWS = ("smooth", "exact")
#: The scalar fields of a joint's record after ``J_rate`` (m), ``W`` (6 x 6), the rows (6), ``u_force`` (3)
#: and ``u_couple`` (3): the numeric form read by both backends (:mod:`kronlag.numeric.friction`).
RECORD_FIELDS = ("static", "kinetic", "viscous", "stribeck_velocity", "radius", "inverse_arm", "preload",
                 "smoothing_velocity", "mode", "hold_row")

# The record's ``mode``: how the law's direction is taken.  The exact law's segments
# (:mod:`kronlag.simulation.stiction`) fix it per joint: +1 or -1 while the joint slides that way (the
# rate may pass through zero inside a step, where the event is located), MODE_HELD while it sticks (the
# law gives no force: the holding row's multiplier, ``hold_row`` of ``[lambda; mu]``, is the friction).
#: ``tanh(v / v_eps)``: the smooth law.
MODE_SMOOTH = 0
#: ``sign(v)``: the exact law outside a run's segments (the trajectory's columns, a single evaluation).
MODE_SIGN = 2
#: Stuck: held by a constraint ``v = 0``.
MODE_HELD = 3
#: Stuck with another: a joint whose rate is zero for every motion the held joints' rows and the constraints
#: allow (locked to a held joint); no row of its own and no force in the equations (its static friction
#: counts in the held group's capacity, :mod:`kronlag.simulation.stiction`).
MODE_LOCKED = 4


@dataclass(frozen=True, kw_only=True)
class Friction:
    """Friction in a joint, proportional to its normal load (see the module docstring for the law).

    Parameters
    ----------
    kinetic : number or expression of the parameters
        ``mu_k``, the sliding coefficient (dimensionless).
    static : optional
        ``mu_s`` (default ``mu_k``); with ``mu_s != mu_k`` a ``stribeck_velocity`` is needed.
    viscous : optional
        ``c`` (N*s/m, or N*m*s/rad for a revolute joint), default 0.
    stribeck_velocity : optional
        ``v_s`` (m/s or rad/s).
    radius : optional
        ``r``, the pin radius (m): required by a revolute joint, not used by a prismatic one.
    arm : optional
        The arm (m) a couple is divided by to give a normal force; absent: couples do not count.
    preload : optional
        ``F0`` (N), default 0.
    law : {"smooth", "exact"}
        ``"smooth"``: ``tanh(v / v_eps)`` in place of ``sign(v)``; ``"exact"``: ``sign(v)`` while the
        joint slides, and a joint whose rate reaches zero sticks, held by a constraint until the
        holding force exceeds ``mu_s N`` (:mod:`kronlag.simulation.stiction`).
    smoothing_velocity : optional
        ``v_eps`` of ``tanh(v / v_eps)`` (m/s or rad/s), default 1e-3.
    """

    kinetic: Any
    static: Any = None
    viscous: Any = 0
    stribeck_velocity: Any = None
    radius: Any = None
    arm: Any = None
    preload: Any = 0
    law: str = "smooth"
    smoothing_velocity: Any = 1e-3

    def __post_init__(self):
        if self.law not in FRICTION_LAWS:
            raise ModelError(f"friction: law must be one of {', '.join(map(repr, FRICTION_LAWS))}, "
                             f"got {self.law!r}")
        for field in fields(self):
            if field.name == "law":
                continue
            value = getattr(self, field.name)
            if value is None:
                continue
            try:
                expression = sp.sympify(value)
            except (sp.SympifyError, TypeError) as error:
                raise ModelError(f"friction {field.name}: expected a number or an expression of the "
                                 f"parameters, got {value!r}") from error
            if not isinstance(expression, sp.Expr):
                raise ModelError(f"friction {field.name}: expected a scalar, got {value!r}")
            if expression.is_number and not (expression.is_real and expression >= 0):
                raise ModelError(f"friction {field.name}: must be a real number >= 0, got {value!r}")
            positive = field.name in ("stribeck_velocity", "smoothing_velocity", "radius", "arm")
            if expression.is_number and positive and expression == 0:
                raise ModelError(f"friction {field.name}: must be > 0, got {value!r}")
            object.__setattr__(self, field.name, expression)
        if self.static is None:
            object.__setattr__(self, "static", self.kinetic)
        if self.law == "smooth" and sp.simplify(self.static - self.kinetic) != 0 and self.stribeck_velocity is None:
            raise ModelError("friction: static != kinetic needs a stribeck_velocity (the speed over which "
                             "mu falls from static to kinetic)")
        excess = sp.simplify(self.static - self.kinetic)
        if excess.is_number and excess < 0:
            raise ModelError(f"friction: static ({self.static}) < kinetic ({self.kinetic})")

    def expressions(self) -> dict[str, sp.Expr]:
        """The given quantities by field name (those left ``None`` are absent)."""
        return {field.name: getattr(self, field.name) for field in fields(self)
                if field.name != "law" and getattr(self, field.name) is not None}

    def as_table(self) -> dict[str, Any]:
        """The fields a model file writes (``law`` and every quantity given), as expressions."""
        return {**self.expressions(), "law": self.law}


#: The fields of :class:`Friction` (a model file's ``friction`` table takes the same keys).
FRICTION_FIELDS = tuple(field.name for field in fields(Friction))


def check_friction(system: System, friction: Friction, kind: str, what: str) -> None:
    """Refuse friction on a joint kind without it, a revolute joint without a radius, and symbols that are
    not parameters (raises ModelError naming ``what``)."""
    if not isinstance(friction, Friction):
        raise ModelError(f"{what}: friction must be a kronlag.Friction, got {type(friction).__name__}")
    dimension = system.dimension
    assert dimension is not None  # add_joint checks it before it checks the friction
    if kind not in FRICTION_KINDS[dimension]:
        raise ModelError(f"{what}: friction is available on {' and '.join(FRICTION_KINDS[dimension])} joints, "
                         f"not on a {dimension}-d {kind} joint")
    if kind == "revolute" and friction.radius is None:
        raise ModelError(f"{what}: friction in a revolute joint needs radius=... (the pin radius)")
    if kind == "prismatic" and friction.radius is not None:
        raise ModelError(f"{what}: a prismatic joint's friction does not use a radius")
    for name, value in friction.expressions().items():
        system._check_symbols(value, f"{what} friction {name}", allow_q=False)


def friction_uses(joint: Joint) -> list[tuple[str, sp.Expr, dict[str, int]]]:
    """``(field, value, dimension)`` of every quantity of ``joint``'s friction, the dimension as powers of
    the base dimensions (:class:`kronlag.model.dimensions.Dimension`): coefficients dimensionless,
    ``radius`` and ``arm`` lengths, ``preload`` a force; the velocities have the rate's dimension (1/time
    for a revolute joint, length/time for a prismatic one) and ``viscous`` a torque or force per rate."""
    revolute = joint.kind == "revolute"
    rate = {"[time]": -1} if revolute else {"[length]": 1, "[time]": -1}
    force = {"[mass]": 1, "[length]": 2 if revolute else 1, "[time]": -2}
    viscous = {base: force.get(base, 0) - rate.get(base, 0) for base in ("[mass]", "[length]", "[time]")}
    dimensions = {"static": {}, "kinetic": {}, "radius": {"[length]": 1}, "arm": {"[length]": 1},
                  "preload": {"[mass]": 1, "[length]": 1, "[time]": -2}, "viscous": viscous,
                  "stribeck_velocity": rate, "smoothing_velocity": rate}
    friction = joint.friction.expressions() if joint.friction is not None else {}
    return [(field, value, dimensions[field]) for field, value in friction.items()]


def stick_constraint_name(joint: str) -> str:
    """The name of the constraint ``v = 0`` that holds a sticking joint (a variant's nonholonomic row)."""
    return f"stick {joint}"


def record_size(m: int) -> int:
    """The length of one joint's record (:func:`friction_record`) for ``m`` coordinates."""
    return m + 36 + 6 + 3 + 3 + len(RECORD_FIELDS)


def _gradient(expression: sp.Expr, coordinates) -> list[sp.Expr]:
    return [sp.diff(expression, q) for q in coordinates]


def _vee_rates(rotation: sp.MatrixBase, coordinates) -> list[sp.Matrix]:
    """Per coordinate ``q_i``: ``vee(R^T dR/dq_i)``, the body-frame angular velocity per unit ``qd_i``."""
    columns = []
    for q in coordinates:
        s = rotation.T * rotation.diff(q)
        columns.append(sp.Matrix([s[2, 1], s[0, 2], s[1, 0]]))
    return columns


def friction_record(system: System, joint: Joint) -> sp.Matrix:
    """The numeric form of ``joint``'s friction, a column of :func:`record_size` expressions of q and the
    parameters: ``J_rate`` (the joint rate ``v = J_rate qd``), ``W`` padded to 6 x 6 (force rows 0..2,
    couple rows 3..5), the indices of its multipliers in ``lambda`` (-1 past its k rows), the unit
    directions whose components are removed from the force and the couple (zero: none), then
    :data:`RECORD_FIELDS`."""
    friction = joint.friction
    assert friction is not None  # called for the joints with friction only
    d = joint.dimension
    geometry = dict(joint.geometry)
    pose_a, pose_b = (Pose(Frame((0,) * d)) if body == GROUND else system.body(body).pose()
                      for body in (joint.body_a, joint.body_b))
    coordinates = system.coordinates
    zero3 = sp.zeros(3, 1)
    u_force = u_couple = zero3
    if joint.kind == "prismatic" or d == 3:
        axis = sp.Matrix(geometry["axis"])
        axis_world = pose_a.frame.direction(axis / sp.sqrt((axis.T * axis)[0, 0]))
        u_force = sp.Matrix([*axis_world, *[0] * (3 - d)])
    if joint.kind == "prismatic":
        separation = pose_b.frame.point(geometry["at_b"]) - pose_a.frame.point(geometry["at_a"])
        rate = _gradient((axis_world.T * separation)[0, 0], coordinates)
    elif d == 2:
        rate = _gradient(pose_b.angle - pose_a.angle, coordinates)
    else:
        u_couple = u_force
        axis_a, axis_b = sp.Matrix(geometry["axis"]), sp.Matrix(geometry.get("axis_b", geometry["axis"]))
        axis_a, axis_b = axis_a / axis_a.norm(), axis_b / axis_b.norm()
        rate = [(axis_b.T * w_b)[0, 0] - (axis_a.T * w_a)[0, 0] for w_b, w_a in
                zip(_vee_rates(pose_b.frame.rotation, coordinates), _vee_rates(pose_a.frame.rotation, coordinates))]
    wrench = sp.zeros(6, 6)
    k = len(joint.constraint_names)
    for i in range(d):
        for j in range(k):
            wrench[i, j] = joint.wrench[i, j]
    for i in range(joint.wrench.rows - d):
        for j in range(k):
            wrench[3 + i, j] = joint.wrench[d + i, j]
    index = {constraint.name: j for j, constraint in enumerate(system.constraints)}
    rows = [index[name] for name in joint.constraint_names] + [-1] * (6 - k)
    values = friction.expressions()
    mode = MODE_SMOOTH if friction.law == "smooth" else getattr(system, "stiction_modes", {}).get(joint.name, MODE_SIGN)
    held = [j for j, constraint in enumerate(system.nonholonomic_constraints)
            if constraint.name == stick_constraint_name(joint.name)]
    hold_row = len(system.constraints) + held[0] if held else -1
    scalars = [values["static"], values["kinetic"], values["viscous"], values.get("stribeck_velocity", 0),
               values.get("radius", 1), 1 / values["arm"] if "arm" in values else 0, values["preload"],
               values["smoothing_velocity"], mode, hold_row]
    return sp.Matrix([*rate, *wrench, *rows, *u_force, *u_couple, *scalars])
