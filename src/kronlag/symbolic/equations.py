"""The equations object returned by :func:`kronlag.derive`."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property, partial
from typing import TYPE_CHECKING, Any, Protocol

import symengine as se
import sympy as sp

from ..core.errors import InputError
from ..model.dimensions import si_parameter_values
from . import matrices as catalogue
from .calculus import matrix_derivative

if TYPE_CHECKING:
    from ..model.system import System

__all__ = ["Equations", "MATRIX_NAMES", "MatrixSource", "StoredMatrices", "acceleration_offset"]

#: The matrices printed with the equations, in order (:data:`kronlag.symbolic.matrices.PRINTED`).
MATRIX_NAMES = catalogue.PRINTED
#: What a :class:`MatrixSource` gives: the stored matrices of the catalogue and the potential energy.
_STORED_NAMES = (*catalogue.STORED, "potential_energy")


class MatrixSource(Protocol):
    """Where an :class:`Equations` object takes its matrices from, on first access."""

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(m, r, s)``."""

    def sympy(self, name: str) -> Any:
        """Matrix ``name`` of :data:`_STORED_NAMES` or ``"C_christoffel"`` in SymPy."""

    def symengine(self, name: str) -> se.DenseMatrix | None:
        """Matrix ``name`` in SymEngine (symbols named as the system's), or None."""


class StoredMatrices:
    """A :class:`MatrixSource` of SymPy matrices held (or computed by ``deferred`` callables on first use)."""

    def __init__(self, matrices: dict[str, Any], *, deferred: Mapping[str, Callable[[], Any]] | None = None):
        self.matrices, self.deferred = matrices, dict(deferred or {})

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.matrices["M"].rows, self.matrices["Phi"].rows, self.matrices["A"].rows

    def sympy(self, name: str) -> Any:
        return self.matrices[name] if name in self.matrices else self.deferred[name]()

    def symengine(self, name: str) -> None:
        return None


def _stored(name: str, doc: str) -> cached_property:
    """The attribute ``name`` of :class:`Equations`: its source's matrix, converted once."""
    def convert(self: Equations) -> Any:
        return self.source.sympy(name)

    convert.__name__, convert.__doc__ = name, doc
    return cached_property(convert)


def acceleration_offset(jacobian: se.DenseMatrix, offset: se.DenseMatrix, coordinates: list, speeds: list,
                        time: se.Symbol) -> se.DenseMatrix:
    """``-d/dt (jacobian qd + offset)`` at fixed ``qd`` (column): Theorem 1 for q, plus the partial in t,
    in SymEngine (``gamma`` from ``Phi_q`` and ``Phi_t``, ``gamma_nh`` from ``A`` and ``b``)."""
    rows = offset.rows
    if not rows:
        return se.zeros(0, 1)
    velocity = jacobian * se.DenseMatrix(len(speeds), 1, speeds) + offset
    return se.DenseMatrix(rows, 1, [-se.Add(se.diff(entry, time), *(se.diff(entry, q) * qd
                                                                     for q, qd in zip(coordinates, speeds)))
                                    for entry in velocity])


