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
:data:`t` may appear in forces only.  Names are unique across coordinates,
speeds, accelerations, parameters, ``t`` and the multiplier symbols
``lambda1, lambda2, ...`` and ``mu1, mu2, ...`` that :func:`kronlag.derive`
creates.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import sympy as sp

__all__ = [
    "t",
    "ModelError",
    "coordinates",
    "speed_symbol",
    "acceleration_symbol",
    "PlanarBody",
    "RigidBody",
    "PointMass",
    "Spring",
    "Damper",
    "DrawingLine",
    "System",
]

#: The time symbol; allowed in applied forces and torques only.
t = sp.Symbol("t")

_MULTIPLIER_NAME = re.compile(r"^(lambda|mu)\d+$")


class ModelError(ValueError):
    """A model description is invalid; the message names the offending item."""


def coordinates(names: str) -> tuple[sp.Symbol, ...]:
    """Create generalized coordinates as plain SymPy symbols.

    >>> coordinates("q1 q2")
    (q1, q2)
    """
    created = sp.symbols(names, seq=True)
    return tuple(created)


def speed_symbol(coordinate: sp.Symbol) -> sp.Symbol:
    """The speed symbol of a coordinate: ``q1`` -> ``q1d``."""
    return sp.Symbol(coordinate.name + "d")


def acceleration_symbol(coordinate: sp.Symbol) -> sp.Symbol:
    """The acceleration symbol of a coordinate: ``q1`` -> ``q1dd``."""
    return sp.Symbol(coordinate.name + "dd")


def _scalar(value, what: str) -> sp.Expr:
    if isinstance(value, str):
        raise ModelError(f"{what}: got the string {value!r}; give a SymPy expression or a number "
                         "(model files are read by kronlag.modelfile, which parses strings safely)")
    try:
        expr = sp.sympify(value, strict=True)
    except (sp.SympifyError, TypeError) as error:
        raise ModelError(f"{what}: expected a SymPy expression or a number, got {type(value).__name__}") from error
    if isinstance(expr, sp.MatrixBase) or not isinstance(expr, sp.Expr):
        raise ModelError(f"{what}: expected a scalar expression, got {type(expr).__name__}")
    return expr


def _matrix(value, shape: tuple[int, int], what: str) -> sp.ImmutableMatrix:
    """Convert to an immutable matrix of the given shape; a vector may be any 1-d sequence."""
    try:
        if shape[1] == 1 and not isinstance(value, sp.MatrixBase):
            rows = [[entry] for entry in value]
        else:
            rows = value
        matrix = sp.Matrix(rows) if not isinstance(rows, sp.MatrixBase) else rows
    except (TypeError, ValueError, sp.SympifyError) as error:
        raise ModelError(f"{what}: expected shape {shape}, could not read {value!r}") from error
    if shape[1] == 1 and matrix.shape == (1, shape[0]):
        matrix = matrix.T
    if matrix.shape != shape:
        raise ModelError(f"{what}: expected shape {shape}, got shape {matrix.shape}")
    return sp.ImmutableMatrix([[_scalar(matrix[i, j], f"{what}[{i},{j}]") for j in range(shape[1])]
                               for i in range(shape[0])])


def _vector(value, what: str, lengths: Sequence[int]) -> sp.ImmutableMatrix:
    if isinstance(value, str) or not isinstance(value, Iterable | sp.MatrixBase):
        raise ModelError(f"{what}: expected a vector of length {' or '.join(map(str, lengths))}, "
                         f"got {type(value).__name__}")
    entries = list(value) if not isinstance(value, sp.MatrixBase) else list(value)
    if isinstance(value, sp.MatrixBase) and 1 not in value.shape:
        raise ModelError(f"{what}: expected a vector, got a matrix of shape {value.shape}")
    if len(entries) not in lengths:
        raise ModelError(f"{what}: expected a vector of length {' or '.join(map(str, lengths))}, "
                         f"got length {len(entries)}")
    return _matrix(entries, (len(entries), 1), what)


@dataclass(frozen=True)
class PlanarBody:
    """A rigid body moving in the plane.

    Parameters
    ----------
    name : str
    mass : expression
        ``m_i``, a parameter or number.
    inertia : expression
        Moment of inertia about the centre of mass, normal to the plane.
    position : 2 expressions of q
        Centre of mass ``(x, y)``.
    angle : expression of q
        Orientation angle; the angular velocity is ``d(angle)/dt``.
    """

    name: str
    mass: sp.Expr
    inertia: sp.Expr
    position: sp.ImmutableMatrix
    angle: sp.Expr

    dimension = 2

    def __init__(self, name: str, *, mass, inertia, position, angle):
        what = f"body {name!r}"
        object.__setattr__(self, "name", _check_name(name, "body"))
        object.__setattr__(self, "mass", _scalar(mass, f"{what} mass"))
        object.__setattr__(self, "inertia", _scalar(inertia, f"{what} inertia"))
        object.__setattr__(self, "position", _vector(position, f"{what} position", (2,)))
        object.__setattr__(self, "angle", _scalar(angle, f"{what} angle"))


