"""The numerical policy of kronlag, in one place: rank decisions on the constraint Jacobian.

Every method that needs the rank of ``G = [Phi_q; A]`` -- forward dynamics (the
augmented solve, in Python and in the generated C), the projections onto the
constraint manifold, :meth:`~kronlag.NumericModel.assemble` and the detection
of singular configurations during a simulation -- decides it the same way:

* the diagonal of ``R`` in a column-pivoted QR of ``G^T`` (C) or the singular
  values of ``G`` (Python), sorted by size, are compared with the largest;
* an entry ``<= rank_rtol`` times the largest counts as zero (a dependent,
  redundant constraint row);
* while integrating, the ratio of the smallest entry that should be nonzero
  (at the rank of the start) to the largest, each row of ``Phi_q`` measured in
  its own unit (its norm at the start of the run, :func:`row_scales`: the
  ratio does not depend on the constraints' units), falls like ``|t - t*|`` near a
  *singular configuration*, where ``Phi_q`` loses rank at an instant (IFToMM
  A02: all bars horizontal).  Below ``APPROACH_RTOL`` (condition number above
  20) the motion *approaches* one: the index-1 methods, which cannot tell the
  branches apart there, stop with status -1, and the switching method hands
  over to the index-3 method (ALI3-P), which passes it on its branch.  A local
  minimum of the sampled ratio below ``APPROACH_RTOL`` is a *passage*,
  recorded as an event in the :class:`~kronlag.Trajectory`.

The projections onto the constraint manifold (:mod:`kronlag.numeric.projection` in Python,
``kl_project`` in the compiled integrator) stop after :data:`MAX_PROJECTION_ITERATIONS`
Gauss-Newton steps, or earlier at a step at rounding level (:data:`STALL`).

The C code receives the same numbers as macros (:func:`c_macros`), generated
from this module, so the two cannot disagree.

Why ``RANK_RTOL = 1e-8`` by default: an integrator's states lie off the
constraint manifold by its local error (``1e-10`` to ``1e-6`` with the Baumgarte
methods at the default tolerances); the singular value of a redundant
(dependent) row off the manifold is of that size relative to the largest, so a
threshold at rounding level (``1e-10`` and below) declares such states full
rank and the accelerations blow up (IFToMM A04).  A threshold far above the
drift but far below the smallest singular value of a regular mechanism keeps
both right; pass ``rank_rtol`` to ``eom.numeric`` for badly scaled models.

The vibration modes of a linearization (:class:`~kronlag.studies.linearization.LinearModel`) solve
``K_r phi = w^2 M_r phi``; an eigenvalue ``w^2`` with ``|w^2| <= ZERO_EIGENVALUE_RTOL`` times the
problem's scale (the largest ``|w^2|``, or ``max |K| / max |M|`` of the unreduced matrices if larger)
is zero within rounding (:func:`zero_eigenvalue_threshold`): a neutral mode (a free spin, 0 rad/s), not an
unstable one.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import InputError

__all__ = ["RANK_RTOL", "CHOLESKY_RTOL", "MAX_RANK_RTOL", "APPROACH_RTOL", "LEAVE_RTOL", "MAX_PROJECTION_ITERATIONS",
           "STALL", "CVODE_TIGHTEST", "INDEX3_TIGHTEST", "ZERO_EIGENVALUE_RTOL", "RESTING_GAP",
           "CONTACT_GAP", "AT_REST", "RATE_CHANGE_STEP", "TURN_RTOL", "FRICTION_RTOL", "FRICTION_MAX_ITERATIONS", "SAME_INSTANT", "integrator_tolerances",
           "zero_eigenvalue_threshold", "numerical_rank", "matrix_rank", "check_rank_rtol", "rank_magnitudes",
           "singular_ratio", "row_scales", "c_macros", "REDUNDANCY_PROBE", "REDUNDANCY_PROBE_RESIDUAL"]

#: Default relative rank tolerance on ``[Phi_q; A]`` (see the module docstring).
RANK_RTOL = 1e-8
#: A Cholesky pivot ``<= CHOLESKY_RTOL * max(diag)`` of ``Z^T M Z`` means M is not positive
#: definite on the constraint null space: a singular configuration.
CHOLESKY_RTOL = 1e-12
#: The largest ``rank_rtol`` allowed: a magnitude ratio of 1e-3 (condition number 1e3) is still
#: a rank, to be passed by the integrators, not a redundant row.
MAX_RANK_RTOL = 1e-3
#: A ratio below this: the motion approaches a singular configuration (condition number above 20).
APPROACH_RTOL = 0.05
#: The switching method returns from the index-3 method to the fast one above this ratio.
LEAVE_RTOL = 2 * APPROACH_RTOL
#: Most Gauss-Newton steps of one projection onto ``Phi(q, t) = 0`` during an integration.
MAX_PROJECTION_ITERATIONS = 8
#: A Gauss-Newton step below ``STALL (1 + |q|)`` in every coordinate is at rounding level: ``Phi`` is as
#: small as it gets, and the projection ends there.
STALL = 1e-15
#: The tightest ``(rtol, atol)`` handed to CVODE: about ``50 eps`` for states of size 1 (below it
#: CVODE stops with "too much accuracy requested").
CVODE_TIGHTEST = (1e-14, 1e-14)
#: The tightest ``(rtol, atol)`` handed to ALI3-P: its velocities ``2/h (q - q0) - v0`` carry the
#: rounding of the positions' Newton iteration amplified by ``2/h``, so an absolute tolerance at
#: rounding level only adds steps and makes the error larger.  IFToMM A02 (N = 2 and 4, the switching
#: method at rtol 1e-8, atol 1e-10): the error of B0 is 1.6-1.8e-5 m with floors (3e-12, 3e-12),
#: 0.7e-5 m with (3e-12, 3e-11), 4-5e-6 m with (1e-12, 1e-11), 1.4e-7 to 2e-6 m with (3e-13, 1e-11).
INDEX3_TIGHTEST = (3e-13, 1e-11)
#: An eigenvalue ``w^2`` of a linearization at most this fraction of the problem's scale is zero
#: within rounding (see the module docstring); rounding leaves ~1e-15 of it, a true mode far more.
ZERO_EIGENVALUE_RTOL = 1e-9
#: Limits (:mod:`kronlag.simulation.impacts`): a contact becomes persistent (held as a constraint)
#: when the rebound would lift its gap by at most ``RESTING_GAP * atol``, i.e. when the rebound speed
#: ``v`` satisfies ``v^2 <= 2 |a| RESTING_GAP atol`` with ``a < 0`` the gap's acceleration in free
#: motion: the Zeno rule, which ends an accumulation of impacts (a bouncing ball) after finitely many.
RESTING_GAP = 10.0
#: Limits: a gap at most ``CONTACT_GAP * atol`` (in its own units) at the start is in contact there.
CONTACT_GAP = 10.0
#: Joint friction (:mod:`kronlag.numeric.friction`): the friction forces ``f`` solved together with
#: ``(qdd, lambda)`` (they depend on the normal loads, hence on ``lambda``) are converged when the error
#: left after a Newton step (that step's change, or the bound from the contraction of the last two steps:
#: ``numeric.friction._converged``) is at most ``FRICTION_RTOL`` times the largest: far below any integrator
#: tolerance, so that the right-hand side is a function of the state to rounding (not lagged).
FRICTION_RTOL = 1e-13
#: Most Newton steps of that solve (a few suffice: the loads are piecewise linear in ``f``); not converged
#: by then (a wedged joint, whose friction grows with the load faster than the load allows: no solution
#: nearby), the evaluation fails.
FRICTION_MAX_ITERATIONS = 50
#: Limits under a sampled controller: a sample instant at most ``SAME_INSTANT * max(1, |t|)`` after an
#: event is taken at the event, with the state before it (as when the event falls on the sample
#: instant; an event located to rounding may fall just before it, and a shorter segment is rounding).
SAME_INSTANT = 1e-10

# -- redundant constraints (issue 19.3) ----------------------------------------------------------
#: A start where ``Phi_q`` is rank deficient is a case of *redundant constraints* (not a singular
#: configuration) when the rank is the same at configurations on the constraints this far (times
#: ``1 + max |q|``) from it along its null space: near a singular configuration the magnitude that
#: vanished there grows like the distance (about 1e-4 here, far above ``RANK_RTOL``), while redundant
#: rows stay dependent on the constraint manifold.  The switching method then starts with CVODE and the
#: minimum-norm multipliers, else with ALI3-P.
REDUNDANCY_PROBE = 1e-4
#: The configurations probed are projected onto the constraints to ``max |Phi|`` at most this times
#: ``rank_rtol`` times the largest singular value of ``Phi_q``: off the constraints by ``|Phi|``, redundant
#: rows have magnitudes of about ``|Phi|``, which must stay well below the rank tolerance.
REDUNDANCY_PROBE_RESIDUAL = 1e-2

# -- exact stiction (kronlag.simulation.stiction) --
#: A joint with the exact friction law whose rate is within AT_REST * atol of zero at the start of a
#: run is at rest: it sticks or slips as its holding force decides (a rate above that slides).
AT_REST = 1.0
#: A joint locked to held ones (exact stiction) is tied to the holds whose rate ratio exceeds this times
#: its largest ratio (the least-squares ratios of the others are rounding).
TIED_RATIO = 1e-9
#: The rate of change of a joint's rate at an event (exact stiction: which way a joint at rest goes) is
#: the change of its rate over a step of this times ``max(1, |t|)`` along the motion, divided by the step.
RATE_CHANGE_STEP = 1e-7
#: A sliding joint whose rate falls through zero turns its direction inside a compiled run (without a
#: return to Python) only at a kinematic dead point the rank policy is sure of: the part of its row
#: ``J_rate`` outside the constraints' row space at most this times ``rank_rtol`` times the largest
#: constraint row's norm (the rank policy calls it dependent below ``rank_rtol``); else Python decides.
TURN_RTOL = 0.1


def integrator_tolerances(rtol: float, atol: float, scale: float,
                          tightest: tuple[float, float]) -> tuple[float, float]:
    """The ``(rtol, atol)`` given to an integrator whose global error exceeds its local tolerance by
    about ``scale``, for the requested ones: both divided by ``scale`` (their ratio, which says where
    absolute accuracy takes over from relative, is kept), neither below ``tightest``, the integrator's
    rounding floors ``(rtol, atol)`` (:data:`CVODE_TIGHTEST`, :data:`INDEX3_TIGHTEST`)."""
    return max(rtol / scale, tightest[0]), max(atol / scale, tightest[1])


def check_rank_rtol(rank_rtol: float) -> float:
    """``rank_rtol`` as a float in ``(0, MAX_RANK_RTOL)``; ValueError otherwise."""
    value = float(rank_rtol)
    if not 0.0 < value < MAX_RANK_RTOL:
        raise InputError(f"rank_rtol must lie in (0, {MAX_RANK_RTOL:g}), got {rank_rtol!r}")
    return value


def numerical_rank(magnitudes: np.ndarray, rank_rtol: float) -> int:
    """Number of ``magnitudes`` (singular values or ``|diag R|``) above ``rank_rtol`` times the largest."""
    magnitudes = np.abs(np.asarray(magnitudes, dtype=float))
    if magnitudes.size == 0 or not magnitudes.max() > 0.0:
        return 0
    return int(np.count_nonzero(magnitudes > rank_rtol * magnitudes.max()))


def zero_eigenvalue_threshold(values: np.ndarray, scale: float = 0.0) -> float:
    """The largest ``|w^2|`` that is zero within rounding among the eigenvalues ``values``:
    ``ZERO_EIGENVALUE_RTOL * max(scale, max |w^2|)`` (``scale``: ``max |K| / max |M|`` of the
    unreduced matrices)."""
    largest = float(np.max(np.abs(np.asarray(values, dtype=float)), initial=0.0))
    return ZERO_EIGENVALUE_RTOL * max(float(scale), largest)


def matrix_rank(matrix: np.ndarray, rank_rtol: float = RANK_RTOL) -> int:
    """The :func:`numerical_rank` of ``matrix`` by its singular values (0 for an empty one)."""
    matrix = np.asarray(matrix, dtype=float)
    return numerical_rank(np.linalg.svd(matrix, compute_uv=False), rank_rtol) if matrix.size else 0


def rank_magnitudes(Phi_q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``|diag R|`` of the column-pivoted QR of ``Phi_q^T`` (decreasing) and the constraint row
    behind each: the rank-revealing magnitudes (``rank_magnitudes`` in ``numeric/codegen/c/linalg.c``)."""
    from scipy.linalg import qr

    if Phi_q.shape[0] == 0:
        return np.zeros(0), np.zeros(0, dtype=int)
    R, permutation = qr(Phi_q.T, mode="r", pivoting=True)
    steps = min(Phi_q.shape)
    magnitudes = np.zeros(Phi_q.shape[0])
    magnitudes[:steps] = np.abs(np.diag(R)[:steps])
    return magnitudes, permutation