@dataclass(frozen=True, eq=False)
class Equations:
    """Equations of motion in the matrix form of Van Khang (2011), Eq. 23::

        M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q
        f(q) = 0,   A(q) qd + b(q) = 0

    with m coordinates, r holonomic and s nonholonomic constraints.  All
    matrices are immutable SymPy matrices, each converted from the derivation's SymEngine form
    on first access (``source``, a :class:`MatrixSource`): the numeric model reads the SymEngine
    form and never needs them (:meth:`symengine`).

    Attributes
    ----------
    M : (m, m)
        Mass matrix, Eq. 12.
    C : (m, m)
        Coriolis/centripetal matrix of Eq. 22,
        ``C = dM/dq (I ⊗ qd) - 1/2 (dM/dq (qd ⊗ I))^T``.
    C_christoffel : (m, m)
        Christoffel-symbol form ``C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k``;
        same product ``C qd`` as ``C``, and ``Md - 2 C_christoffel`` is skew-symmetric.
    Cqd : (m, 1)
        ``C qd``, the velocity terms of Lagrange's equations, summed body by body
        (``J^T W Jd qd`` for a translation); equal to ``C * qd`` but far smaller
        for long chains, which is what the numeric model evaluates.
    g : (m, 1)
        ``(dPi/dq)^T``, the gradient of the potential energy.
    Phi : (r, 1)
        Holonomic constraints ``f(q)``.
    Phi_q : (r, m)
        Constraint Jacobian ``df/dq``.
    Phi_t : (r, 1)
        ``df/dt``, nonzero for drives (rheonomic constraints ``f(q, t) = 0``).
    A : (s, m), b : (s, 1)
        Nonholonomic constraints ``A(q) qd + b(q) = 0``.
    f_Q : (m, 1)
        Generalized non-conservative forces (may depend on q, qd and ``t``).
    potential_energy : expression
        ``Pi(q)``.


    References
    ----------
    .. [1] N. Van Khang, "Kronecker product and a new matrix form of Lagrangian equations with
       multipliers for constrained multibody systems", Mechanics Research Communications 38 (2011)
       294-299, https://doi.org/10.1016/j.mechrescom.2011.04.004
    """

    system: System
    time: sp.Symbol
    source: MatrixSource = field(repr=False)

    M = _stored("M", "Mass matrix (m, m), Eq. 12.")
    C = _stored("C", "Coriolis/centripetal matrix (m, m) of Eq. 22.")
    Cqd = _stored("Cqd", "``C qd`` (m, 1), summed body by body.")
    g = _stored("g", "``(dPi/dq)^T`` (m, 1).")
    Phi = _stored("Phi", "Holonomic constraints ``f(q)`` (r, 1).")
    Phi_q = _stored("Phi_q", "Constraint Jacobian ``df/dq`` (r, m).")
    A = _stored("A", "Nonholonomic constraint matrix (s, m).")
    b = _stored("b", "Nonholonomic constraint offset (s, 1): ``A qd + b = 0``.")
    f_Q = _stored("f_Q", "Generalized non-conservative forces (m, 1).")
    potential_energy = _stored("potential_energy", "``Pi(q)``.")
    C_christoffel = _stored("C_christoffel", "Christoffel-symbol form of the Coriolis matrix, shape (m, m); "
                            "see the class docstring.")

    def symengine(self, name: str) -> se.DenseMatrix | None:
        """Matrix ``name`` as the derivation left it in SymEngine (symbols named as the system's),
        or None when there is no such form (equations simplified, substituted or unpickled, or a
        matrix computed here): the numeric model's kernels read it without a round trip through SymPy."""
        return self.source.symengine(name)

    # -- symbols --------------------------------------------------------------

    @property
    def coordinates(self) -> tuple[sp.Symbol, ...]:
        """``q`` (length m)."""
        return self.system.coordinates

    @property
    def speeds(self) -> tuple[sp.Symbol, ...]:
        """``qd`` (length m): ``q1`` -> ``q1d``."""
        return self.system.speeds

    @property
    def accelerations(self) -> tuple[sp.Symbol, ...]:
        """``qdd`` (length m): ``q1`` -> ``q1dd``."""
        return self.system.accelerations

    @property
    def parameters(self) -> tuple[sp.Symbol, ...]:
        """The declared parameters."""
        return self.system.parameters

    @cached_property
    def lambdas(self) -> tuple[sp.Symbol, ...]:
        """Multipliers ``lambda1 .. lambdar`` of the holonomic constraints."""
        return tuple(sp.Symbol(f"lambda{j + 1}") for j in range(self.Phi.rows))

    @cached_property
    def mus(self) -> tuple[sp.Symbol, ...]:
        """Multipliers ``mu1 .. mus`` of the nonholonomic constraints."""
        return tuple(sp.Symbol(f"mu{k + 1}") for k in range(self.A.rows))

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(m, r, s)``: coordinates, holonomic and nonholonomic constraints."""
        return self.source.shape

    # -- derived matrices -------------------------------------------------------

    @cached_property
    def dM_dq(self) -> sp.ImmutableMatrix:
        """``dM/dq`` (Definition 1), shape (m, m²): entry ``(i, j m + k)`` is ``dM_ij/dq_k``."""
        return sp.ImmutableMatrix(matrix_derivative(self.M, self.coordinates))

    @cached_property
    def Md(self) -> sp.ImmutableMatrix:
        """``dM/dt = sum_k dM/dq_k qd_k`` (Theorem 1), shape (m, m)."""
        total = sp.zeros(*self.M.shape)
        for q, qd in zip(self.coordinates, self.speeds):
            total += self.M.diff(q) * qd
        return sp.ImmutableMatrix(total)

    @cached_property
    def Phi_t(self) -> sp.ImmutableMatrix:
        """``Phi_t = dPhi/dt`` at fixed q, shape (r, 1): zero unless constraints are drives
        (rheonomic); the velocity constraints are ``Phi_q qd + Phi_t = 0``."""
        return sp.ImmutableMatrix(self.Phi.diff(self.time))

    @cached_property
    def rheonomic(self) -> bool:
        """Whether a constraint depends on the time (a drive)."""
        return self.time in set().union(*(entry.free_symbols for entry in (*self.Phi, *self.b)))

    @cached_property
    def constraints_do_work(self) -> bool:
        """Whether the constraint forces can do work: ``Phi_t`` or ``b`` is not identically zero
        (their power is ``lambda^T Phi_t + mu^T b`` on the constraint manifold)."""
        return any(entry != 0 for entry in (*self.Phi_t, *self.b))

    @cached_property
    def gamma(self) -> sp.ImmutableMatrix:
        """``gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt``, shape (r, 1), so that ``Phi_q qdd = gamma``.

        ``dPhi_q/dt = dPhi_q/dq (I ⊗ qd)`` (Theorem 1), evaluated as the sparse sum
        ``sum_k dPhi_q/dq_k qd_k``; the time terms vanish unless constraints are drives.
        """
        return self._acceleration_offset(self.Phi_q, self.Phi_t)

    @cached_property
    def gamma_nh(self) -> sp.ImmutableMatrix:
        """``-(dA/dt) qd - db/dt``, shape (s, 1), so that ``A qdd = gamma_nh``."""
        return self._acceleration_offset(self.A, self.b)

    def _acceleration_offset(self, jacobian: sp.MatrixBase, offset: sp.MatrixBase) -> sp.ImmutableMatrix:
        """-d/dt (jacobian qd + offset) at fixed ``qd`` (:func:`acceleration_offset`)."""
        # differentiated in SymEngine: SymPy's diff of the velocity of closed_chain(30, "relative")
        # takes 25 s, SymEngine's 0.1 s (and 0.2 s back to SymPy)
        native = acceleration_offset(se.DenseMatrix(jacobian.rows, jacobian.cols, [se.sympify(e) for e in jacobian]),
                                     se.DenseMatrix(offset.rows, 1, [se.sympify(e) for e in offset]),
                                     [se.sympify(q) for q in self.coordinates], [se.sympify(v) for v in self.speeds],
                                     se.sympify(self.time))
        return sp.ImmutableMatrix(offset.rows, 1, [entry._sympy_() for entry in native])

    @cached_property
    def kinetic_energy(self) -> sp.Expr:
        """``T = 1/2 qd^T M qd``."""
        qd = sp.Matrix(self.speeds)
        return (qd.T * self.M * qd)[0, 0] / 2

    @cached_property
    def residual(self) -> sp.ImmutableMatrix:
        """Eq. 23 as residuals, shape (m + r + s, 1)::

            [M qdd + C qd + Phi_q^T lambda + A^T mu + g - f_Q;  f(q);  A qd + b]
        """
        qdd = sp.Matrix(self.accelerations)
        qd = sp.Matrix(self.speeds)
        dynamics = self.M * qdd + self.C * qd + self.g - self.f_Q
        if self.Phi.rows:
            dynamics += self.Phi_q.T * sp.Matrix(self.lambdas)
        if self.A.rows:
            dynamics += self.A.T * sp.Matrix(self.mus)
        rows = list(dynamics) + list(self.Phi) + list(self.A * qd + self.b)
        return sp.ImmutableMatrix(len(rows), 1, rows)

    # -- transformations --------------------------------------------------------

    def simplify(self, simplifier: Callable[[sp.Expr], sp.Expr] = sp.trigsimp) -> Equations:
        """A new equations object with ``simplifier`` applied to every entry (default ``trigsimp``)."""
        return self._transformed(lambda item: item.applyfunc(simplifier) if isinstance(item, sp.MatrixBase)
                                 else simplifier(item))

    def subs(self, values: dict) -> Equations:
        """A new equations object with parameters replaced by values (names or symbols as keys)."""
        by_name = {p.name: p for p in self.parameters}
        mapping = {by_name.get(key, key) if isinstance(key, str) else key: value
                   for key, value in values.items()}
        return self._transformed(lambda item: item.subs(mapping))

    def _transformed(self, transform: Callable) -> Equations:
        matrices: dict[str, Any] = {name: transform(getattr(self, name)) for name in _STORED_NAMES}
        source = StoredMatrices(matrices, deferred={"C_christoffel": lambda: transform(self.C_christoffel)})
        return Equations(system=self.system, time=self.time, source=source)

    # -- numerics ---------------------------------------------------------------

    def numeric(self, parameters: dict, *, backend: str = "auto", rank_rtol: float | None = None):
        """Generate and compile the numeric model (:class:`kronlag.numeric.NumericModel`).

        Parameters
        ----------
        parameters : dict
            Value of every parameter, keyed by name or symbol: a float (SI), a pint quantity
            (converted to SI after its dimension is checked against the parameter's use in the
            system: :func:`kronlag.model.dimensions.si_parameter_values`), or a callable ``f(t)``
            for a time-varying one (e.g. a torque).
        backend : {"auto", "c", "python"}
            ``"auto"``: ``"c"`` when a C compiler is available and works, else ``"python"``
            (``"numpy"``: deprecated name of ``"python"``).
        rank_rtol : float, optional
            Relative rank tolerance on ``[Phi_q; A]`` for every rank decision of the
            model (default :data:`kronlag.numeric.tolerances.RANK_RTOL`).
        """
        from ..numeric.numeric_model import NumericModel  # a convenience above this layer (the layer contract)

        parameters = si_parameter_values(self.system, parameters)
        return NumericModel(self, parameters, backend=backend, **({} if rank_rtol is None else {"rank_rtol": rank_rtol}))

    # -- printing ---------------------------------------------------------------

    @cached_property
    def _latex_names(self) -> dict[sp.Symbol, str]:
        names: dict[sp.Symbol, str] = {}
        for q, qd, qdd in zip(self.coordinates, self.speeds, self.accelerations):
            base = sp.latex(q)
            names[qd] = rf"\dot{{{base}}}"
            names[qdd] = rf"\ddot{{{base}}}"
        return names

    def latex(self, name: str | None = None) -> str:
        """LaTeX of one matrix (``"M"``, ``"C"``, ...) or, with no name, of Eq. 23."""
        if name is None:
            return self.latex_equations()
        if name not in MATRIX_NAMES + ("dM_dq", "Md"):
            raise InputError(f"unknown matrix {name!r}; choose from {', '.join(MATRIX_NAMES)}, dM_dq, Md")
        return sp.latex(getattr(self, name), symbol_names=self._latex_names)

    def latex_equations(self) -> str:
        r"""Eq. 23 written out row by row as a LaTeX ``aligned`` block (each row ``= 0``)."""
        lines = [sp.latex(row, symbol_names=self._latex_names) + r" &= 0" for row in self.residual]
        return "\\begin{aligned}\n" + " \\\\\n".join(lines) + "\n\\end{aligned}"

    def __repr__(self) -> str:
        m, r, s = self.shape
        return f"Equations({self.system.name!r}, m={m}, r={r}, s={s})"

    # -- pickling ---------------------------------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        """The fields and cached matrices, with the source as SymPy matrices (converted now if not
        yet): the Christoffel form as the matrix when already computed, else its formula."""
        state = dict(self.__dict__)
        matrices = {name: getattr(self, name) for name in _STORED_NAMES}
        if "C_christoffel" in state:
            matrices["C_christoffel"] = state["C_christoffel"]
            deferred = {}
        else:
            deferred = {"C_christoffel": partial(christoffel_matrix, self.M, self.coordinates, self.speeds)}
        state["source"] = StoredMatrices(matrices, deferred=deferred)
        return state

    def __str__(self) -> str:
        blocks = [repr(self)]
        for name in MATRIX_NAMES:
            matrix = getattr(self, name)
            if matrix.rows:
                blocks.append(f"{name} =\n{sp.pretty(matrix, use_unicode=False, wrap_line=False)}")
        return "\n\n".join(blocks)


def christoffel_matrix(M: sp.MatrixBase, coordinates, speeds) -> sp.ImmutableMatrix:
    """``C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k`` (m, m) from ``M`` (m, m)."""
    m = M.rows
    derivatives = [M.diff(q) for q in coordinates]
    return sp.ImmutableMatrix(m, m, lambda i, j: sum(
        (derivatives[k][i, j] + derivatives[j][i, k] - derivatives[i][j, k]) * speeds[k] / 2 for k in range(m)))
