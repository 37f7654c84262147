"""Dimensions of a model's quantities: inferred from where each expression is used, checked against units.

Every symbol of a system (coordinate, parameter) gets a dimension, a product of powers of the
base dimensions (mass, length, time, ...).  Where an expression is used fixes its dimension:

- a body's mass is a mass, its position a length, its planar angle and the entries of its
  rotation dimensionless, its inertia (planar scalar, spatial tensor entries) a mass*length^2;
- gravity is a length/time^2; a point of a spring, damper, force, drawing or trace a length;
- a spring's stiffness an energy/length^2 and its free length a length, a damper's coefficient a force/speed, a
  force a force, a torque and a potential an energy, the generalized force of a coordinate ``q`` an energy/dim(q),
  a joint's friction quantities as :func:`kronlag.model.friction.friction_uses` says;
- the terms of every sum are alike (so each constraint row is homogeneous and a drive's motion
  has its target's dimension), the arguments of sin, cos, exp, log, ... and of a power with a
  symbolic exponent are dimensionless, ``t`` is a time and the speed of ``q`` is dim(q)/time.

A number written in an expression is SI: as a term of a sum it takes the sum's dimension
(``x - 0.5``), as a factor it is a pure number.  A parameter given a unit (in a model file, or
as a pint quantity in Python: :func:`si_parameter_values`) has that unit's dimension; one
without a unit, and every coordinate, takes the dimension its uses give it.

The checks are a linear system in the exponents: the units are entered first, then the uses, then
the derived parameters' definitions.  An equation that contradicts what is known is refused
when the contradiction involves a unit (:class:`DimensionConflict`, naming the unit or the
definition and the uses); among quantities that have no unit at all (a parameter taken "as given
in SI", a coordinate) a contradiction is not refused, since nothing declared is wrong there.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

import sympy as sp

from ..core.errors import InputError, ModelError
from .bodies import Body
from .friction import friction_uses
from .loads import BodyTorque, Damper, GeneralizedForce, PointForce, Spring
from .symbols import speed_symbol, t

if TYPE_CHECKING:
    from .system import System

__all__ = ["Dimension", "Place", "DimensionCheck", "DimensionConflict", "SI_FACTOR_RANGE", "check_si_factor",
           "si_parameter_values", "DIMENSIONLESS", "MASS", "LENGTH", "TIME"]

#: The smallest and largest SI factor of a unit (``"mm"``: 1e-3); outside, values under- or overflow.
SI_FACTOR_RANGE = (1e-300, 1e300)

_ORDER = ("[mass]", "[length]", "[time]")


class Dimension:
    """A product of powers of base dimensions (pint's names: ``"[mass]"``, ``"[length]"``, ...).

    ``Dimension(quantity.dimensionality)`` for a pint quantity; ``*``, ``/`` and ``**`` combine them.
    """

    __slots__ = ("powers",)

    def __init__(self, powers: Mapping[str, Fraction | int | float] = ()):
        order = {base: i for i, base in enumerate(_ORDER)}
        self.powers = tuple(sorted(((base, Fraction(power).limit_denominator(1000)) for base, power in dict(powers).items()
                                    if power != 0), key=lambda item: (order.get(item[0], len(order)), item[0])))

    def __mul__(self, other: Dimension) -> Dimension:
        return self.combine(other, 1)

    def __truediv__(self, other: Dimension) -> Dimension:
        return self.combine(other, -1)

    def __pow__(self, power: Fraction | int) -> Dimension:
        return Dimension({base: value * power for base, value in self.powers})

    def combine(self, other: Dimension, power: Fraction | int) -> Dimension:
        """``self * other**power``."""
        powers = dict(self.powers)
        for base, value in other.powers:
            powers[base] = powers.get(base, 0) + value * power
        return Dimension(powers)

    def __eq__(self, other) -> bool:
        return isinstance(other, Dimension) and self.powers == other.powers

    def __hash__(self) -> int:
        return hash(self.powers)

    def __bool__(self) -> bool:  # False for the dimensionless
        return bool(self.powers)

    def formula(self) -> str:
        """``"mass*length^2/time^2"``; ``"1"`` when dimensionless."""
        def factors(items):
            return "*".join(base.strip("[]") + ("" if power == 1 else f"^{power}" if power.denominator == 1
                                                else f"^({power})") for base, power in items)
        above = factors((base, power) for base, power in self.powers if power > 0) or "1"
        below = [(base, -power) for base, power in self.powers if power < 0]
        if not below:
            return above
        return f"{above}/{factors(below)}" if len(below) == 1 else f"{above}/({factors(below)})"

    def describe(self) -> str:
        """What messages call it: ``"a length"``, ``"a moment of inertia (mass*length^2)"``."""
        name = _NAMES.get(self.powers)
        if name is None:
            return f"a quantity of dimension {self.formula()}"
        simple = not self or (len(self.powers) == 1 and self.powers[0][1] == 1)
        return name if simple else f"{name} ({self.formula()})"

    def __repr__(self) -> str:
        return f"Dimension({self.formula()})"


DIMENSIONLESS = Dimension()
MASS = Dimension({"[mass]": 1})
LENGTH = Dimension({"[length]": 1})
TIME = Dimension({"[time]": 1})
_INERTIA = MASS * LENGTH ** 2
_FORCE = MASS * LENGTH / TIME ** 2
_ENERGY = _FORCE * LENGTH
_ACCELERATION = LENGTH / TIME ** 2

_NAMES = {dimension.powers: name for dimension, name in (
    (DIMENSIONLESS, "dimensionless (an angle or a ratio)"), (MASS, "a mass"), (LENGTH, "a length"),
    (TIME, "a time"), (_INERTIA, "a moment of inertia"), (_ACCELERATION, "an acceleration"),
    (LENGTH / TIME, "a speed"), (TIME ** -1, "a frequency or an angular speed"),
    (TIME ** -2, "an angular acceleration"), (_FORCE, "a force"), (_ENERGY, "an energy or a torque"),
    (_ENERGY / LENGTH ** 2, "a stiffness"), (_FORCE * TIME / LENGTH, "a damping coefficient"))}

#: The dimension of a body field (:attr:`kronlag.model.bodies.Field.name`; every entry of a vector or matrix).
_BODY_FIELDS = {"mass": MASS, "inertia": _INERTIA, "position": LENGTH, "angle": DIMENSIONLESS,
                "rotation": DIMENSIONLESS}


def check_si_factor(factor: float) -> None:
    """ValueError unless ``factor`` (one unit in SI base units) is finite and within :data:`SI_FACTOR_RANGE`."""
    low, high = SI_FACTOR_RANGE
    if not math.isfinite(factor) or not low <= abs(factor) <= high:
        raise ValueError(f"its SI factor {factor!r} is outside {low:g}..{high:g}: values in this unit would "
                         "under- or overflow")


# -- the linear system of the exponents ----------------------------------------------------------

@dataclass(frozen=True)
class _Form:
    """``prod x_i**c_i * constant``: a dimension in terms of unknown ones (the symbols' dimensions)."""

    coefficients: Mapping[int, Fraction]
    constant: Dimension = DIMENSIONLESS

    def times(self, other: _Form, power: Fraction | int = 1) -> _Form:
        """``self * other**power``."""
        coefficients = dict(self.coefficients)
        for index, value in other.coefficients.items():
            coefficients[index] = coefficients.get(index, 0) + value * power
        return _Form({index: value for index, value in coefficients.items() if value},
                     self.constant.combine(other.constant, power))


def _known(dimension: Dimension) -> _Form:
    return _Form({}, dimension)


def _unknown(index: int) -> _Form:
    """The dimension of unknown ``index`` (a symbol's)."""
    return _Form({index: Fraction(1)})


class _Solver:
    """Equations ``form = dimensionless`` kept in triangular form.  Each row records how it was made
    (its equation, scaled, minus multiples of earlier rows), so that a contradiction can name the
    equations behind it without every row carrying that list."""

    def __init__(self):
        # pivot -> (row with coefficient 1 at the pivot, its equation, its scale, the (pivot, factor) subtracted)
        self.rows: dict[int, tuple[_Form, int, Fraction, tuple[tuple[int, Fraction], ...]]] = {}
        self.rank: dict[int, int] = {}  # pivot -> when it became one

    def reduce(self, form: _Form) -> tuple[_Form, list[tuple[int, Fraction]]]:
        """The form with every pivot eliminated (earliest first: a row holds only later pivots), and the
        ``(pivot, factor)`` of the rows subtracted."""
        queue = [(self.rank[index], index) for index in form.coefficients if index in self.rows]
        heapq.heapify(queue)
        steps = []
        while queue:
            _, pivot = heapq.heappop(queue)
            factor = form.coefficients.get(pivot)
            if factor is None:
                continue
            row = self.rows[pivot][0]
            form = form.times(row, -factor)
            steps.append((pivot, factor))
            for index in row.coefficients:
                if index in self.rows and index != pivot and index in form.coefficients:
                    heapq.heappush(queue, (self.rank[index], index))
        return form, steps

    def add(self, form: _Form, equation: int) -> dict[int, Fraction] | None:
        """Enter ``form = dimensionless``; for a contradiction, the equations combined into it (with
        their factors), else None."""
        form, steps = self.reduce(form)
        if not form.coefficients:
            return self._combination(equation, steps) if form.constant else None
        pivot = min(form.coefficients)
        scale = 1 / form.coefficients[pivot]
        self.rows[pivot] = (_Form({}).times(form, scale), equation, scale, tuple(steps))
        self.rank[pivot] = len(self.rank)
        return None

    def _combination(self, equation: int, steps: list[tuple[int, Fraction]]) -> dict[int, Fraction]:
        """The equations' factors in ``equation - sum(factor * row)``, the rows expanded latest first."""
        factors = {equation: Fraction(1)}
        pending = {pivot: -factor for pivot, factor in steps}
        queue = [(-self.rank[pivot], pivot) for pivot in pending]
        heapq.heapify(queue)
        while queue:
            _, pivot = heapq.heappop(queue)
            weight = pending.pop(pivot)
            _, source, scale, made = self.rows[pivot]
            factors[source] = factors.get(source, 0) + weight * scale
            for earlier, factor in made:  # made of earlier rows only: expanded after this one
                if earlier not in pending:
                    heapq.heappush(queue, (-self.rank[earlier], earlier))
                pending[earlier] = pending.get(earlier, 0) - weight * scale * factor
        return {index: factor for index, factor in factors.items() if factor}

    def value(self, form: _Form) -> Dimension | None:
        """The dimension the equations give ``form``; None where they leave it open."""
        form, _ = self.reduce(form)
        return None if form.coefficients else form.constant


# -- places and conflicts -------------------------------------------------------------------------

@dataclass(frozen=True)
class Place:
    """Where a quantity is declared or used: ``entry`` in a model file (``"bodies[2].mass"``) and its
    ``description`` for a system built in Python (``"body 'piston' mass"``)."""

    entry: str
    description: str


class DimensionConflict(ModelError):
    """A unit or a derived parameter's definition that does not fit how the parameter is used: ``entry``
    (the model-file entry, or the parameter in Python) and ``problem`` (naming the other places)."""

    def __init__(self, entry: str, problem: str):
        super().__init__(f"{entry}: {problem}")
        self.entry = entry
        self.problem = problem


@dataclass(frozen=True)
class _Declaration:
    """A parameter's unit or definition: the facts a conflict can be blamed on."""

    parameter: str
    place: Place
    text: str  # the unit or the expression as written
    kind: str  # "unit" or "value"


_NUMBER = None  # the form of a pure number: SI, takes the dimension of the terms it is added to


class DimensionCheck:
    """The dimensions of a system's symbols, inferred from units, definitions and uses.

    Enter the units (:meth:`unit`) first, then the uses (:meth:`system_uses`, :meth:`use`,
    :meth:`same`), then the derived parameters' definitions (:meth:`derived`); each raises
    :class:`DimensionConflict` at the first one that contradicts a unit (so that a wrong unit is
    named with the use it contradicts, and a definition with the unit or the uses of its parameter).

    Parameters
    ----------
    system : System
    in_file : bool
        Name places by their model-file entries (else by their descriptions).
    """

    def __init__(self, system: System, *, in_file: bool):
        self.system = system
        self.in_file = in_file
        self.solver = _Solver()
        # each equation: its form (= dimensionless), where it comes from, the parameters its expression names
        self.equations: list[tuple[_Form, Place | _Declaration, frozenset[str]]] = []
        self.symbols: dict[sp.Symbol, _Form] = {t: _known(TIME)}
        self.parameters: dict[str, int] = {}
        for index, symbol in enumerate((*system.parameters, *system.coordinates)):
            self.symbols[symbol] = _unknown(index)
            if index < len(system.parameters):
                self.parameters[symbol.name] = index
        for q in system.coordinates:
            self.symbols[speed_symbol(q)] = self.symbols[q].times(_known(TIME), -1)
        self._unknowns = len(system.parameters) + len(system.coordinates)
        self._names: frozenset[str] = frozenset()
        self._forms: dict[sp.Basic, _Form | None] = {}  # of the subexpressions seen, whose requirements are entered

    # -- entering facts ---------------------------------------------------------------------------

    def unit(self, parameter: str, dimension: Dimension, *, unit: str, place: Place) -> None:
        """The parameter is given in ``unit`` (as written), of ``dimension``."""
        self._names = frozenset((parameter,))
        form = _unknown(self.parameters[parameter]).times(_known(dimension), -1)
        self._equate(form, _Declaration(parameter, place, unit, "unit"))

    def derived(self, parameter: str, expression: sp.Expr, *, text: str, place: Place) -> None:
        """The parameter is defined as ``expression`` (``text`` as written)."""
        declaration = _Declaration(parameter, place, text, "value")
        value = self._start(expression, declaration)
        if value is not _NUMBER:
            self._equate(_unknown(self.parameters[parameter]).times(value, -1), declaration)

    def use(self, expression: sp.Expr, dimension: Dimension | None, place: Place) -> None:
        """``expression`` is used as a ``dimension`` (None: only its own sums must be homogeneous)."""
        form = self._start(expression, place)
        if dimension is not None and form is not _NUMBER:
            self._equate(form.times(_known(dimension), -1), place)

    def same(self, first: sp.Expr, second: sp.Expr, place: Place) -> None:
        """``first`` and ``second`` have one dimension (a drive's target and motion, a coordinate and its guess)."""
        self._start(sp.Add(first, -second, evaluate=False), place)

    def system_uses(self) -> None:
        """The uses of every expression of the system: bodies, points, joints, constraints, loads, drawing."""
        for place, expression, dimension in _uses(self.system):
            self.use(expression, dimension, place)

    # -- inference --------------------------------------------------------------------------------

    def _start(self, expression, origin: Place | _Declaration) -> _Form | None:
        expression = sp.sympify(expression)
        self._names = frozenset(symbol.name for symbol in expression.free_symbols) & self.parameters.keys()
        return self.form(expression, origin)

    def form(self, expression: sp.Basic, origin: Place | _Declaration) -> _Form | None:
        """The dimension of an expression (None for a pure number), requiring its parts to fit."""
        if isinstance(expression, sp.Symbol):
            if expression not in self.symbols:
                self.symbols[expression] = self._fresh()
            return self.symbols[expression]
        if not expression.args:
            return _NUMBER
        if expression not in self._forms:
            self._forms[expression] = self._compound(expression, origin)
        return self._forms[expression]

    def _compound(self, expression: sp.Basic, origin: Place | _Declaration) -> _Form | None:
        if isinstance(expression, sp.Piecewise):
            return self._alike([self.form(value, origin) for value, _ in expression.args], origin)
        parts = [self.form(argument, origin) for argument in expression.args]
        if expression.is_Add or isinstance(expression, sp.Min | sp.Max):
            return self._alike(parts, origin)
        known = [part for part in parts if part is not _NUMBER]
        if not known:
            return _NUMBER
        if expression.is_Mul:
            product = _Form({})
            for part in known:
                product = product.times(part)
            return product
        if expression.is_Pow and (expression.exp.is_Rational or expression.exp.is_Float):
            return _Form({}).times(parts[0], Fraction(float(expression.exp)).limit_denominator(1000))
        if isinstance(expression, sp.Abs):
            return parts[0]
        if isinstance(expression, sp.atan2):
            self._alike(parts, origin)
            return _known(DIMENSIONLESS)
        if isinstance(expression, sp.sign | sp.Heaviside):
            return _known(DIMENSIONLESS)
        if expression.is_Pow or isinstance(expression, sp.Function):
            for part in known:  # a symbolic power, sin, exp, log, ...: of dimensionless arguments
                self._equate(part, origin)
            return _known(DIMENSIONLESS)
        return self._fresh()  # nothing known about other constructs: no requirement either

    def _alike(self, parts: list[_Form | None], origin: Place | _Declaration) -> _Form | None:
        """The common dimension of terms (numbers take it)."""
        known = [part for part in parts if part is not _NUMBER]
        for part in known[1:]:
            self._equate(part.times(known[0], -1), origin)
        return known[0] if known else _NUMBER

    def _fresh(self) -> _Form:
        self._unknowns += 1
        return _unknown(self._unknowns)

    def _equate(self, form: _Form, origin: Place | _Declaration) -> None:
        self.equations.append((form, origin, self._names))
        contradiction = self.solver.add(form, len(self.equations) - 1)
        if contradiction is None:
            return
        declarations = [i for i in contradiction if isinstance(self.equations[i][1], _Declaration)]
        if not any(self._is_unit(i) for i in declarations):
            self.equations[-1] = (_Form({}), origin, self._names)  # no unit involved: taken as given (see above)
            return
        raise self._conflict(sorted(contradiction), declarations)

    # -- messages ---------------------------------------------------------------------------------

    def _text(self, place: Place) -> str:
        return place.entry if self.in_file else place.description

    def _conflict(self, involved: list[int], declarations: list[int]) -> DimensionConflict:
        """The conflict among the equations ``involved`` (the last one just entered), blamed on one
        declaration: a definition just entered (against its parameter's unit, or against its uses);
        else the unit, then the definition, of a parameter the failing expression names; else the
        first unit."""
        last = involved[-1]
        origin = self.equations[last][1]
        if isinstance(origin, _Declaration):
            return self._definition(involved, last)
        named = self.equations[last][2]
        blamed_index = min(declarations, key=lambda i: (self.equations[i][1].parameter not in named,
                                                        self.equations[i][1].kind != "unit", i))
        blamed = self.equations[blamed_index][1]
        index = self.parameters[blamed.parameter]
        others = [i for i in involved if i != blamed_index]
        if blamed.kind == "unit":
            declared = self._solved([blamed_index]).value(_unknown(index))
        else:
            declared = self._solved(others).value(self._defined(blamed_index))
        return DimensionConflict(self._text(blamed.place),
                                 f"{blamed.text!r} is {_described(declared)}, but {blamed.parameter} is used "
                                 f"as {_described(self._solved(others).value(_unknown(index)))} "
                                 f"in {self._places(others)}")

    def _definition(self, involved: list[int], definition: int) -> DimensionConflict:
        """A definition that contradicts its parameter's unit or uses."""
        declaration = self.equations[definition][1]
        index = self.parameters[declaration.parameter]
        others = [i for i in involved if i != definition]
        value = _described(self._solved(others).value(self._defined(definition)))
        unit = next((i for i in others if self._is_unit(i, declaration.parameter)), None)
        if unit is None:
            used_as = _described(self._solved(others).value(_unknown(index)))
            return DimensionConflict(self._text(declaration.place),
                                     f"{declaration.text!r} is {value}, but {declaration.parameter} is used as "
                                     f"{used_as} in {self._places(others)}")
        stated = self.equations[unit][1]
        sources = [self.equations[i][1].parameter for i in others if i != unit and self._is_unit(i)]
        places = [i for i in others if isinstance(self.equations[i][1], Place)]
        reasons = ([f"the units of {', '.join(sorted(set(sources)))}"] if sources else []) \
            + ([self._places(places)] if places else [])
        source = f" (from {' and '.join(reasons)})" if reasons else ""
        return DimensionConflict(self._text(declaration.place),
                                 f"{declaration.text!r} is {value}{source}, but "
                                 f"{self._text(stated.place)} {stated.text!r} is "
                                 f"{_described(self._solved([unit]).value(_unknown(index)))}")

    def _is_unit(self, equation: int, parameter: str | None = None) -> bool:
        """Whether the equation is a unit (of ``parameter``)."""
        origin = self.equations[equation][1]
        return isinstance(origin, _Declaration) and origin.kind == "unit" and parameter in (None, origin.parameter)

    def _defined(self, definition: int) -> _Form:
        """The form of a definition's expression (its equation is ``parameter / expression``)."""
        parameter = self.parameters[self.equations[definition][1].parameter]
        return _unknown(parameter).times(self.equations[definition][0], -1)

    def _places(self, equations: list[int]) -> str:
        """The uses among ``equations``, the last entered (the failing one) first, at most three."""
        uses = list(dict.fromkeys(self._text(self.equations[i][1]) for i in reversed(equations)
                                  if isinstance(self.equations[i][1], Place)))
        return ", ".join(uses[:3]) + (f" and {len(uses) - 3} more" if len(uses) > 3 else "")

    def _solved(self, equations: list[int]) -> _Solver:
        """A solver of the given equations alone."""
        solver = _Solver()
        for i in equations:
            solver.add(self.equations[i][0], i)
        return solver


def _described(dimension: Dimension | None) -> str:
    return "something else" if dimension is None else dimension.describe()


# -- the uses of a system -------------------------------------------------------------------------

_LOAD_KINDS = {"springs": "spring", "dampers": "damper", "potentials": "potential", "forces": "force",
               "torques": "torque", "generalized_forces": "generalized force"}


def _uses(system: System):
    """``(place, expression, dimension or None)`` for every expression of the system."""
    for i, body in enumerate(system.bodies):
        yield from _body_uses(body, f"bodies[{i}]")
    bodies = {body.name: i for i, body in enumerate(system.bodies)}
    for name, point in system.points.items():
        entry = f"bodies[{bodies[point.body]}].points.{name}" if point.body in bodies else f"points.{name}"
        for k, value in enumerate(point.position):
            yield Place(f"{entry}[{k}]", f"point {name!r}"), value, LENGTH
    if system.gravity is not None:
        yield from ((Place(f"gravity[{k}]", f"gravity[{k}]"), value, _ACCELERATION)
                    for k, value in enumerate(system.gravity))
    joint_rows = {}
    for j, joint in enumerate(system.joints):
        joint_rows |= {row: Place(f"joints[{j}]", f"joint {joint.name!r} row {row!r}") for row in joint.constraint_names}
        yield from ((Place(f"joints[{j}].friction.{key}", f"joint {joint.name!r} friction {key}"), value,
                     Dimension(powers)) for key, value, powers in friction_uses(joint))
    for key in ("constraints", "nonholonomic_constraints"):
        index = 0
        for constraint in getattr(system, key):
            place = joint_rows.get(constraint.name)
            if place is None:
                place = Place(f"{key}[{index}].expression", f"{key[:-1].replace('_', ' ')} {constraint.name!r}")
                index += 1
            yield place, constraint.expression, None
    counts: dict[str, int] = {}
    for load in system.loads:
        table = load.file_table or type(load).__name__
        index = counts[table] = counts.get(table, -1) + 1
        kind = _LOAD_KINDS.get(table, type(load).__name__)
        yield from _load_uses(load, f"{table}[{index}]", f"{kind} {load.name!r}", system)
    for key, field in (("drawing", "points"), ("traces", "point")):
        for i, line in enumerate(getattr(system, key)):
            place = Place(f"{key}[{i}].{field}", f"{key} {line.name!r}")
            yield from ((place, value, LENGTH) for point in line.points for value in point)


def _body_uses(body: Body, entry: str):
    for field, value, _ in body.expressions():
        dimension = _BODY_FIELDS.get(field)
        if dimension is None:
            continue
        values = list(value) if isinstance(value, sp.MatrixBase) else [value]
        for k, item in enumerate(values):
            suffix = "" if len(values) == 1 else f"[{k}]" if len(values) <= 3 else f"[{k // 3}][{k % 3}]"
            yield Place(f"{entry}.{field}{suffix}", f"body {body.name!r} {field}{suffix}"), item, dimension


def _load_uses(load, entry: str, description: str, system: System):
    def place(field: str) -> Place:
        return Place(f"{entry}.{field}", description if field in ("force", "torque") else f"{description} {field}")

    if isinstance(load, Spring | Damper):
        yield from ((place(field), value, LENGTH) for field in ("point_a", "point_b") for value in getattr(load, field))
        if isinstance(load, Spring):
            yield place("stiffness"), load.stiffness, _ENERGY / LENGTH ** 2
            yield place("free_length"), load.free_length, LENGTH
        else:
            yield place("coefficient"), load.coefficient, _FORCE * TIME / LENGTH
    elif isinstance(load, PointForce):
        yield from ((place("point"), value, LENGTH) for value in load.point)
        yield from ((place("force"), value, _FORCE) for value in load.value)
    elif isinstance(load, BodyTorque):
        yield from ((place("torque"), value, _ENERGY) for value in load.value)
    elif isinstance(load, GeneralizedForce):
        yield from ((place("force"), value * q, _ENERGY) for q, value in zip(system.coordinates, load.value))
    else:
        yield Place(f"{entry}.expression", description), load.potential(), _ENERGY


# -- parameter values given as pint quantities ---------------------------------------------------

def _is_quantity(value) -> bool:
    return hasattr(value, "dimensionality") and hasattr(value, "to_base_units") and hasattr(value, "magnitude")


def si_parameter_values(system: System, values: Mapping) -> dict:
    """``values`` with every pint quantity converted to SI, after checking its dimension against the use.

    Numbers and callables are taken as given (SI).  A quantity ``Q_(300, "mm")`` becomes 0.3.

    Raises
    ------
    InputError
        A quantity is not a finite real scalar, its unit under- or overflows, or its dimension does not fit
        how the system uses the parameter (the message names the parameter and the use).
    """
    quantities = {key: value for key, value in values.items() if _is_quantity(value)}
    if not quantities:
        return dict(values)
    converted = dict(values)
    check = DimensionCheck(system, in_file=False)
    for key, quantity in quantities.items():
        name = key.name if isinstance(key, sp.Symbol) else str(key)
        try:
            one = (1 * quantity.units).to_base_units()
            check_si_factor(float(one.magnitude))
            magnitude = float(quantity.magnitude) * float(one.magnitude)
        except OverflowError:
            raise InputError(f"parameter {name}: {quantity:~} cannot be used: its unit's SI factor overflows") from None
        except (ValueError, TypeError) as error:
            raise InputError(f"parameter {name}: {quantity:~} cannot be used: {error}") from None
        if not math.isfinite(magnitude):
            raise InputError(f"parameter {name}: {quantity:~} is not a finite number in SI ({magnitude})")
        converted[key] = magnitude
        if name in check.parameters:
            place = Place(f"parameter {name}", f"parameter {name}")
            check.unit(name, Dimension(one.dimensionality), unit=f"{quantity:~}", place=place)
    check.system_uses()
    return converted