@dataclass(frozen=True)
class RigidBody:
    """A rigid body moving in space.

    Parameters
    ----------
    name : str
    mass : expression
    inertia : 3x3 symmetric matrix
        Inertia tensor about the centre of mass in the body frame.
    position : 3 expressions of q
        Centre of mass in the inertial frame.
    rotation : 3x3 matrix of expressions of q
        ``R(q)`` maps body-frame components to inertial components.  The
        body-frame angular velocity ``omega = J_R qd`` follows from the skew
        matrix ``R^T dR/dt`` (Theorem 1).
    simplify : bool
        Apply ``trigsimp`` to the entries of ``J_R`` (default ``True``); worth
        it for Euler-angle rotations, whose ``R^T dR/dq_k`` hides many
        ``sin^2 + cos^2``.
    """

    name: str
    mass: sp.Expr
    inertia: sp.ImmutableMatrix
    position: sp.ImmutableMatrix
    rotation: sp.ImmutableMatrix
    simplify: bool = True

    dimension = 3

    def __init__(self, name: str, *, mass, inertia, position, rotation, simplify: bool = True):
        what = f"body {name!r}"
        object.__setattr__(self, "name", _check_name(name, "body"))
        object.__setattr__(self, "mass", _scalar(mass, f"{what} mass"))
        tensor = _matrix(inertia, (3, 3), f"{what} inertia tensor")
        asymmetric = [(i, j) for i in range(3) for j in range(i + 1, 3)
                      if sp.simplify(tensor[i, j] - tensor[j, i]) != 0]
        if asymmetric:
            i, j = asymmetric[0]
            raise ModelError(f"{what} inertia tensor is not symmetric: entry [{i},{j}] = {tensor[i, j]} "
                             f"but [{j},{i}] = {tensor[j, i]}")
        object.__setattr__(self, "inertia", tensor)
        object.__setattr__(self, "position", _vector(position, f"{what} position", (3,)))
        object.__setattr__(self, "rotation", _matrix(rotation, (3, 3), f"{what} rotation"))
        object.__setattr__(self, "simplify", bool(simplify))


@dataclass(frozen=True)
class PointMass:
    """A particle of mass ``mass`` at ``position`` (2 or 3 expressions of q)."""

    name: str
    mass: sp.Expr
    position: sp.ImmutableMatrix

    def __init__(self, name: str, *, mass, position):
        what = f"body {name!r}"
        object.__setattr__(self, "name", _check_name(name, "body"))
        object.__setattr__(self, "mass", _scalar(mass, f"{what} mass"))
        object.__setattr__(self, "position", _vector(position, f"{what} position", (2, 3)))

    @property
    def dimension(self) -> int:
        return self.position.rows


@dataclass(frozen=True)
class Spring:
    """Linear spring between two points: ``Pi = 1/2 k (|p_a - p_b| - L0)^2``."""

    name: str
    point_a: sp.ImmutableMatrix
    point_b: sp.ImmutableMatrix
    stiffness: sp.Expr
    free_length: sp.Expr

    def potential(self) -> sp.Expr:
        separation = self.point_a - self.point_b
        squared = (separation.T * separation)[0, 0]
        if self.free_length == 0:
            return self.stiffness * squared / 2
        return self.stiffness * (sp.sqrt(squared) - self.free_length) ** 2 / 2


@dataclass(frozen=True)
class Damper:
    """Linear damper between two points: force ``-c dL/dt`` along the line, ``L = |p_a - p_b|``."""

    name: str
    point_a: sp.ImmutableMatrix
    point_b: sp.ImmutableMatrix
    coefficient: sp.Expr


@dataclass(frozen=True)
class DrawingLine:
    """A polyline of points (vectors of expressions of q) drawn in animations; joints are its vertices."""

    name: str
    points: tuple[sp.ImmutableMatrix, ...]


@dataclass(frozen=True)
class _NamedExpression:
    """A named scalar: a constraint or a potential term."""

    name: str
    expression: sp.Expr


@dataclass(frozen=True)
class _AppliedForce:
    """A generalized force, or a force/torque vector mapped through a Jacobian."""

    name: str
    kind: str  # "generalized", "point", "body torque"
    value: sp.ImmutableMatrix
    where: sp.ImmutableMatrix | str | None = None
    frame: str = "world"


