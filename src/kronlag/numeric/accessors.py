"""The matrix accessors of :class:`~kronlag.numeric.numeric_model.NumericModel`: ``model.M(q, t)``,
``model.C(q, qd, t)``, ... one per matrix of the catalogue (:mod:`kronlag.symbolic.matrices`).

They are made from the catalogue at import time and set on :class:`MatrixAccessors`, the base class of
``NumericModel``; the same methods are declared for type checkers, which cannot see methods set at run
time (tests/test_packaging.py checks that the declarations name the catalogue's accessors, with ``qd``
where the matrix depends on the speeds).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from ..symbolic import matrices as catalogue

__all__ = ["MatrixAccessors", "ACCESSOR_MATRICES"]


class MatrixAccessors:
    """``model.<name>(q[, qd], t=0.0)`` for every matrix of the catalogue with an accessor (but
    ``potential_energy``, a float: :meth:`NumericModel.potential_energy`)."""

    if TYPE_CHECKING:
        def _evaluate(self, name: str, q: Any, qd: Any, t: float) -> np.ndarray: ...  # NumericModel's

        def M(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def C(self, q: Any, qd: Any, t: float = 0.0) -> np.ndarray: ...
        def C_christoffel(self, q: Any, qd: Any, t: float = 0.0) -> np.ndarray: ...
        def Cqd(self, q: Any, qd: Any, t: float = 0.0) -> np.ndarray: ...
        def g(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def Phi(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def Phi_q(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def Phi_t(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def gamma(self, q: Any, qd: Any, t: float = 0.0) -> np.ndarray: ...
        def A(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def b(self, q: Any, t: float = 0.0) -> np.ndarray: ...
        def gamma_nh(self, q: Any, qd: Any, t: float = 0.0) -> np.ndarray: ...
        def f_Q(self, q: Any, qd: Any, t: float = 0.0) -> np.ndarray: ...


def _accessor(entry: catalogue.EquationMatrix) -> Callable[..., np.ndarray]:
    """The method ``model.<name>(q[, qd], t=0.0)`` of a matrix of the catalogue, with its docstring."""
    name = entry.name

    def of_speeds(self: MatrixAccessors, q: Any, qd: Any, t: float = 0.0) -> np.ndarray:
        return self._evaluate(name, q, qd, t)

    def of_positions(self: MatrixAccessors, q: Any, t: float = 0.0) -> np.ndarray:
        return self._evaluate(name, q, None, t)

    accessor: Callable[..., np.ndarray] = of_speeds if entry.speeds else of_positions
    shape = f"({entry.rows},)" if entry.vector else f"({entry.rows}, {entry.columns})"
    accessor.__name__ = accessor.__qualname__ = name
    accessor.__doc__ = f"``{name}``: {entry.meaning}, shape {shape}."
    return accessor


#: The catalogue's matrices that have an accessor here.
ACCESSOR_MATRICES = tuple(entry for entry in catalogue.MATRICES.values()
                          if entry.accessor and entry.name != "potential_energy")

for _entry in ACCESSOR_MATRICES:
    setattr(MatrixAccessors, _entry.name, _accessor(_entry))
