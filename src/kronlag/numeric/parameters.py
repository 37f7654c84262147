"""The parameter values of a numeric model: constants in one vector ``p`` (the order of
``Equations.parameters``), and callables ``f(t)`` for time-varying ones, evaluated at every call."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import InputError
from ..model.symbols import name_indices

if TYPE_CHECKING:
    from ..symbolic.equations import Equations

__all__ = ["ParameterValues"]

#: The matrices a time-varying parameter must not enter (their time derivatives would be needed).
_CONSTANT_IN = ("M", "Phi", "A", "b")


@dataclass(frozen=True, eq=False, slots=True)
class ParameterValues:
    """Values of the parameters ``names``: ``constants`` (P,) (the entries of time-varying ones unused)
    and ``time_varying``, the ``(index, f)`` of the parameters given as callables ``f(t)``."""

    names: tuple[str, ...]
    constants: np.ndarray
    time_varying: tuple[tuple[int, Callable[[float], float]], ...]

    @classmethod
    def resolve(cls, equations: Equations, given: Mapping) -> ParameterValues:
        """The values of every parameter of ``equations`` from ``given`` (keyed by name or symbol).

        Raises
        ------
        InputError
            A parameter is missing, unknown, neither a number nor a callable, or is
            time-varying but enters ``M`` or the constraints (finiteness: :meth:`check_finite`).
        """
        names = tuple(p.name for p in equations.parameters)
        index = {name: i for i, name in enumerate(names)}
        values = dict(zip(name_indices(list(given), index, "parameter(s)"), given.values()))
        missing = [name for name, i in index.items() if i not in values]
        if missing:
            raise InputError(f"missing value(s) for parameter(s): {', '.join(missing)}")
        constants = np.zeros(len(names))
        time_varying = []
        for i, value in values.items():
            if callable(value):
                time_varying.append((i, value))
                continue
            try:
                constants[i] = float(value)
            except (TypeError, ValueError) as error:
                raise InputError(f"parameter {names[i]}: expected a number or a callable f(t), got {value!r}") from error
        frozen = [names[i] for i, _ in time_varying
                  if any(getattr(equations, name).has(equations.parameters[i]) for name in _CONSTANT_IN)]
        if frozen:
            raise InputError(f"parameter(s) {', '.join(frozen)} enter M or the constraints and cannot vary "
                             "with time (the equations would need their time derivatives)")
        return cls(names, constants, tuple(time_varying))

    def check_finite(self) -> None:
        """InputError naming the first constant parameter that is not a finite number (after the bodies'
        physical checks, which name the body a bad mass or inertia belongs to)."""
        bad = [i for i, value in enumerate(self.constants) if not np.isfinite(value)]  # time-varying ones: 0
        if bad:
            raise InputError(f"parameter {self.names[bad[0]]}: expected a finite number, got {self.constants[bad[0]]!r}")

    def vector(self, t: float = 0.0) -> np.ndarray:
        """``p`` at time ``t``, shape (P,) (the constants themselves, not a copy, when nothing varies)."""
        if not self.time_varying:
            return self.constants
        p = self.constants.copy()
        for i, function in self.time_varying:
            p[i] = float(function(t))
        return p

    def batch(self, times: np.ndarray) -> np.ndarray:
        """``p`` at the times ``times`` (0-d or (N,)): (P,) when nothing varies or ``times`` is 0-d, else (N, P)."""
        if not self.time_varying:
            return self.constants
        if times.ndim == 0:
            return self.vector(float(times))
        return np.array([self.vector(time) for time in times]).reshape(len(times), len(self.names))

    def as_dict(self) -> dict[str, float | Callable]:
        """The values by name: floats, and the callables ``f(t)`` of time-varying ones."""
        values: dict[str, float | Callable] = dict(zip(self.names, self.constants.tolist()))
        values.update({self.names[i]: function for i, function in self.time_varying})
        return values