def _check_name(name, what: str) -> str:
    if not isinstance(name, str) or not name.strip():
        raise ModelError(f"a {what} needs a non-empty name, got {name!r}")
    return name


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
        self.bodies, self.constraints, self.nonholonomic_constraints = [], [], []
        self.springs, self.dampers, self.potentials, self.forces = [], [], [], []
        self.drawing: list[DrawingLine] = []
        self.traces: list[DrawingLine] = []
        self.points: dict = {}  # name -> kronlag.frames.BodyPoint
        self.joints: list = []  # kronlag.joints.Joint
        if gravity is not None:
            vector = _vector(gravity, "gravity", (2, 3))
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
            if _MULTIPLIER_NAME.match(name):
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
        unknown = sorted(expr.free_symbols - allowed, key=lambda s: s.name)
        if not unknown:
            return
        symbol = unknown[0]
        if symbol in self.coordinates:
            reason = "may not depend on the coordinates"
        elif symbol in self.speeds:
            reason = "may not depend on the speeds"
        elif symbol == t:
            reason = "may not depend on time (only applied forces and torques may)"
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

    # -- building -----------------------------------------------------------

    def add_body(self, body: PlanarBody | RigidBody | PointMass) -> PlanarBody | RigidBody | PointMass:
        """Add a body; its mass and inertia must be constant, its pose depend on q only."""
        if not isinstance(body, PlanarBody | RigidBody | PointMass):
            raise ModelError(f"add_body takes a PlanarBody, RigidBody or PointMass, got {type(body).__name__}")
        what = f"body {body.name!r}"
        self._unique(self.bodies, body.name, "body")
        self._check_dimension(body.dimension, what)
        self._check_symbols(body.mass, f"{what} mass", allow_q=False)
        if getattr(body, "inertia", None) is not None:
            self._check_symbols(sp.Matrix([body.inertia]), f"{what} inertia", allow_q=False)
        self._check_symbols(body.position, f"{what} position")
        if isinstance(body, PlanarBody):
            self._check_symbols(body.angle, f"{what} angle")
        if isinstance(body, RigidBody):
            self._check_symbols(body.rotation, f"{what} rotation")
        self.bodies.append(body)
        return body

    def body(self, name: str) -> PlanarBody | RigidBody | PointMass:
        """The body called ``name``."""
        for body in self.bodies:
            if body.name == name:
                return body
        raise ModelError(f"no body named {name!r}; bodies are {[b.name for b in self.bodies]}")

    def add_point(self, name: str, body: str, local):
        """Name the point with body coordinates ``local`` (from the centre of mass, in the body
        frame) of ``body`` (``"ground"``: world coordinates); returns its
        :class:`kronlag.frames.BodyPoint`, whose ``position`` is the world position ``r(q)``."""
        from .frames import make_body_point

        _check_name(name, "point")
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
        from .joints import add_joint

        return add_joint(self, kind, body_a, body_b, **geometry)

    def add_constraint(self, expression, *, name: str | None = None) -> None:
        """Add a holonomic constraint ``f_j(q) = 0``."""
        name = name or f"constraint {len(self.constraints) + 1}"
        self._unique(self.constraints, name, "constraint")
        expr = _scalar(expression, f"constraint {name!r}")
        if expr.free_symbols & set(self.speeds):
            raise ModelError(f"constraint {name!r} contains speeds; give a velocity constraint with "
                             "add_nonholonomic_constraint")
        self._check_symbols(expr, f"constraint {name!r}")
        if not expr.free_symbols & set(self.coordinates):
            raise ModelError(f"constraint {name!r} does not depend on any coordinate: {expr}")
        self.constraints.append(_NamedExpression(name, expr))

    def add_nonholonomic_constraint(self, expression, *, name: str | None = None) -> None:
        """Add a constraint ``A_k(q) qd + b_k(q) = 0`` given as an expression linear in ``qd``."""
        name = name or f"nonholonomic constraint {len(self.nonholonomic_constraints) + 1}"
        self._unique(self.nonholonomic_constraints, name, "nonholonomic constraint")
        expr = _scalar(expression, f"nonholonomic constraint {name!r}")
        self._check_symbols(expr, f"nonholonomic constraint {name!r}", allow_qd=True)
        speeds = set(self.speeds)
        if not expr.free_symbols & speeds:
            raise ModelError(f"nonholonomic constraint {name!r} does not depend on any speed; "
                             "a constraint on q alone is holonomic (add_constraint)")
        for qd in self.speeds:
            coefficient = sp.diff(expr, qd)
            if coefficient.free_symbols & speeds:
                raise ModelError(f"nonholonomic constraint {name!r} is not linear in the speeds: "
                                 f"its coefficient of {qd} is {coefficient}")
        self.nonholonomic_constraints.append(_NamedExpression(name, expr))

    def add_spring(self, point_a, point_b, *, stiffness, free_length=0, name: str | None = None) -> None:
        """Add a linear spring between two points (vectors of expressions of q)."""
        name = name or f"spring {len(self.springs) + 1}"
        self._unique(self.springs, name, "spring")
        a, b = self._point_pair(point_a, point_b, f"spring {name!r}")
        k = _scalar(stiffness, f"spring {name!r} stiffness")
        length = _scalar(free_length, f"spring {name!r} free length")
        self._check_symbols(k, f"spring {name!r} stiffness", allow_q=False)
        self._check_symbols(length, f"spring {name!r} free length", allow_q=False)
        self.springs.append(Spring(name, a, b, k, length))

    def add_damper(self, point_a, point_b, *, coefficient, name: str | None = None) -> None:
        """Add a linear damper between two points; it enters ``f_Q``."""
        name = name or f"damper {len(self.dampers) + 1}"
        self._unique(self.dampers, name, "damper")
        a, b = self._point_pair(point_a, point_b, f"damper {name!r}")
        c = _scalar(coefficient, f"damper {name!r} coefficient")
        self._check_symbols(c, f"damper {name!r} coefficient", allow_q=False)
        self.dampers.append(Damper(name, a, b, c))

    def _point_pair(self, point_a, point_b, what: str):
        a = _vector(point_a, f"{what} first point", (2, 3))
        b = _vector(point_b, f"{what} second point", (2, 3))
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
        expr = _scalar(expression, f"potential {name!r}")
        self._check_symbols(expr, f"potential {name!r}")
        self.potentials.append(_NamedExpression(name, expr))

    def add_generalized_force(self, force, *, name: str | None = None) -> None:
        """Add generalized non-conservative forces (a vector of length m) to ``f_Q``.

        Entries may depend on q, qd, the parameters and the time :data:`t`.
        """
        name = name or f"generalized force {len(self.forces) + 1}"
        self._unique(self.forces, name, "force")
        vector = _vector(force, f"generalized force {name!r}", (len(self.coordinates),))
        self._check_symbols(vector, f"generalized force {name!r}", allow_qd=True, allow_t=True)
        self.forces.append(_AppliedForce(name, "generalized", vector))

    def add_force(self, point, force, *, name: str | None = None) -> None:
        """Add a force ``F`` (inertial components) acting at ``point``: ``f_Q += J^T F``, ``J = dpoint/dq``."""
        name = name or f"force {len(self.forces) + 1}"
        self._unique(self.forces, name, "force")
        where = _vector(point, f"force {name!r} point", (2, 3))
        vector = _vector(force, f"force {name!r}", (where.rows,))
        self._check_dimension(where.rows, f"force {name!r}")
        self._check_symbols(where, f"force {name!r} point")
        self._check_symbols(vector, f"force {name!r}", allow_qd=True, allow_t=True)
        self.forces.append(_AppliedForce(name, "point", vector, where))

    def add_torque(self, body: str, torque, *, frame: str = "world", name: str | None = None) -> None:
        """Add a torque acting on a body.

        For a planar body ``torque`` is a scalar and ``f_Q += (d angle/dq)^T torque``.
        For a spatial body it is a 3-vector in the inertial (``frame="world"``) or
        body (``frame="body"``) frame and ``f_Q += J_R^T torque_body``.
        """
        name = name or f"torque {len(self.forces) + 1}"
        self._unique(self.forces, name, "force")
        target = self.body(body)
        if isinstance(target, PointMass):
            raise ModelError(f"torque {name!r} acts on point mass {body!r}, which cannot take a torque")
        if frame not in ("world", "body"):
            raise ModelError(f"torque {name!r}: frame must be 'world' or 'body', got {frame!r}")
        if isinstance(target, PlanarBody):
            if isinstance(torque, Iterable) and not isinstance(torque, sp.Expr | str):
                raise ModelError(f"torque {name!r} on planar body {body!r} must be a scalar")
            vector = sp.ImmutableMatrix([_scalar(torque, f"torque {name!r}")])
        else:
            vector = _vector(torque, f"torque {name!r}", (3,))
        self._check_symbols(vector, f"torque {name!r}", allow_qd=True, allow_t=True)
        self.forces.append(_AppliedForce(name, "body torque", vector, body, frame))

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
        vectors = tuple(_vector(point, f"{what} point {k + 1}", (2, 3)) for k, point in enumerate(points))
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
