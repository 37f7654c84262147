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

import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp

__all__ = [
    "t",
    "ModelError",
    "coordinates",
    "speed_symbol",
    "acceleration_symbol",
    "PlanarBody",
    "RigidBody",
    "RotationSequence",
    "MAX_ROTATION_FACTORS",
    "check_parameter_values",
    "PointMass",
    "Spring",
    "Damper",
    "DrawingLine",
    "System",
    "drive_name",
]

#: The time symbol; allowed in applied forces and torques and in constraints (drives).
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


#: Most elementary rotations in one :class:`RotationSequence`; more would make the rotation
#: matrix, and every derivative of it, grow beyond what :func:`kronlag.derive` handles quickly.
MAX_ROTATION_FACTORS = 16

_PRINCIPAL_AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def _axis_rotation(axis: sp.ImmutableMatrix, angle: sp.Expr) -> sp.ImmutableMatrix:
    """Rodrigues' formula ``I + sin(angle) [u]x + (1 - cos(angle)) [u]x^2`` for a unit axis ``u``."""
    cross = sp.Matrix([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return sp.ImmutableMatrix(sp.eye(3) + sp.sin(angle) * cross + (1 - sp.cos(angle)) * cross * cross)


@dataclass(frozen=True)
class RotationSequence:
    """A rotation composed of elementary rotations, ``R = R_1(angle_1) R_2(angle_2) ... R_n(angle_n)``.

    ``R_k`` turns by ``angle_k`` (an expression of q and parameters) about the constant unit
    axis ``u_k``.  Because the factors are known, the body-frame angular velocity needs no
    simplification (see :meth:`body_axes`)::

        omega_body = sum_k (R_{k+1} ... R_n)^T u_k d(angle_k)/dt

    Parameters
    ----------
    factors : sequence of (axis, angle)
        ``axis`` is ``"x"``, ``"y"``, ``"z"`` or a constant unit 3-vector; at most
        :data:`MAX_ROTATION_FACTORS` factors.

    Examples
    --------
    >>> import sympy as sp
    >>> psi, theta = sp.symbols("psi theta")
    >>> RotationSequence([("z", psi), ("x", theta)]).matrix[2, :]
    Matrix([[0, sin(theta), cos(theta)]])
    """

    factors: tuple[tuple[sp.ImmutableMatrix, sp.Expr], ...]

    def __init__(self, factors, *, what: str = "rotation sequence"):
        if isinstance(factors, str) or not isinstance(factors, Iterable):
            raise ModelError(f"{what}: expected a sequence of (axis, angle) pairs, got {type(factors).__name__}")
        pairs = list(factors)
        if not pairs:
            raise ModelError(f"{what}: needs at least one elementary rotation")
        if len(pairs) > MAX_ROTATION_FACTORS:
            raise ModelError(f"{what}: {len(pairs)} elementary rotations, at most {MAX_ROTATION_FACTORS} "
                             "are allowed (compose them with fewer factors)")
        checked = []
        for k, pair in enumerate(pairs):
            if isinstance(pair, str) or not isinstance(pair, Sequence) or len(pair) != 2:
                raise ModelError(f"{what} factor {k}: expected a pair (axis, angle), got {pair!r}")
            axis, angle = pair
            if isinstance(axis, str):
                if axis not in _PRINCIPAL_AXES:
                    raise ModelError(f"{what} factor {k}: axis must be 'x', 'y', 'z' or a unit 3-vector, "
                                     f"got {axis!r}")
                axis = _PRINCIPAL_AXES[axis]
            vector = _vector(axis, f"{what} factor {k} axis", (3,))
            norm_error = sp.simplify((vector.T * vector)[0, 0] - 1)
            if norm_error != 0:
                raise ModelError(f"{what} factor {k}: the axis {list(vector)} is not a unit vector "
                                 f"(|u|^2 - 1 = {norm_error})")
            checked.append((vector, _scalar(angle, f"{what} factor {k} angle")))
        object.__setattr__(self, "factors", tuple(checked))

    def _factor_matrix(self, k: int) -> sp.ImmutableMatrix:
        axis, angle = self.factors[k]
        principal = next((name for name, unit in _PRINCIPAL_AXES.items() if list(axis) == list(unit)), None)
        if principal is None:
            return _axis_rotation(axis, angle)
        c, s = sp.cos(angle), sp.sin(angle)
        return sp.ImmutableMatrix({"x": [[1, 0, 0], [0, c, -s], [0, s, c]],
                                   "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
                                   "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[principal])

    @property
    def matrix(self) -> sp.ImmutableMatrix:
        """``R`` (3x3): maps body-frame components to the frame the sequence starts in."""
        rotation = sp.eye(3)
        for k in range(len(self.factors)):
            rotation = rotation * self._factor_matrix(k)
        return sp.ImmutableMatrix(rotation)

    def body_axes(self) -> list[tuple[sp.ImmutableMatrix, sp.Expr]]:
        """``[(w_k, angle_k)]`` with ``w_k = (R_{k+1} ... R_n)^T u_k``, the axis of factor k in the body
        frame, so that ``omega_body = sum_k w_k d(angle_k)/dt``."""
        result = []
        tail = sp.eye(3)
        for k in reversed(range(len(self.factors))):
            axis, angle = self.factors[k]
            result.append((sp.ImmutableMatrix(tail.T * axis), angle))
            tail = self._factor_matrix(k) * tail
        return result[::-1]


#: Random points at which a rotation matrix is checked numerically for orthogonality.
_ORTHOGONALITY_POINTS = 4
#: Relative tolerance of the numeric orthogonality check.
_ORTHOGONALITY_TOLERANCE = 1e-9
#: Largest operation count of an entry of ``R^T R - I`` that is simplified symbolically.
_SYMBOLIC_CHECK_OPERATIONS = 40


def _check_rotation(rotation: sp.ImmutableMatrix, what: str) -> None:
    """Raise :class:`ModelError` unless ``rotation`` is orthogonal with determinant +1.

    Entries of ``R^T R - I`` small enough are simplified symbolically (a zero is a
    proof); otherwise, or if some entry does not simplify to zero, ``R`` is evaluated at
    :data:`_ORTHOGONALITY_POINTS` random points of its symbols (uniform in [-2, 2]).  A
    rotation written with Euler parameters is orthogonal only on their normalization
    constraint: ``R^T R = s(q) I`` with a factor ``s`` that varies with the coordinates is
    accepted as such, a constant factor other than 1 is not.
    """
    deviation = rotation.T * rotation - sp.eye(3)
    if all(sp.count_ops(entry) <= _SYMBOLIC_CHECK_OPERATIONS for entry in deviation):
        if (all(sp.trigsimp(sp.expand(entry)) == 0 for entry in deviation)
                and sp.trigsimp(sp.expand(rotation.det())) == 1):
            return
    symbols = sorted(rotation.free_symbols, key=lambda symbol: symbol.name)
    evaluate = sp.lambdify(symbols, rotation, modules="numpy")
    generator = np.random.default_rng(20111)
    points: list[tuple[dict, np.ndarray]] = []
    for _ in range(10 * _ORTHOGONALITY_POINTS):
        values = generator.uniform(-2.0, 2.0, len(symbols))
        with np.errstate(all="ignore"):
            try:
                matrix = np.array(evaluate(*values), dtype=float)
            except (ZeroDivisionError, ValueError, TypeError, OverflowError):
                continue
        if np.all(np.isfinite(matrix)):
            points.append((dict(zip((s.name for s in symbols), values)), matrix))
        if len(points) == _ORTHOGONALITY_POINTS:
            break
    if not points:
        raise ModelError(f"{what} cannot be evaluated at random values of its symbols "
                         f"{', '.join(s.name for s in symbols)} (to check that it is orthogonal)")
    scales = []
    for point, matrix in points:
        gram = matrix.T @ matrix
        scale = np.trace(gram) / 3
        where = ", ".join(f"{name}={value:.4g}" for name, value in point.items()) or "its constant value"
        off = np.abs(gram - scale * np.eye(3))
        if off.max() > _ORTHOGONALITY_TOLERANCE * max(1.0, scale):
            i, j = np.unravel_index(np.argmax(off), off.shape)
            expected = f"{scale:.6g}" if i == j else "0"
            raise ModelError(f"{what} is not orthogonal: (R^T R)[{i},{j}] = {gram[i, j]:.6g}, expected {expected} "
                             f"(columns {i} and {j} of R are not orthonormal) at {where}")
        determinant = np.linalg.det(matrix)
        if determinant <= 0:
            raise ModelError(f"{what} has determinant {determinant:.6g} at {where}: "
                             "it is a reflection, not a rotation (expected +1)")
        scales.append(scale)
    if np.ptp(scales) <= _ORTHOGONALITY_TOLERANCE and abs(scales[0] - 1) > _ORTHOGONALITY_TOLERANCE:
        where = ", ".join(f"{name}={value:.4g}" for name, value in points[0][0].items()) or "its constant value"
        raise ModelError(f"{what} is not orthogonal: R^T R = {scales[0]:.6g} I (expected the identity, "
                         f"(R^T R)[0,0] = {scales[0]:.6g}) at {where}")


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
    rotation : 3x3 matrix of expressions of q, or RotationSequence
        ``R(q)`` maps body-frame components to inertial components; it must be orthogonal
        with determinant +1 (checked symbolically where cheap, else numerically at random
        points; the error names the entry of ``R^T R`` that is off).  The body-frame
        angular velocity is ``omega = J_R qd``.  For a :class:`RotationSequence` ``J_R``
        follows from the factors' axes (no simplification needed); for a matrix, its
        column k is ``vee(R^T dR/dq_k)`` (Theorem 1).
    simplify : bool
        For a rotation given as a matrix: apply ``trigsimp`` to the entries of ``J_R``
        (default ``True``) that are small enough for it to be cheap (at most
        ``kronlag.derivation.TRIGSIMP_MAX_OPERATIONS`` operations); larger entries are kept
        as they are, so that the cost stays bounded.  Worth it for Euler-angle rotations,
        whose ``R^T dR/dq_k`` hides many ``sin^2 + cos^2``.
    """

    name: str
    mass: sp.Expr
    inertia: sp.ImmutableMatrix
    position: sp.ImmutableMatrix
    rotation: sp.ImmutableMatrix
    simplify: bool = True
    rotation_sequence: RotationSequence | None = None

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
        if isinstance(rotation, RotationSequence):
            object.__setattr__(self, "rotation_sequence", rotation)
            object.__setattr__(self, "rotation", rotation.matrix)
        else:
            object.__setattr__(self, "rotation_sequence", None)
            matrix = _matrix(rotation, (3, 3), f"{what} rotation")
            _check_rotation(matrix, f"{what} rotation")
            object.__setattr__(self, "rotation", matrix)
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
        self.bodies, self.constraints, self.nonholonomic_constraints = [], [], []
        self.springs, self.dampers, self.potentials, self.forces = [], [], [], []
        self.drawing: list[DrawingLine] = []
        self.traces: list[DrawingLine] = []
        self.points: dict = {}  # name -> kronlag.frames.BodyPoint
        self.joints: list = []  # kronlag.joints.Joint
        self.drives: list[str] = []  # names of the constraints added by add_drive
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
        """Add a holonomic constraint ``f_j(q, t) = 0``.

        A constraint that depends on the time :data:`t` is rheonomic (a drive, see
        :meth:`add_drive`): its velocity and acceleration levels are
        ``Phi_q qd + Phi_t = 0`` and ``Phi_q qdd = gamma`` with
        ``gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt``.
        """
        name = name or f"constraint {len(self.constraints) + 1}"
        self._unique(self.constraints, name, "constraint")
        expr = _scalar(expression, f"constraint {name!r}")
        if expr.free_symbols & set(self.speeds):
            raise ModelError(f"constraint {name!r} contains speeds; give a velocity constraint with "
                             "add_nonholonomic_constraint")
        self._check_symbols(expr, f"constraint {name!r}", allow_t=True)
        if not expr.free_symbols & set(self.coordinates):
            raise ModelError(f"constraint {name!r} does not depend on any coordinate: {expr}")
        self.constraints.append(_NamedExpression(name, expr))

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
        target = _scalar(target, what)
        motion = _scalar(motion, f"{what} motion")
        self._check_symbols(motion, f"{what} motion", allow_q=False, allow_t=True)
        name = name or drive_name(target)
        self.add_constraint(target - motion, name=name)
        self.drives.append(name)
        return name

    def add_nonholonomic_constraint(self, expression, *, name: str | None = None) -> None:
        """Add a constraint ``A_k(q) qd + b_k(q) = 0`` given as an expression linear in ``qd``."""
        name = name or f"nonholonomic constraint {len(self.nonholonomic_constraints) + 1}"
        self._unique(self.nonholonomic_constraints, name, "nonholonomic constraint")
        expr = _scalar(expression, f"nonholonomic constraint {name!r}")
        self._check_symbols(expr, f"nonholonomic constraint {name!r}", allow_qd=True, allow_t=True)
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


#: Relative tolerance of the physical checks of :func:`check_parameter_values`.
_PHYSICAL_TOLERANCE = 1e-9


def check_parameter_values(system: System, values: Mapping[str, float]) -> None:
    """Check that the bodies are physical for the given parameter values.

    Every mass must be non-negative (zero is allowed for an auxiliary massless body; a mass
    matrix left singular by it is reported by ``forward_dynamics``); a planar moment of
    inertia non-negative; a spatial
    inertia tensor ``I`` positive semidefinite with principal moments ``I_1, I_2, I_3``
    satisfying the triangle inequalities ``I_a + I_b >= I_c`` (a real mass distribution
    has them).  :class:`kronlag.NumericModel` calls this with the values it was given.

    Parameters
    ----------
    system : System
    values : mapping of parameter name to float

    Raises
    ------
    ModelError
        Naming the body, the quantity and its value.
    """
    symbols = {symbol: sp.Float(float(values[symbol.name])) for symbol in system.parameters if symbol.name in values}

    def number(expr, what: str) -> float:
        value = sp.sympify(expr).xreplace(symbols)
        if value.free_symbols:
            raise ModelError(f"{what} depends on {', '.join(sorted(s.name for s in value.free_symbols))}, "
                             "which have no value")
        if value.is_real is False:  # reported by the code generation, with the matrix entry
            raise _NotReal
        return float(value)

    for body in system.bodies:
        try:
            _check_body(body, number)
        except _NotReal:
            continue


class _NotReal(Exception):
    """A body's mass or inertia is not a real number (see :func:`check_parameter_values`)."""


def _check_body(body, number: Callable[[object, str], float]) -> None:
    """The checks of :func:`check_parameter_values` for one body."""
    what = f"body {body.name!r}"
    mass = number(body.mass, f"{what} mass")
    if not mass >= 0:
        raise ModelError(f"{what}: mass = {mass:.6g} ({body.mass}); a mass must not be negative")
    if isinstance(body, PlanarBody):
        inertia = number(body.inertia, f"{what} inertia")
        if inertia < 0:
            raise ModelError(f"{what}: moment of inertia = {inertia:.6g} ({body.inertia}); "
                             "it must not be negative")
    elif isinstance(body, RigidBody):
        tensor = np.array([[number(body.inertia[i, j], f"{what} inertia[{i},{j}]") for j in range(3)]
                           for i in range(3)])
        moments = np.linalg.eigvalsh(tensor)
        tolerance = _PHYSICAL_TOLERANCE * max(1e-300, np.abs(moments).max())
        if moments[0] < -tolerance:
            raise ModelError(f"{what}: the inertia tensor is not positive semidefinite (principal moments "
                             f"{', '.join(f'{value:.6g}' for value in moments)}); tensor {tensor.tolist()}")
        if moments[0] + moments[1] < moments[2] - tolerance:
            raise ModelError(f"{what}: the principal moments of inertia {', '.join(f'{v:.6g}' for v in moments)} "
                             f"violate the triangle inequality I1 + I2 >= I3 ({moments[0] + moments[1]:.6g} < "
                             f"{moments[2]:.6g}): no mass distribution has them")
