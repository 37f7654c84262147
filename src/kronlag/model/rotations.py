"""Rotations: elementary rotations and their products, and the checks a rotation matrix must pass.

Rotation matrices ``R`` map body-frame components to world components (``r_world = origin + R r_body``):

- :func:`elementary_rotation` (``R_x``, ``R_y``, ``R_z``: the one place they are written),
  :func:`axis_angle` (Rodrigues), :func:`euler_sequence` (Euler/Cardan angles, intrinsic or
  extrinsic) and :func:`euler_parameters` (unit quaternion ``e0, e1, e2, e3``, whose normalization
  constraint :func:`euler_parameter_constraint` returns);
- :class:`RotationSequence`: a product of elementary rotations (and rotations by Euler parameters,
  :data:`EULER_PARAMETERS`) whose body-frame angular velocity needs no simplification;
- :func:`check_rotation`: orthogonal with determinant +1, symbolically where cheap, else numerically.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..core.errors import ModelError
from ..core.kernels import ExpressionFunction
from .inputs import as_components, as_scalar, as_vector

__all__ = [
    "matrix_product",
    "elementary_rotation",
    "planar_rotation",
    "axis_angle",
    "euler_sequence",
    "euler_parameters",
    "euler_parameter_constraint",
    "euler_parameters_of",
    "euler_parameter_rates",
    "EULER_PARAMETERS",
    "skew",
    "RotationSequence",
    "MAX_ROTATION_FACTORS",
    "check_rotation",
]


def elementary_rotation(axis: str, angle) -> sp.Matrix:
    """Rotation by ``angle`` about the body axis ``"x"``, ``"y"`` or ``"z"``, shape (3, 3).

    >>> elementary_rotation("z", sp.Symbol("a"))
    Matrix([
    [cos(a), -sin(a), 0],
    [sin(a),  cos(a), 0],
    [     0,       0, 1]])
    """
    c, s = sp.cos(angle), sp.sin(angle)
    entries = {"x": [[1, 0, 0], [0, c, -s], [0, s, c]],
               "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
               "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}
    if axis not in entries:
        raise ModelError(f"rotation axis must be 'x', 'y' or 'z', got {axis!r}")
    return sp.Matrix(entries[axis])


def planar_rotation(angle) -> sp.Matrix:
    """Rotation of the plane by ``angle``, shape (2, 2): the upper left block of ``R_z(angle)``."""
    return elementary_rotation("z", angle)[:2, :2]


def skew(vector) -> sp.Matrix:
    """The matrix ``[v]x`` with ``[v]x w = v x w``: shape (3, 3) for a 3-vector; for a 1-vector ``(w,)``
    (an angle or angular velocity about the normal of the plane) the planar ``[[0, -w], [w, 0]]``,
    shape (2, 2), with ``[w]x r = w e_z x r``.

    >>> skew((sp.Symbol("w"),))
    Matrix([
    [0, -w],
    [w,  0]])
    """
    try:
        vector = list(vector)
    except TypeError:
        pass  # as_components reports it
    if isinstance(vector, list) and len(vector) == 1:
        (w,) = as_components(vector, "skew: vector", 1)
        return sp.Matrix([[0, -w], [w, 0]])
    x, y, z = as_components(vector, "skew: vector", 3)
    return sp.Matrix([[0, -z, y], [z, 0, -x], [-y, x, 0]])


def axis_angle(axis, angle) -> sp.Matrix:
    """Rotation by ``angle`` about ``axis`` (Rodrigues): ``R = I + sin a K + (1 - cos a) K^2``.

    ``K = [u]x`` with ``u = axis / |axis|`` (a unit axis is taken as it is); the axis must not be zero.

    >>> R = axis_angle((0, 0, 2), sp.Symbol("a"))
    >>> R == elementary_rotation("z", sp.Symbol("a"))
    True
    """
    direction = as_components(axis, "axis_angle: axis", 3)
    length = sp.sqrt(sum(entry ** 2 for entry in direction))
    if length == 0:
        raise ModelError("axis_angle: the axis is the zero vector")
    K = skew(direction if length == 1 else direction / length)
    return sp.eye(3) + sp.sin(angle) * K + (1 - sp.cos(angle)) * (K * K)  # K^2 first: constant for a constant axis


def euler_sequence(axes: str, angles: Sequence, *, extrinsic: bool = False) -> sp.Matrix:
    """Rotation from Euler/Cardan angles, e.g. ``"zxz"`` (Euler) or ``"xyz"`` (Cardan).

    Intrinsic (default; rotations about the axes of the moving frame):
    ``R = R_a1(angle1) R_a2(angle2) R_a3(angle3)``.  Extrinsic (about the fixed
    axes, in the order given): ``R = R_a3(angle3) R_a2(angle2) R_a1(angle1)``.

    >>> psi, theta, phi = sp.symbols("psi theta phi")
    >>> euler_sequence("zxz", (psi, theta, phi)) == (elementary_rotation("z", psi)
    ...     * elementary_rotation("x", theta) * elementary_rotation("z", phi))
    True
    """
    if not isinstance(axes, str) or not axes or any(axis not in "xyz" for axis in axes):
        raise ModelError(f"euler_sequence: axes must be a non-empty string of x, y, z, got {axes!r}")
    angles = list(angles)
    if len(angles) != len(axes):
        raise ModelError(f"euler_sequence: {len(axes)} axes {axes!r} need {len(axes)} angles, got {len(angles)}")
    factors = [elementary_rotation(axis, angle) for axis, angle in zip(axes, angles)]
    rotation = sp.eye(3)
    for factor in (reversed(factors) if extrinsic else factors):
        rotation = rotation * factor
    return rotation


def euler_parameters(e0, e1, e2, e3) -> sp.Matrix:
    """Rotation from Euler parameters (a unit quaternion ``e0 + e1 i + e2 j + e3 k``).

    ``R = (e0^2 - e^T e) I + 2 (e e^T + e0 [e]x)`` with ``e = (e1, e2, e3)``, the
    homogeneous form (equal to ``(2 e0^2 - 1) I + 2 (e e^T + e0 [e]x)`` on the unit
    sphere, and ``R^T R = (e0^2 + e^T e)^2 I`` everywhere); it is a rotation only where
    ``e0^2 + e1^2 + e2^2 + e3^2 = 1``: add :func:`euler_parameter_constraint` to the
    system (:func:`kronlag.joints.free_body` does).
    """
    e = sp.Matrix([e1, e2, e3])
    return (e0 ** 2 - (e.T * e)[0, 0]) * sp.eye(3) + 2 * (e * e.T + e0 * skew(e))


def euler_parameter_constraint(e0, e1, e2, e3) -> sp.Expr:
    """The normalization constraint ``e0^2 + e1^2 + e2^2 + e3^2 - 1 = 0`` of Euler parameters."""
    return e0 ** 2 + e1 ** 2 + e2 ** 2 + e3 ** 2 - 1


def euler_parameter_rates(e0, e1, e2, e3) -> sp.Matrix:
    """``G(e)`` (3x4) with the body-frame angular velocity ``omega = 2 G(e) edot`` of the rotation
    :func:`euler_parameters` (on the unit sphere; ``G(e) e = 0`` and ``G G^T = |e|^2 I``).

    >>> euler_parameter_rates(1, 0, 0, 0)
    Matrix([
    [0, 1, 0, 0],
    [0, 0, 1, 0],
    [0, 0, 0, 1]])
    """
    return sp.Matrix([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])


def euler_parameters_of(rotation) -> np.ndarray:
    """Euler parameters ``(e0, e1, e2, e3)``, ``e0 >= 0``, of a numeric rotation matrix, shape (4,).

    The inverse of :func:`euler_parameters` (for initial guesses of bodies placed by
    Euler parameters); the largest of ``e0^2 .. e3^2`` is taken from the diagonal
    first, which keeps the result accurate for every rotation.

    >>> euler_parameters_of(np.array(elementary_rotation("z", np.pi / 2), dtype=float)).round(6)
    array([0.707107, 0.      , 0.      , 0.707107])
    """
    R = np.asarray(rotation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ModelError(f"euler_parameters_of: expected a 3x3 rotation matrix, got {R.tolist()}")
    squares = 0.25 * (1 + np.array([np.trace(R), 2 * R[0, 0] - np.trace(R), 2 * R[1, 1] - np.trace(R),
                                    2 * R[2, 2] - np.trace(R)]))
    k = int(np.argmax(squares))
    e = np.empty(4)
    e[k] = np.sqrt(squares[k])
    # off-diagonal sums and differences: 4 e0 e_i = R_kj - R_jk, 4 e_i e_j = R_ij + R_ji
    products = {(0, 1): R[2, 1] - R[1, 2], (0, 2): R[0, 2] - R[2, 0], (0, 3): R[1, 0] - R[0, 1],
                (1, 2): R[0, 1] + R[1, 0], (1, 3): R[0, 2] + R[2, 0], (2, 3): R[1, 2] + R[2, 1]}
    for (i, j), value in products.items():
        if k in (i, j):
            e[j if k == i else i] = value / (4 * e[k])
    return e if e[0] >= 0 else -e



#: Most elementary rotations in one :class:`RotationSequence`; more would make the rotation
#: matrix, and every derivative of it, grow beyond what :func:`kronlag.derive` handles quickly.
MAX_ROTATION_FACTORS = 16

#: How far ``|u|^2`` of an axis of floating-point numbers may be from 1: the rounding of a
#: normalized float vector (a few units in the last place), not a tolerance for a wrong axis.
_UNIT_ROUNDING = 1e-15

_PRINCIPAL_AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}

#: The "axis" of a :class:`RotationSequence` factor that turns by Euler parameters: the factor
#: ``(EULER_PARAMETERS, (e0, e1, e2, e3))`` is :func:`euler_parameters` ``(e0, e1, e2, e3)`` (a ball
#: joint or a floating base without gimbal lock; add :func:`euler_parameter_constraint`).
EULER_PARAMETERS = "euler_parameters"


@dataclass(frozen=True)
class RotationSequence:
    """A rotation composed of elementary rotations, ``R = R_1(angle_1) R_2(angle_2) … R_n(angle_n)``.

    ``R_k`` turns by ``angle_k`` (an expression of q and parameters) about the constant unit
    axis ``u_k``.  Because the factors are known, the body-frame angular velocity needs no
    simplification (see :meth:`body_axes`)::

        omega_body = sum_k (R_{k+1} ... R_n)^T u_k d(angle_k)/dt

    A factor ``(EULER_PARAMETERS, (e0, e1, e2, e3))`` is the rotation by Euler parameters
    (:func:`euler_parameters`); it adds ``(R_{k+1} ... R_n)^T 2 G(e) edot``
    (:func:`euler_parameter_rates`), four terms with the "axes" ``2 G(e)[:, j]`` and "angles" ``e_j``.

    Parameters
    ----------
    factors : sequence of (axis, angle)
        ``axis`` is ``"x"``, ``"y"``, ``"z"`` or a constant unit 3-vector, or
        :data:`EULER_PARAMETERS` with four expressions as the "angle"; at most
        :data:`MAX_ROTATION_FACTORS` factors.

    Examples
    --------
    >>> import sympy as sp
    >>> psi, theta = sp.symbols("psi theta")
    >>> RotationSequence([("z", psi), ("x", theta)]).matrix[2, :]
    Matrix([[0, sin(theta), cos(theta)]])
    """

    factors: tuple[tuple[sp.ImmutableMatrix | str, sp.Expr | sp.ImmutableMatrix], ...]

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
            if isinstance(axis, str) and axis == EULER_PARAMETERS:
                checked.append((axis, as_vector(angle, f"{what} factor {k} Euler parameters", (4,))))
                continue
            if isinstance(axis, str):
                if axis not in _PRINCIPAL_AXES:
                    raise ModelError(f"{what} factor {k}: axis must be 'x', 'y', 'z' or a unit 3-vector, "
                                     f"got {axis!r}")
                axis = _PRINCIPAL_AXES[axis]
            vector = as_vector(axis, f"{what} factor {k} axis", (3,))
            norm_error = sp.simplify((vector.T * vector)[0, 0] - 1)
            if norm_error != 0 and not (norm_error.is_Float and abs(norm_error) <= _UNIT_ROUNDING):
                raise ModelError(f"{what} factor {k}: the axis {list(vector)} is not a unit vector "
                                 f"(|u|^2 - 1 = {norm_error})")
            checked.append((vector, as_scalar(angle, f"{what} factor {k} angle")))
        object.__setattr__(self, "factors", tuple(checked))

    @property
    def axis_names(self) -> tuple[str | None, ...]:
        """The name ``"x"``, ``"y"`` or ``"z"`` of each factor's axis, ``None`` for another axis."""
        return tuple(next((name for name, unit in _PRINCIPAL_AXES.items()
                           if not isinstance(axis, str) and list(axis) == list(unit)), None)
                     for axis, _ in self.factors)

    def _factor_matrix(self, k: int) -> sp.ImmutableMatrix:
        axis, angle = self.factors[k]
        if isinstance(axis, str):  # EULER_PARAMETERS
            return sp.ImmutableMatrix(euler_parameters(*angle))
        principal = self.axis_names[k]
        rotation = axis_angle(axis, angle) if principal is None else elementary_rotation(principal, angle)
        return sp.ImmutableMatrix(rotation)

    @property
    def matrix(self) -> sp.ImmutableMatrix:
        """``R`` (3x3): maps body-frame components to the frame the sequence starts in."""
        rotation = sp.eye(3)
        for k in range(len(self.factors)):
            rotation = matrix_product(rotation, self._factor_matrix(k))
        return sp.ImmutableMatrix(rotation)

    def body_axes(self) -> list[tuple[sp.ImmutableMatrix, sp.Expr]]:
        """``[(w_k, angle_k)]`` with ``w_k = (R_{k+1} ... R_n)^T u_k``, the axis of factor k in the body
        frame, so that ``omega_body = sum_k w_k d(angle_k)/dt`` (an Euler-parameter factor gives four
        pairs ``((R_{k+1} ... R_n)^T 2 G(e)[:, j], e_j)``, whose ``w`` vary with e)."""
        result: list[tuple[sp.ImmutableMatrix, sp.Expr]] = []
        tail = sp.eye(3)
        for k in reversed(range(len(self.factors))):
            axis, angle = self.factors[k]
            if isinstance(axis, str):  # EULER_PARAMETERS: 2 G(e) edot, one term per parameter
                rates = 2 * matrix_product(tail.T, euler_parameter_rates(*angle))
                result.extend((sp.ImmutableMatrix(rates[:, j]), angle[j]) for j in reversed(range(4)))
            else:
                result.append((sp.ImmutableMatrix(matrix_product(tail.T, axis)), angle))
            tail = matrix_product(self._factor_matrix(k), tail)
        return result[::-1]


