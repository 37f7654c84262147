"""Model description: coordinates, bodies, forces and constraints.

A :class:`System` collects everything :func:`kronlag.derive` needs.  Every
``add_*`` call validates its item at once and raises :class:`ModelError`
naming the item, so a mistake surfaces where it was made.

Symbols
-------
Coordinates ``q`` are plain SymPy symbols chosen by the user (a redundant set
is allowed).  The speed and acceleration of a coordinate named ``x`` are the
plain symbols ``xd`` and ``xdd`` (see :func:`speed_symbol`).  Every other
symbol in the model must be declared as a parameter; the time symbol
:data:`t` may appear in forces and in holonomic and nonholonomic constraints
(drives: rheonomic constraints, see :meth:`System.add_drive`).  Names are unique across coordinates,
speeds, accelerations, parameters, ``t`` and the multiplier symbols
``lambda1, lambda2, ...`` and ``mu1, mu2, ...`` that :func:`kronlag.derive`
creates.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp

from ..core.errors import ModelError
from .bodies import Body
from .frames import BodyPoint, make_body_point
from .inputs import as_scalar, as_vector
from .joints import Joint, add_joint
from .limits import Limit, make_limit
from .loads import (
    AppliedForce,
    BodyTorque,
    Damper,
    GeneralizedForce,
    Load,
    NamedExpression,
    PointForce,
    Potential,
    Spring,
)
from .structure import describe
from .symbols import MULTIPLIER_NAME, acceleration_symbol, check_name, free_symbols, speed_symbol, t
from .trees import TreeLink, make_tree_link

if TYPE_CHECKING:
    from .robot_formats.description import RobotDescription

__all__ = ["System", "DrawingLine", "drive_name"]


@dataclass(frozen=True)
class DrawingLine:
    """A polyline of points (vectors of expressions of q) drawn in animations; joints are its vertices."""

    name: str
    points: tuple[sp.ImmutableMatrix, ...]


def _loads_of(kind: type[Load], doc: str) -> property:
    """A read-only view of ``system.loads``: those of type ``kind``, as a tuple."""
    return property(lambda system: tuple(load for load in system.loads if isinstance(load, kind)), doc=doc)


def drive_name(target) -> str:
    """The default name of the drive of ``target`` (:meth:`System.add_drive`): ``"drive <target>"``."""
    return f"drive {target}"


class System:
    """A constrained multibody system described with redundant coordinates.

    The equations :func:`kronlag.derive` produces are (Van Khang 2011, Eq. 23)::

        M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
        f(q) = 0,   A(q) qd + b(q) = 0

    Parameters
    ----------
    coordinates : sequence of sympy.Symbol
        The generalized coordinates ``q`` (length m).
    parameters : sequence of sympy.Symbol
        Every other symbol the model uses (lengths, masses, ``g``, ...).
    gravity : vector of 2 or 3 expressions, optional
        Gravitational acceleration; bodies get the potential ``-m gravity . r``.
    name : str
    """

    def __init__(self, coordinates: Sequence[sp.Symbol], *, parameters: Sequence[sp.Symbol] = (),
                 gravity=None, name: str = "system"):
        self.name = name
        self.coordinates = self._symbols(coordinates, "coordinate")
        if not self.coordinates:
            raise ModelError("a system needs at least one coordinate")
        self.parameters = self._symbols(parameters, "parameter")
        self._check_unique_names()
        self.gravity = None
        self.bodies: list[Body] = []
        self.constraints: list[NamedExpression] = []
        self.nonholonomic_constraints: list[NamedExpression] = []
        self.loads: list[Load] = []  # in the order added; springs, dampers, potentials, forces list them by type
        self.drawing: list[DrawingLine] = []
        self.traces: list[DrawingLine] = []
        self.points: dict[str, BodyPoint] = {}
        self.joints: list[Joint] = []
        self.drives: list[str] = []  # names of the constraints added by add_drive
        self.limits: list[Limit] = []
        self.robot: RobotDescription | None = None  # set by the robot file readers (kronlag.model.robot_formats)
        self.tree: list[TreeLink] = []  # a declared kinematic tree (add_tree_link), parents first
        if gravity is not None:
            vector = as_vector(gravity, "gravity", (2, 3))
            self._check_symbols(vector, "gravity", allow_q=False)
            self.gravity = vector

    # -- symbol bookkeeping -------------------------------------------------

    @staticmethod
    def _symbols(items, what: str) -> tuple[sp.Symbol, ...]:
        if isinstance(items, str | sp.Basic):
            raise ModelError(f"{what}s must be a sequence of SymPy symbols, got {items!r}")
        symbols = tuple(items)
        for item in symbols:
            if not isinstance(item, sp.Symbol):
                raise ModelError(f"{what} {item!r} is not a SymPy Symbol (got {type(item).__name__})")
            if isinstance(item, sp.Dummy):
                raise ModelError(f"{what} {item.name} is a Dummy; use sp.Symbol({item.name!r})")
        return symbols

    @property
    def speeds(self) -> tuple[sp.Symbol, ...]:
        """``qd``: one speed symbol per coordinate."""
        return tuple(speed_symbol(q) for q in self.coordinates)

    @property
    def accelerations(self) -> tuple[sp.Symbol, ...]:
        """``qdd``: one acceleration symbol per coordinate."""
        return tuple(acceleration_symbol(q) for q in self.coordinates)

    def _check_unique_names(self) -> None:
        seen: dict[str, str] = {"t": "the time symbol"}
        entries = ([(q.name, f"coordinate {q.name}") for q in self.coordinates]
                   + [(s.name, f"speed of coordinate {q.name}") for q, s in zip(self.coordinates, self.speeds)]
                   + [(a.name, f"acceleration of coordinate {q.name}")
                      for q, a in zip(self.coordinates, self.accelerations)]
                   + [(p.name, f"parameter {p.name}") for p in self.parameters])
        for name, role in entries:
            if name in seen:
                raise ModelError(f"the name {name!r} is used twice: {seen[name]} and {role}")
            if MULTIPLIER_NAME.match(name):
                raise ModelError(f"{role}: the name {name!r} is reserved for the multipliers lambda_j / mu_k")
            seen[name] = role

    def _check_symbols(self, expr, what: str, *, allow_q: bool = True, allow_qd: bool = False,
                       allow_t: bool = False) -> None:
        allowed = set(self.parameters)
        if allow_q:
            allowed |= set(self.coordinates)
        if allow_qd:
            allowed |= set(self.speeds)
        if allow_t:
            allowed.add(t)
        unknown = sorted(free_symbols(expr) - allowed, key=lambda s: s.name)
        if not unknown:
            return
        symbol = unknown[0]
        if symbol in self.coordinates:
            reason = "may not depend on the coordinates"
        elif symbol in self.speeds:
            reason = "may not depend on the speeds"
        elif symbol == t:
            reason = "may not depend on time (only applied forces, torques and constraints may)"
        elif symbol.name in {s.name for s in (*self.coordinates, *self.speeds, *self.parameters, t)}:
            reason = ("uses a symbol that has the name of a declared one but other assumptions"
                      " (use plain sp.Symbol(name))")
        else:
            reason = ("uses a symbol that is neither a coordinate nor a declared parameter"
                      " (add it to parameters=...)")
        raise ModelError(f"{what} {reason}: {', '.join(s.name for s in unknown)}")

    def _check_dimension(self, dimension: int, what: str) -> None:
        existing = self.dimension
        if existing is not None and existing != dimension:
            raise ModelError(f"{what} is {dimension}-dimensional but the system is {existing}-dimensional "
                             f"({'gravity' if self.gravity is not None else 'its bodies'})")

    @property
    def dimension(self) -> int | None:
        """2 for a planar system, 3 for a spatial one, ``None`` while undetermined."""
        if self.gravity is not None:
            return self.gravity.rows
        for body in self.bodies:
            return body.dimension
        return None

    def _unique(self, collection, name: str, what: str) -> None:
        if any(item.name == name for item in collection):
            raise ModelError(f"duplicate {what} name {name!r}")

    # -- the loads, by type (views of ``loads``) ------------------------------

    springs = _loads_of(Spring, "The springs, in the order added.")
    dampers = _loads_of(Damper, "The dampers, in the order added.")
    potentials = _loads_of(Potential, "The potential energy terms of :meth:`add_potential`, in the order added.")
    forces = _loads_of(AppliedForce, "The applied forces, torques and generalized forces, in the order added.")

    # -- building -----------------------------------------------------------

    def describe(self) -> str:
        """The structure report: bodies, joints, loop-closing constraints, Grübler count
        (:func:`kronlag.model.structure.describe`)."""
        return describe(self)

    def add_body(self, body: Body) -> Body:
        """Add a body (a :class:`~kronlag.model.bodies.Body`: a PlanarBody, RigidBody, PointMass...);
        its mass and inertia must be constant, its pose depend on q only."""
        if not isinstance(body, Body):
            raise ModelError(f"add_body takes a PlanarBody, RigidBody, PointMass or another Body, "
                             f"got {type(body).__name__}")
        what = f"body {body.name!r}"
        self._unique(self.bodies, body.name, "body")
        self._check_dimension(body.dimension, what)
        for field, expression, varies in body.expressions():
            self._check_symbols(expression, f"{what} {field}", allow_q=varies)
        self.bodies.append(body)
        return body

    def body(self, name: str) -> Body:
        """The body called ``name``."""
        for body in self.bodies:
            if body.name == name:
                return body
        raise ModelError(f"no body named {name!r}; bodies are {[b.name for b in self.bodies]}")

    def add_tree_link(self, body: str, coordinate: sp.Symbol, *, parent: str = "ground",
                      joint: str = "revolute", origin=None, angle=0, rotation=None, axis=None,
                      centre=None) -> TreeLink:
        """Declare that ``body`` hangs from ``parent`` by a one-coordinate joint (a declared tree,
        :mod:`kronlag.model.trees`), so that ``M`` and ``C qd + g`` may be computed recursively.

        The declaration does not change the equations (the bodies' own expressions define them);
        before relying on it, the C and Python kernels check that it reproduces every body's pose at
        random states and otherwise keep the flat kernel with a ``TreeDeclarationWarning`` naming the
        body (:func:`kronlag.numeric.codegen.recursive.dynamics_algorithm` says which is used).

        Parameters
        ----------
        body : str
            An added body not yet in the tree.
        coordinate : sympy.Symbol
            The joint's coordinate (a coordinate of the System, one link each).
        parent : str
            A body declared before, or ``"ground"``.
        joint : {"revolute", "prismatic"}
        origin : vector of 2 (planar) or 3 expressions, optional
            The joint's place in the parent's frame (default: its origin).
        angle : expression, optional
            Planar: the joint frame's turn in the parent's frame at ``coordinate = 0``.
        rotation : 3x3 matrix, optional
            Spatial: the joint frame's axes in the parent's frame (default: the parent's).
        axis : vector of 2 or 3 numbers, optional
            The joint axis in the joint frame (planar revolute: z, not given; planar prismatic:
            default ``(1, 0)``; spatial: required).
        centre : vector of 2 or 3 expressions, optional
            The body's centre of mass in the link frame (default: the joint).

        Returns
        -------
        TreeLink
        """
        what = f"tree link {body!r}"
        if self.dimension not in (2, 3):
            raise ModelError(f"{what}: add the bodies (or gravity) first: the tree is planar or spatial")
        self.body(body)
        if any(link.body == body for link in self.tree):
            raise ModelError(f"{what}: body {body!r} is already in the tree")
        if parent != "ground" and not any(link.body == parent for link in self.tree):
            raise ModelError(f"{what}: parent {parent!r} must be 'ground' or a body declared before it")
        if coordinate not in self.coordinates:
            raise ModelError(f"{what}: {coordinate!r} is not a coordinate of the system")
        if any(link.coordinate == coordinate for link in self.tree):
            raise ModelError(f"{what}: coordinate {coordinate} already moves another link")
        planar = self.dimension == 2
        link = make_tree_link(body, coordinate, parent=parent, joint=joint,
                              origin=(0,) * self.dimension if origin is None else origin, angle=angle,
                              rotation=rotation, axis=axis,
                              centre=(0,) * self.dimension if centre is None else centre, planar=planar)
        self._check_symbols(sp.Matrix([*link.origin, *link.rotation, *link.centre]), what, allow_q=False)
        self.tree.append(link)
        return link

    def add_point(self, name: str, body: str, local):
        """Name the point with body coordinates ``local`` (from the centre of mass, in the body
        frame) of ``body`` (``"ground"``: world coordinates); returns its
        :class:`kronlag.frames.BodyPoint`, whose ``position`` is the world position ``r(q)``."""
        check_name(name, "point")
        if name in self.points:
            raise ModelError(f"duplicate point name {name!r}")
        point = make_body_point(self, name, body, local)
        self._check_symbols(point.position, f"point {name!r}")
        self.points[name] = point
        return point

    def point(self, name: str):
        """The :class:`kronlag.frames.BodyPoint` called ``name``."""
        if name not in self.points:
            raise ModelError(f"no point named {name!r}; points are {list(self.points)}")
        return self.points[name]

    def add_joint(self, kind: str, body_a: str, body_b: str, **geometry):
        """Add a joint between ``body_a`` (or ``"ground"``) and ``body_b``: its named constraint
        rows ``"<name>.x"``, ... ; see :func:`kronlag.joints.add_joint` for kinds and geometry."""
        return add_joint(self, kind, body_a, body_b, **geometry)

    def add_constraint(self, expression, *, name: str | None = None) -> None:
        """Add a holonomic constraint ``f_j(q, t) = 0``.

        A constraint that depends on the time :data:`t` is rheonomic (a drive, see
        :meth:`add_drive`): its velocity and acceleration levels are
        ``Phi_q qd + Phi_t = 0`` and ``Phi_q qdd = gamma`` with
        ``gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt``.
        """
        name = name or f"constraint {len(self.constraints) + 1}"
        self._unique(self.constraints, name, "constraint")
        expr = as_scalar(expression, f"constraint {name!r}")
        if free_symbols(expr) & set(self.speeds):
            raise ModelError(f"constraint {name!r} contains speeds; give a velocity constraint with "
                             "add_nonholonomic_constraint")
        self._check_symbols(expr, f"constraint {name!r}", allow_t=True)
        if not free_symbols(expr) & set(self.coordinates):
            raise ModelError(f"constraint {name!r} does not depend on any coordinate: {expr}")
        self.constraints.append(NamedExpression(name, expr))

    def add_drive(self, target, motion, *, name: str | None = None) -> str:
        """Prescribe ``target(q) = motion(t)``: the rheonomic constraint ``target - motion = 0``.

        The drive's multiplier ``lambda_j`` is then its force: the generalized force
        ``u = -lambda_j`` that the drive applies along ``target`` (a torque for an
        angle, a force for a length); it appears by name among the reactions and in
        :func:`kronlag.inverse_dynamics`.

        Parameters
        ----------
        target : coordinate symbol, coordinate name or expression of q
            What is driven: a coordinate, or e.g. a component of a point's position
            (``system.point("P").position[0]``).
        motion : expression of t and the parameters
            Its prescribed value; differentiated twice symbolically.
        name : str, optional
            The constraint's name (default ``"drive <target>"``).

        Returns
        -------
        str
            The name of the drive's constraint.
        """
        by_name = {q.name: q for q in self.coordinates}
        if isinstance(target, str):
            if target not in by_name:
                raise ModelError(f"drive of {target!r}: no such coordinate; coordinates are {list(by_name)}")
            target = by_name[target]
        what = f"drive {name!r}" if name else f"drive of {target}"
        target = as_scalar(target, what)
        motion = as_scalar(motion, f"{what} motion")
        self._check_symbols(motion, f"{what} motion", allow_q=False, allow_t=True)
        name = name or drive_name(target)
        self.add_constraint(target - motion, name=name)
        self.drives.append(name)
        return name

    def add_limit(self, expression, *, lower=None, upper=None, restitution=0, name: str | None = None) -> Limit:
        """Bound ``lower <= expression(q) <= upper`` (either bound may be absent): a stop.

        At contact Newton's restitution law applies (post-impact gap speed ``-e`` times the
        impact speed, every constraint kept); a contact that persists is held as a constraint
        until its force would pull; see :mod:`kronlag.simulation.impacts` and docs/limits.md.
        ``restitution`` and the bounds may use parameters; the initial state must lie within.
        """
        name = name or f"limit {len(self.limits) + 1}"
        check_name(name, "limit")
        self._unique(self.limits, name, "limit")
        limit = make_limit(name, expression, lower, upper, restitution, self.coordinates)
        self._check_symbols(limit.value, f"limit {name!r}")
        for label, bound in (("lower bound", limit.lower), ("upper bound", limit.upper),
                             ("restitution", limit.restitution)):
            if bound is not None:
                self._check_symbols(bound, f"limit {name!r} {label}", allow_q=False)
        self.limits.append(limit)
        return limit

    def add_nonholonomic_constraint(self, expression, *, name: str | None = None) -> None:
        """Add a constraint ``A_k(q) qd + b_k(q) = 0`` given as an expression linear in ``qd``."""
        name = name or f"nonholonomic constraint {len(self.nonholonomic_constraints) + 1}"
        self._unique(self.nonholonomic_constraints, name, "nonholonomic constraint")
        expr = as_scalar(expression, f"nonholonomic constraint {name!r}")
        self._check_symbols(expr, f"nonholonomic constraint {name!r}", allow_qd=True, allow_t=True)
        speeds = set(self.speeds)
        if not free_symbols(expr) & speeds:
            raise ModelError(f"nonholonomic constraint {name!r} does not depend on any speed; "
                             "a constraint on q alone is holonomic (add_constraint)")
        for qd in self.speeds:
            coefficient = sp.diff(expr, qd)
            if free_symbols(coefficient) & speeds:
                raise ModelError(f"nonholonomic constraint {name!r} is not linear in the speeds: "
                                 f"its coefficient of {qd} is {coefficient}")
        self.nonholonomic_constraints.append(NamedExpression(name, expr))

    def add_spring(self, point_a, point_b, *, stiffness, free_length=0, name: str | None = None) -> None:
        """Add a linear spring between two points (vectors of expressions of q)."""
        name = name or f"spring {len(self.springs) + 1}"
        self._unique(self.springs, name, "spring")
        a, b = self._point_pair(point_a, point_b, f"spring {name!r}")
        k = as_scalar(stiffness, f"spring {name!r} stiffness")
        length = as_scalar(free_length, f"spring {name!r} free length")
        self._check_symbols(k, f"spring {name!r} stiffness", allow_q=False)
        self._check_symbols(length, f"spring {name!r} free length", allow_q=False)
        self.loads.append(Spring(name, a, b, k, length))

    def add_damper(self, point_a, point_b, *, coefficient, name: str | None = None) -> None:
        """Add a linear damper between two points; it enters ``f_Q``."""
        name = name or f"damper {len(self.dampers) + 1}"
        self._unique(self.dampers, name, "damper")
        a, b = self._point_pair(point_a, point_b, f"damper {name!r}")
        c = as_scalar(coefficient, f"damper {name!r} coefficient")
        self._check_symbols(c, f"damper {name!r} coefficient", allow_q=False)
        self.loads.append(Damper(name, a, b, c))

    def _point_pair(self, point_a, point_b, what: str):
        a = as_vector(point_a, f"{what} first point", (2, 3))
        b = as_vector(point_b, f"{what} second point", (2, 3))
        if a.rows != b.rows:
            raise ModelError(f"{what}: its points have lengths {a.rows} and {b.rows}")
        self._check_dimension(a.rows, what)
        self._check_symbols(a, f"{what} first point")
        self._check_symbols(b, f"{what} second point")
        return a, b

    def add_potential(self, expression, *, name: str | None = None) -> None:
        """Add a potential energy term ``Pi(q)``; it enters ``g = (dPi/dq)^T``."""
        name = name or f"potential {len(self.potentials) + 1}"
        self._unique(self.potentials, name, "potential")
        expr = as_scalar(expression, f"potential {name!r}")
        self._check_symbols(expr, f"potential {name!r}")
        self.loads.append(Potential(name, expr))

    def add_generalized_force(self, force, *, name: str | None = None) -> None:
        """Add generalized non-conservative forces (a vector of length m) to ``f_Q``.

        Entries may depend on q, qd, the parameters and the time :data:`t`.
        """
        name = name or f"generalized force {len(self.forces) + 1}"
        self._unique(self.forces, name, "force")
        vector = as_vector(force, f"generalized force {name!r}", (len(self.coordinates),))
        self._check_symbols(vector, f"generalized force {name!r}", allow_qd=True, allow_t=True)
        self.loads.append(GeneralizedForce(name, vector))

    def add_force(self, point, force, *, name: str | None = None) -> None:
        """Add a force ``F`` (inertial components) acting at ``point``: ``f_Q += J^T F``, ``J = dpoint/dq``."""
        name = name or f"force {len(self.forces) + 1}"
        self._unique(self.forces, name, "force")
        where = as_vector(point, f"force {name!r} point", (2, 3))
        vector = as_vector(force, f"force {name!r}", (where.rows,))
        self._check_dimension(where.rows, f"force {name!r}")
        self._check_symbols(where, f"force {name!r} point")
        self._check_symbols(vector, f"force {name!r}", allow_qd=True, allow_t=True)
        self.loads.append(PointForce(name, vector, where))

    def add_torque(self, body: str, torque, *, frame: str = "world", name: str | None = None) -> None:
        """Add a torque acting on a body.

        For a planar body ``torque`` is a scalar and ``f_Q += (d angle/dq)^T torque``.
        For a spatial body it is a 3-vector in the inertial (``frame="world"``) or
        body (``frame="body"``) frame and ``f_Q += J_R^T torque_body``.
        """
        name = name or f"torque {len(self.forces) + 1}"
        self._unique(self.forces, name, "force")
        target = self.body(body)
        vector = target.torque_components(torque, f"torque {name!r}")
        if frame not in ("world", "body"):
            raise ModelError(f"torque {name!r}: frame must be 'world' or 'body', got {frame!r}")
        self._check_symbols(vector, f"torque {name!r}", allow_qd=True, allow_t=True)
        self.loads.append(BodyTorque(name, vector, target, frame))

    def add_drawing_line(self, points, *, name: str | None = None) -> None:
        """Add a polyline for animations: links are drawn as lines, joints as dots at the vertices."""
        name = name or f"line {len(self.drawing) + 1}"
        self._unique(self.drawing, name, "drawing line")
        self.drawing.append(DrawingLine(name, self._drawing_points(points, f"drawing line {name!r}")))

    def add_trace(self, point, *, name: str | None = None) -> None:
        """Mark a point whose path animations draw."""
        name = name or f"trace {len(self.traces) + 1}"
        self._unique(self.traces, name, "trace")
        self.traces.append(DrawingLine(name, self._drawing_points([point], f"trace {name!r}")))

    def _drawing_points(self, points, what: str) -> tuple[sp.ImmutableMatrix, ...]:
        if isinstance(points, str) or not isinstance(points, Iterable):
            raise ModelError(f"{what}: expected a sequence of points, got {type(points).__name__}")
        vectors = tuple(as_vector(point, f"{what} point {k + 1}", (2, 3)) for k, point in enumerate(points))
        if not vectors:
            raise ModelError(f"{what}: needs at least one point")
        for k, vector in enumerate(vectors):
            self._check_dimension(vector.rows, f"{what} point {k + 1}")
            self._check_symbols(vector, f"{what} point {k + 1}")
        return vectors

    @property
    def degrees_of_freedom(self) -> int:
        """``n = m - r - s`` (assuming independent constraints)."""
        return len(self.coordinates) - len(self.constraints) - len(self.nonholonomic_constraints)

    def __repr__(self) -> str:
        return (f"System({self.name!r}, m={len(self.coordinates)}, bodies={len(self.bodies)}, "
                f"r={len(self.constraints)}, s={len(self.nonholonomic_constraints)})")

