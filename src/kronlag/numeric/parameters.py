"""The parameter values of a numeric model: constants in one vector ``p`` (the order of
``Equations.parameters``), callables ``f(t)`` for time-varying ones, evaluated at every call, and
definitions: parameters given as SymPy expressions of others (``I1 = m1*l1**2/12``), computed in
the order of their dependencies and computed again whenever the values they use change."""

from __future__ import annotations

import cmath
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from ..core.errors import InputError
from ..core.dependencies import dependency_order
from ..model.bodies import check_parameter_values
from ..model.symbols import name_indices

if TYPE_CHECKING:
    from ..model.system import System
    from ..symbolic.equations import Equations

__all__ = ["ParameterValues"]

#: The matrices a time-varying parameter must not enter (their time derivatives would be needed).
_CONSTANT_IN = ("M", "Phi", "A", "b")


@dataclass(frozen=True, eq=False, slots=True)
class ParameterValues:
    """Values of the parameters ``names``: ``constants`` (P,) (the entries of time-varying ones unused),
    ``time_varying``, the ``(index, f)`` of the parameters given as callables ``f(t)``, and
    ``definitions``, the ``(index, expression)`` of the parameters defined by an expression of others,
    in the order of their dependencies (their values are in ``constants``)."""

    names: tuple[str, ...]
    constants: np.ndarray
    time_varying: tuple[tuple[int, Callable[[float], float]], ...]
    definitions: tuple[tuple[int, sp.Expr], ...] = ()

    @classmethod
    def resolve(cls, equations: Equations, given: Mapping) -> ParameterValues:
        """The values of every parameter of ``equations`` from ``given`` (keyed by name or symbol).

        A value is a number, a callable ``f(t)`` (a time-varying parameter) or a SymPy expression
        of other parameters (a definition, e.g. ``m1*l1**2/12``, as a model file writes it):
        computed from their values, and again by :meth:`changed` when they change.

        Raises
        ------
        InputError
            A parameter is missing, unknown, neither a number, a callable nor an expression
            of other (constant) parameters, definitions form a cycle or give no finite real
            number, or a parameter is time-varying but enters ``M`` or the constraints
            (finiteness: :meth:`check_finite`).
        """
        names = tuple(p.name for p in equations.parameters)
        index = {name: i for i, name in enumerate(names)}
        values = dict(zip(name_indices(list(given), index, "parameter(s)"), given.values()))
        missing = [name for name, i in index.items() if i not in values]
        if missing:
            raise InputError(f"missing value(s) for parameter(s): {', '.join(missing)}")
        constants = np.zeros(len(names))
        time_varying, expressions = [], {}
        for i, value in values.items():
            if isinstance(value, sp.Basic) and value.free_symbols:  # before callable(): a Symbol is callable
                expressions[i] = value
                continue
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
        definitions = _in_dependency_order(names, expressions, {i for i, _ in time_varying})
        for i, expression in definitions:
            constants[i] = _defined_value(names[i], expression, index, constants)
        return cls(names, constants, tuple(time_varying), definitions)

    def changed(self, equations: Equations, given: Mapping) -> ParameterValues:
        """These values with those of ``given`` (by name or symbol) replaced; the definitions not given
        are computed again from the new values, a definition given a value is dropped."""
        index = {name: i for i, name in enumerate(self.names)}
        names = [self.names[i] for i in name_indices(list(given), index, "parameter(s)")]
        return ParameterValues.resolve(equations, {**self.specification(), **dict(zip(names, given.values()))})

    def specification(self) -> dict[str, float | Callable | sp.Expr]:
        """What rebuilds these values (:meth:`resolve`): :meth:`as_dict` with every defined parameter
        as its expression."""
        return {**self.as_dict(), **self.definitions_by_name()}

    def definitions_by_name(self) -> dict[str, sp.Expr]:
        """The expressions of the defined parameters, in the order of their dependencies."""
        return {self.names[i]: expression for i, expression in self.definitions}

    def check(self, system: System) -> None:
        """The bodies' physical checks (:func:`kronlag.model.bodies.check_parameter_values`, ModelError
        naming the body), then :meth:`check_finite`."""
        check_parameter_values(system, dict(zip(self.names, self.vector(0.0).tolist())))
        self.check_finite()

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


def _in_dependency_order(names: tuple[str, ...], expressions: Mapping[int, sp.Expr],
                         time_varying: set[int]) -> tuple[tuple[int, sp.Expr], ...]:
    """The definitions ordered so that each comes after those it uses (:func:`dependency_order`);
    InputError for an unknown name, a time-varying dependency or a cycle."""
    index = {name: i for i, name in enumerate(names)}
    uses: dict[int, set[int]] = {}
    for i, expression in expressions.items():
        used = {symbol.name for symbol in expression.free_symbols}
        unknown = sorted(used - index.keys())
        if unknown:
            raise InputError(f"parameter {names[i]} = {expression}: {', '.join(unknown)} are not parameters")
        varying = sorted(name for name in used if index[name] in time_varying)
        if varying:
            raise InputError(f"parameter {names[i]} = {expression} uses the time-varying {', '.join(varying)}: "
                             "give it a value or a callable f(t) of its own")
        uses[i] = {index[name] for name in used} & expressions.keys()
    order, left = dependency_order(uses)
    if left:  # the cycles and what depends on them
        while (used := set().union(*(uses[i] for i in left)) & left) != left:  # drop the mere dependents
            left = used
        cycle = sorted(names[i] for i in left)
        raise InputError(f"parameter definitions depend on each other in a cycle: {', '.join(cycle)}")
    return tuple((i, expressions[i]) for i in order)


def _defined_value(name: str, expression: sp.Expr, index: Mapping[str, int], constants: np.ndarray) -> float:
    """The value of a definition from the values it uses (substituted, never parsed or executed)."""
    used = {symbol: sp.Float(float(constants[index[symbol.name]])) for symbol in expression.free_symbols}
    value = expression.xreplace(used)
    try:
        number = complex(value)
    except (TypeError, ValueError):
        number = complex("nan")
    if number.imag != 0 or not cmath.isfinite(number):
        given = ", ".join(f"{symbol.name} = {float(v):g}" for symbol, v in sorted(used.items(), key=str))
        raise InputError(f"parameter {name} = {expression} is not a finite real number for {given}: {value}")
    return number.real