def matrix_product(left, right) -> sp.Matrix:
    """``left * right`` for matrices of expressions, skipping the products with an exact zero.

    SymPy's own product asks ``0 * entry`` of every entry (to catch ``0 * oo``), and that
    assumption query walks the whole entry: on the rotations of a deep kinematic chain it
    dominates building the model.  Entries here are finite expressions of the coordinates.
    """
    def entry(i: int, j: int) -> sp.Expr:
        return sp.Add(*(left[i, k] * right[k, j] for k in range(left.cols)
                        if left[i, k] != 0 and right[k, j] != 0))
    return sp.Matrix(left.rows, right.cols, entry)


#: Random points at which a rotation matrix is checked numerically for orthogonality.
_ORTHOGONALITY_POINTS = 4
#: Relative tolerance of the numeric orthogonality check.
_ORTHOGONALITY_TOLERANCE = 1e-9
#: Largest operation count of an entry of ``R^T R - I`` that is simplified symbolically.
_SYMBOLIC_CHECK_OPERATIONS = 40


def check_rotation(rotation: sp.ImmutableMatrix, what: str) -> None:
    """Raise :class:`ModelError` unless ``rotation`` is orthogonal with determinant +1.

    Entries of ``R^T R - I`` small enough are simplified symbolically (a zero is a
    proof); otherwise, or if some entry does not simplify to zero, ``R`` is evaluated
    (:class:`~kronlag.core.kernels.ExpressionFunction`) at the first
    :data:`_ORTHOGONALITY_POINTS` of ``10 *`` as many random points of its symbols
    (uniform in [-2, 2]) where it is finite.  A rotation written with Euler parameters is
    orthogonal only on their normalization constraint: ``R^T R = s(q) I`` with a factor
    ``s`` that varies with the coordinates is accepted as such, a constant factor other
    than 1 is not.
    """
    deviation = rotation.T * rotation - sp.eye(3)
    if all(sp.count_ops(entry) <= _SYMBOLIC_CHECK_OPERATIONS for entry in deviation):
        if (all(sp.trigsimp(sp.expand(entry)) == 0 for entry in deviation)
                and sp.trigsimp(sp.expand(rotation.det())) == 1):
            return
    symbols = sorted(rotation.free_symbols, key=lambda symbol: symbol.name)
    try:
        evaluate = ExpressionFunction({"R": rotation}, [("x", symbols)], name="rotation")
    except (ModelError, NotImplementedError) as error:
        raise ModelError(f"{what} cannot be evaluated numerically (to check that it is orthogonal): "
                         f"{error}") from None
    candidates = np.random.default_rng(20111).uniform(-2.0, 2.0, (10 * _ORTHOGONALITY_POINTS, len(symbols)))
    with np.errstate(all="ignore"):
        matrices = evaluate.batch(candidates)["R"]
    finite = np.all(np.isfinite(matrices), axis=(1, 2))
    points = list(zip(candidates[finite], matrices[finite]))[:_ORTHOGONALITY_POINTS]
    if not points:
        raise ModelError(f"{what} cannot be evaluated at random values of its symbols "
                         f"{', '.join(s.name for s in symbols)} (to check that it is orthogonal)")

    def where(values: np.ndarray) -> str:
        return ", ".join(f"{s.name}={value:.4g}" for s, value in zip(symbols, values)) or "its constant value"

    scales = []
    for values, matrix in points:
        gram = matrix.T @ matrix
        scale = np.trace(gram) / 3
        off = np.abs(gram - scale * np.eye(3))
        if off.max() > _ORTHOGONALITY_TOLERANCE * max(1.0, scale):
            i, j = np.unravel_index(np.argmax(off), off.shape)
            expected = f"{scale:.6g}" if i == j else "0"
            raise ModelError(f"{what} is not orthogonal: (R^T R)[{i},{j}] = {gram[i, j]:.6g}, expected {expected} "
                             f"(columns {i} and {j} of R are not orthonormal) at {where(values)}")
        determinant = np.linalg.det(matrix)
        if determinant <= 0:
            raise ModelError(f"{what} has determinant {determinant:.6g} at {where(values)}: "
                             "it is a reflection, not a rotation (expected +1)")
        scales.append(scale)
    if np.ptp(scales) <= _ORTHOGONALITY_TOLERANCE and abs(scales[0] - 1) > _ORTHOGONALITY_TOLERANCE:
        raise ModelError(f"{what} is not orthogonal: R^T R = {scales[0]:.6g} I (expected the identity, "
                         f"(R^T R)[0,0] = {scales[0]:.6g}) at {where(points[0][0])}")