def row_scales(Phi_q: np.ndarray, rank_rtol: float) -> np.ndarray:
    """The units of the constraint rows in the approach test: their norms in ``Phi_q`` at the start of
    a run (``kl_row_scales`` in ``simulation/c/monitor.c``).  A row numerically zero there (norm at most
    ``rank_rtol`` times the largest) is measured in the largest row's units (1 if every row is zero)."""
    norms = np.linalg.norm(Phi_q, axis=1)
    largest = norms.max(initial=0.0)
    return np.where(norms > rank_rtol * largest, norms, largest if largest > 0.0 else 1.0)


def singular_ratio(Phi_q: np.ndarray, generic_rank: int, scales: np.ndarray) -> tuple[float, int]:
    """``magnitude[rho - 1] / magnitude[0]`` of :func:`rank_magnitudes` of the rows of ``Phi_q`` divided
    by ``scales`` (:func:`row_scales` at the start of the run; 1 when there is nothing to lose) and the
    constraint row behind it (-1 then): falls like ``|t - t*|`` near a singular configuration
    (``kl_singular_ratio`` in ``simulation/c/monitor.c``).

    Each row is measured in its own unit, its size at the start: the ratio does not depend on the
    constraints' units (a loop in metres or in millimetres, a row in metres beside one in radians),
    while a row whose gradient vanishes at the singular configuration (IFToMM A02's horizontal
    closure rows) still falls with it, as rows scaled to unit norm at every step would not.  Of a rank
    deficient ``Phi_q`` (``generic_rank`` below its rows: redundant constraints) only the
    ``generic_rank`` rows its own pivoted QR puts first (the independent ones, in their order) are
    kept: a dependent row nearly zero at the start (a loop planar to rounding) would otherwise be
    scaled up to an arbitrary direction."""
    if generic_rank == 0:
        return 1.0, -1
    rows = (np.arange(Phi_q.shape[0]) if generic_rank >= Phi_q.shape[0]
            else np.sort(rank_magnitudes(Phi_q)[1][:generic_rank]))
    magnitudes, permutation = rank_magnitudes(Phi_q[rows] / np.asarray(scales, dtype=float)[rows, None])
    ratio = magnitudes[generic_rank - 1] / magnitudes[0] if magnitudes[0] > 0 else 0.0
    return float(ratio), int(rows[permutation[generic_rank - 1]])


