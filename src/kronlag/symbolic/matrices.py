"""The catalogue of the equation matrices: every list of matrices in kronlag is taken from here.

The equations of motion (Van Khang 2011, Eq. 23)::

    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
    f(q) = 0,   A(q) qd + b(q) = 0

have m coordinates, r holonomic and s nonholonomic constraints.  Each entry of
:data:`MATRICES` names a matrix, its shape in those dimensions, whether it reads
the speeds ``qd`` and where it appears: printed with the equations
(:class:`~kronlag.symbolic.equations.Equations`, :func:`~kronlag.symbolic.export.format_equations`),
written by :func:`~kronlag.symbolic.export.export_code`, given as CasADi/JAX functions
(:mod:`~kronlag.symbolic.interop`), evaluated by the numeric model's accessors
(:class:`~kronlag.numeric.NumericModel`: ``model.M(q)``, batches) or read by the compiled
solvers only (:data:`~kronlag.numeric.codegen.layouts.LAYOUTS`).  A new matrix is one entry here
(and its formula in :class:`~kronlag.symbolic.equations.Equations`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["EquationMatrix", "MATRICES", "names", "shape", "STORED", "PRINTED", "EXPORTED", "INTEROP", "ACCESSORS",
           "SPEED_DEPENDENT", "VECTORS"]


@dataclass(frozen=True)
class EquationMatrix:
    """One matrix of the equations.

    Attributes
    ----------
    name : str
        Its attribute on ``Equations`` and ``NumericModel`` and its name in generated code.
    rows, columns : str or int
        ``"m"``, ``"r"``, ``"s"`` or 1; a matrix with one column is a vector (shape ``(n,)`` in NumPy).
    speeds : bool
        It depends on the speeds ``qd`` (its accessor takes ``qd``).
    meaning : str
        What it is, in the symbols of Eq. 23.
    stored : bool
        ``Equations`` holds it from the derivation (else it is computed on first access).
    printed, exported, interop : bool
        Shown with the equations; written by ``export_code``; a CasADi/JAX function.
    accessor : bool
        ``NumericModel`` has an accessor for it (``model.M(q, t)``) and evaluates it in batches.
    """

    name: str
    rows: str | int
    columns: str | int
    speeds: bool
    meaning: str
    stored: bool = False
    printed: bool = False
    exported: bool = False
    interop: bool = False
    accessor: bool = True

    @property
    def vector(self) -> bool:
        return self.columns == 1

    def shape(self, m: int, r: int, s: int) -> tuple[int, ...]:
        """``(rows,)`` for a vector, else ``(rows, columns)``."""
        dimensions = {"m": m, "r": r, "s": s, 1: 1}
        return (dimensions[self.rows],) if self.vector else (dimensions[self.rows], dimensions[self.columns])


#: The matrices, in the order they are listed everywhere.
MATRICES: dict[str, EquationMatrix] = {matrix.name: matrix for matrix in (
    EquationMatrix("M", "m", "m", False, "mass matrix (Eq. 12)", stored=True, printed=True, exported=True, interop=True),
    EquationMatrix("C", "m", "m", True, "Coriolis matrix of Eq. 22, C = dM/dq (I ⊗ qd) - 1/2 (dM/dq (qd ⊗ I))^T",
           stored=True, printed=True, exported=True, interop=True),
    EquationMatrix("C_christoffel", "m", "m", True, "Christoffel-symbol Coriolis matrix (same C qd, Md - 2 C skew)",
           printed=True),
    EquationMatrix("Cqd", "m", 1, True, "velocity terms C qd", stored=True, interop=True),
    EquationMatrix("g", "m", 1, False, "gradient of the potential energy, (dPi/dq)^T", stored=True, printed=True,
           exported=True, interop=True),
    EquationMatrix("Phi", "r", 1, False, "holonomic constraints f(q, t)", stored=True, printed=True, exported=True,
           interop=True),
    EquationMatrix("Phi_q", "r", "m", False, "constraint Jacobian df/dq", stored=True, printed=True, exported=True,
           interop=True),
    EquationMatrix("Phi_t", "r", 1, False, "df/dt (drives): Phi_q qd + Phi_t = 0", exported=True, interop=True),
    EquationMatrix("gamma", "r", 1, True, "-(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt: Phi_q qdd = gamma", exported=True,
           interop=True),
    EquationMatrix("A", "s", "m", False, "nonholonomic constraint matrix", stored=True, printed=True, exported=True,
           interop=True),
    EquationMatrix("b", "s", 1, False, "nonholonomic constraint offset: A qd + b = 0", stored=True, printed=True,
           exported=True, interop=True),
    EquationMatrix("gamma_nh", "s", 1, True, "-(dA/dt) qd - db/dt: A qdd = gamma_nh", interop=True),
    EquationMatrix("f_Q", "m", 1, True, "generalized non-conservative forces f_Q(q, qd, t)", stored=True, printed=True,
           exported=True, interop=True),
    EquationMatrix("potential_energy", 1, 1, False, "potential energy Pi(q)"),
    # read by the compiled solvers only (the blocks of kronlag.numeric.codegen.layouts.LAYOUTS)
    EquationMatrix("h", "m", 1, True, "f_Q - C qd - g", accessor=False),
    EquationMatrix("K", "m", "m", True, "d/dq of e = M a + C qd + g - f_Q + Phi_q^T nu + A^T mu", accessor=False),
    EquationMatrix("D", "m", "m", True, "d/dqd of the same e", accessor=False),
)}


def names(role: str) -> tuple[str, ...]:
    """The names of the matrices with the flag ``role`` (``"printed"``, ``"exported"``, ...), in order."""
    return tuple(name for name, matrix in MATRICES.items() if getattr(matrix, role))


def shape(name: str, m: int, r: int, s: int) -> tuple[int, ...]:
    """The NumPy shape of matrix ``name``: ``(n,)`` for a vector, ``(rows, columns)`` otherwise."""
    return MATRICES[name].shape(m, r, s)


#: Held by ``Equations`` from the derivation.
STORED = names("stored")
#: Shown with the equations (``str(eom)``, ``eom.latex(name)``, ``format_equations``).
PRINTED = names("printed")
#: Written by ``export_code``.
EXPORTED = names("exported")
#: Given as CasADi and JAX functions.
INTEROP = names("interop")
#: Evaluated by ``NumericModel`` accessors and ``evaluate_batch``.
ACCESSORS = names("accessor")
#: Depend on the speeds ``qd``.
SPEED_DEPENDENT = names("speeds")
#: Vectors (one column).
VECTORS = names("vector")