def c_macros(rank_rtol: float) -> str:
    """The policy as C macros for the generated code."""
    return (f"#define KRONLAG_RANK_RTOL {rank_rtol!r}\n#define KRONLAG_CHOLESKY_RTOL {CHOLESKY_RTOL!r}\n"
            f"#define KRONLAG_APPROACH_RTOL {APPROACH_RTOL!r}\n"
            f"#define KRONLAG_LEAVE_RTOL {LEAVE_RTOL!r}\n"
            f"#define KRONLAG_MAX_PROJECTION_ITERATIONS {MAX_PROJECTION_ITERATIONS}\n"
            f"#define KRONLAG_STALL {STALL!r}\n#define KRONLAG_FRICTION_RTOL {FRICTION_RTOL!r}\n"
            f"#define KRONLAG_FRICTION_MAX_ITERATIONS {FRICTION_MAX_ITERATIONS}\n"
            f"#define KRONLAG_RATE_CHANGE_STEP {RATE_CHANGE_STEP!r}\n#define KRONLAG_TURN_RTOL {TURN_RTOL!r}\n")


#: Recursive dynamics kernels (:mod:`kronlag.numeric.codegen.recursive`): a robot link's frame must move
#: as its joint says (turn about the unit axis, or slide along it) to this relative accuracy at a test
#: angle, else the System keeps the flat kernel (a reader's frame that disagreed would be a defect).
TREE_AXIS_RTOL = 1e-12
__all__ += ["TREE_AXIS_RTOL"]

#: Declared kinematic trees (:meth:`kronlag.System.add_tree_link`): composed from the root, the links
#: must place every body's centre of mass (relative to 1 + the largest coordinate of the positions)
#: and orientation (rotation matrix entries) as the body's own expressions do to this accuracy at
#: random states, else the recursive kernel is not used (the flat one is, with a warning).
TREE_POSE_RTOL = 1e-10
__all__ += ["TREE_POSE_RTOL"]
