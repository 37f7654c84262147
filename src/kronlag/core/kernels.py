"""The one route from symbolic expressions to numbers: kernels.

A *kernel* evaluates a few named matrices of SymPy expressions at given inputs
and writes their entries, row-major and one block after the other, into a flat
output.  The expressions are prepared once for every printer:
SymPy -> SymEngine (memoized, so that shared subexpressions are converted once;
numbers exact where a double holds them exactly, see :class:`ExpressionConverter`),
common-subexpression elimination with ``symengine.cse``, or in linear time for large kernels
(:func:`cse_kernel`, :func:`linear_cse`), inputs renamed to array entries such as ``q[i]``.

The printers only write the result out: :func:`python_source` (Python, run on
floats with :mod:`math` or on NumPy arrays for many states at once, or on
CasADi / JAX objects by :mod:`kronlag.symbolic.interop`) here, C in
:mod:`kronlag.numeric.codegen`.  :class:`ExpressionFunction` compiles named
matrices of any inputs into a Python function in one call; every layer that
needs numbers from expressions goes through it or through the numeric model's
kernels (:class:`kronlag.numeric.codegen.KernelSource`).
"""

from __future__ import annotations

import functools
import math
import operator
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import symengine as se
import sympy as sp

from .errors import InputError, ModelError

__all__ = [
    "Block",
    "Kernel",
    "ExpressionConverter",
    "cse_kernel",
    "linear_cse",
    "rebuilt",
    "LINEAR_CSE_OUTPUTS",
    "LINEAR_CSE_NODES",
    "literal",
    "python_source",
    "python_functions",
    "SCALAR_NAMESPACE",
    "ARRAY_NAMESPACE",
    "ExpressionFunction",
    "expression_kernel",
    "input_renames",
    "PLACEHOLDER",
]


@dataclass(frozen=True)
class Block:
    """One output matrix of a kernel: its name and shape (a vector has ``(n, 1)``)."""

    name: str
    shape: tuple[int, int]

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


@dataclass(frozen=True)
class Kernel:
    """A kernel after common-subexpression elimination, ready to print.

    ``temporaries`` are ``(symbol, expression)`` pairs in evaluation order;
    ``outputs`` are the entries of all ``blocks``, row-major, concatenated;
    ``constants`` maps the placeholder symbols ``K<i>`` standing for numbers
    that are not small exact integers or fractions to their double values
    (printed as correctly rounded floating-point literals, see :func:`literal`).
    ``large``: its subexpressions were eliminated by :func:`linear_cse` (the C backend keeps the
    temporaries of such kernels local to the function that uses them).
    """

    name: str
    blocks: tuple[Block, ...]
    temporaries: tuple[tuple[se.Symbol, se.Basic], ...]
    outputs: tuple[se.Basic, ...]
    constants: dict[str, float] = field(default_factory=dict)
    large: bool = False

    @property
    def size(self) -> int:
        return sum(block.size for block in self.blocks)

    def split(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        """The blocks of a flat output (``(size,)`` or ``(N, size)``) by name, each of its shape
        (with the leading N)."""
        values, start = {}, 0
        for block in self.blocks:
            values[block.name] = flat[..., start:start + block.size].reshape(flat.shape[:-1] + block.shape)
            start += block.size
        return values


#: Integers up to this size are exact doubles: they stay exact in SymEngine and print as C/Python
#: numbers that the compiler reads exactly.
_EXACT_LIMIT = 2**53
#: The numerators and denominators of fractions that stay exact: SymEngine's C printer writes a
#: fraction's parts with 15 significant digits (``1e+15/1024.0`` for ``(10**15 + 1)/1024``).
_EXACT_FRACTION_LIMIT = 10**15 - 1

#: The placeholder symbols ``K<i>`` of constants printed as literals (:attr:`Kernel.constants`).
PLACEHOLDER = re.compile(r"\bK\d+\b")


def literal(value: float) -> str:
    """``value`` as a floating-point literal read back exactly (shortest round trip), parenthesized if negative."""
    text = repr(float(value))
    return f"({text})" if value < 0 else text


#: Functions written as :class:`sympy.Piecewise` before conversion: their derivatives are then
#: piecewise too (SymEngine leaves those of ``Min``/``Max`` unevaluated) and one form reaches the
#: code.  ``Heaviside(x)`` takes SymPy's value at 0, ``1/2`` unless given (``Heaviside(x, 1)``).
PIECEWISE_FUNCTIONS = (sp.Min, sp.Max, sp.Heaviside)


def piecewise_form(expr: sp.Basic) -> sp.Basic:
    """``expr`` with every ``Min``, ``Max`` and ``Heaviside`` rewritten as a ``Piecewise``."""
    if not expr.has(*PIECEWISE_FUNCTIONS):
        return expr
    return expr.replace(lambda node: isinstance(node, PIECEWISE_FUNCTIONS), lambda node: node.rewrite(sp.Piecewise))


class ExpressionConverter:
    """SymPy -> SymEngine, memoized, with the inputs renamed (``renames``: e.g. ``q1`` -> ``q[0]``).

    Numbers: integers up to 2**53 and fractions whose parts have at most 15 digits stay
    exact (they print as ``3`` or ``1.0/3.0``, exact doubles divided once, so correctly
    rounded); floats become such fractions when they can.  Every other real
    number (``10**20``, ``2**64``, ``1e-300``, ``1/3`` of huge parts) becomes a
    placeholder symbol ``K<i>`` whose value, ``float(number)`` (correctly
    rounded), is kept in :attr:`constants` and printed as a literal: an integer
    literal never reaches C, where a large one would overflow.  Complex and
    non-finite numbers are a :class:`~kronlag.core.errors.ModelError`.
    """

    def __init__(self, renames: dict[sp.Symbol, se.Symbol]):
        self.memo: dict = dict(renames)
        self._by_name = {symbol.name: target for symbol, target in renames.items()}
        self._native_memo: dict = {}  # apart: a SymEngine symbol equals the SymPy one of its name
        self.constants: dict[str, float] = {}
        self._placeholders: dict[float, se.Symbol] = {}

    def __call__(self, expr: sp.Basic) -> se.Basic:
        result = self.memo.get(expr)
        if result is None:
            result = self._build(piecewise_form(expr))
            self.memo[expr] = result
        return result

    def _build(self, expr: sp.Basic) -> se.Basic:
        if isinstance(expr, sp.Piecewise):  # its arguments are (value, condition) pairs
            return se.Piecewise(*[(self(value), self(condition)) for value, condition in expr.args])
        if expr.is_Number or expr in (sp.I, sp.zoo):
            return self._number(expr)
        if isinstance(expr, sp.Symbol):
            raise InputError(f"symbol {expr} is not an input of the expressions (inputs: "
                             f"{', '.join(sorted(str(s) for s in self.memo if isinstance(s, sp.Symbol)))})")
        if not expr.args:
            return se.sympify(expr)
        args = [self(arg) for arg in expr.args]
        if expr.is_Add:
            return se.Add(*args)
        if expr.is_Mul:
            return se.Mul(*args)
        if expr.is_Pow:
            return se.Pow(*args)
        function = getattr(se, type(expr).__name__, None)
        if function is None:
            raise NotImplementedError(f"cannot generate code for {type(expr).__name__}: {expr}")
        return function(*args)

    def _number(self, number: sp.Basic) -> se.Basic:
        if number.is_extended_real is False or number is sp.zoo:
            raise ModelError(f"the complex constant {number} has no numeric value in real arithmetic")
        if not number.is_finite:
            raise ModelError(f"the non-finite constant {number} has no numeric value")
        if number.is_Float:
            value = float(number)
            if not math.isfinite(value):
                raise ModelError(f"the constant {number} overflows a double")
            number = sp.Rational(*value.as_integer_ratio())
        if max(abs(number.p), number.q) <= (_EXACT_LIMIT if number.q == 1 else _EXACT_FRACTION_LIMIT):
            return se.Rational(int(number.p), int(number.q))
        value = float(number)  # correctly rounded: SymPy divides Python integers
        if not math.isfinite(value):
            raise ModelError(f"the constant {number} overflows a double")
        symbol = self._placeholders.get(value)
        if symbol is None:
            symbol = self._placeholders[value] = se.Symbol(f"K{len(self._placeholders)}")
            self.constants[symbol.name] = value
        return symbol

    def native(self, expr: se.Basic) -> se.Basic:
        """The same conversion for an expression already in SymEngine whose symbols are named as
        the inputs (the derivation's own matrices: no round trip through SymPy); memoized."""
        result = self._native_memo.get(expr)
        if result is None:
            result = self._native_memo[expr] = self._build_native(expr)
        return result

    def _build_native(self, expr: se.Basic) -> se.Basic:
        if isinstance(expr, se.Symbol):
            target = self._by_name.get(expr.name)
            if target is None:
                raise InputError(f"symbol {expr} is not an input of the expressions (inputs: "
                                 f"{', '.join(sorted(self._by_name))})")
            return target
        if expr.is_Number:  # with infinities, NaN and complex numbers: as SymPy's (the same errors)
            return self(expr._sympy_())
        if not expr.args:
            return expr
        args = [self.native(arg) for arg in expr.args]
        if isinstance(expr, se.FunctionSymbol):
            raise NotImplementedError(f"cannot generate code for the undefined function {expr}")
        return rebuilt(expr, args)

    def native_matrix(self, matrix: se.DenseMatrix, name: str = "matrix") -> list[list[se.Basic]]:
        """The entries of the SymEngine ``matrix`` (called ``name`` in errors) converted by :meth:`native`."""
        return [[self._located(matrix[i, j], f"{name}[{i}, {j}]") for j in range(matrix.cols)]
                for i in range(matrix.rows)]

    def _located(self, expr: se.Basic, where: str) -> se.Basic:
        try:
            return self.native(expr)
        except ModelError as error:  # the entry as SymPy prints it, as :meth:`entry` names it
            raise ModelError(f"{where} = {sp.sympify(expr)}: {error}") from None

    def matrix(self, matrix: sp.MatrixBase, name: str = "matrix") -> list[list[se.Basic]]:
        """The entries of ``matrix`` (called ``name`` in errors) converted."""
        return [[self.entry(matrix[i, j], f"{name}[{i}, {j}]") for j in range(matrix.cols)]
                for i in range(matrix.rows)]

    def entry(self, expr: sp.Basic, where: str) -> se.Basic:
        """``expr`` converted; a :class:`ModelError` names ``where`` it stands."""
        try:
            return self(expr)
        except ModelError as error:
            raise ModelError(f"{where} = {expr}: {error}") from None


def _maximum(*values):
    return functools.reduce(np.maximum, values)


def _minimum(*values):
    return functools.reduce(np.minimum, values)


def _piecewise(*pairs):
    """``Piecewise((value, condition), ...)`` on floats: the value of the first true condition."""
    return next(value for value, condition in pairs if condition)


def _piecewise_arrays(*pairs):
    """``Piecewise((value, condition), ...)`` on arrays, element by element."""
    values = [np.asarray(value, dtype=float) for value, _ in pairs]
    conditions = [np.asarray(condition, dtype=bool) for _, condition in pairs]
    shape = np.broadcast_shapes(*(array.shape for array in values + conditions))
    return np.select([np.broadcast_to(c, shape) for c in conditions], [np.broadcast_to(v, shape) for v in values],
                     np.nan)


#: The generated Python source runs in one of two namespaces: :mod:`math` on floats (one
#: state: fastest in pure Python), or NumPy on arrays (many states at once, vectorised).
_FUNCTION_NAMES = ("sin", "cos", "tan", "sinh", "cosh", "tanh", "exp", "log", "sqrt", "floor", "pi", "e")
SCALAR_NAMESPACE: dict[str, object] = {name: getattr(math, name) for name in _FUNCTION_NAMES}
SCALAR_NAMESPACE.update({name: getattr(math, name) for name in ("asin", "acos", "atan", "atan2", "asinh",
                                                                 "acosh", "atanh")},
                         E=math.e, ceiling=math.ceil, abs=abs, max=max, min=min,
                         sign=lambda x: math.copysign(1.0, x) if x else 0.0, Piecewise=_piecewise,
                         And=lambda *conditions: all(conditions), Or=lambda *conditions: any(conditions))
ARRAY_NAMESPACE: dict[str, object] = {name: getattr(np, name) for name in _FUNCTION_NAMES}
ARRAY_NAMESPACE.update(asin=np.arcsin, acos=np.arccos, atan=np.arctan, atan2=np.arctan2, asinh=np.arcsinh,
                        acosh=np.arccosh, atanh=np.arctanh, E=np.e, ceiling=np.ceil, abs=np.abs,
                        max=_maximum, min=_minimum, sign=np.sign, Piecewise=_piecewise_arrays,
                        And=lambda *conditions: functools.reduce(np.logical_and, conditions),
                        Or=lambda *conditions: functools.reduce(np.logical_or, conditions))


def python_source(kernel: Kernel, arguments: Sequence[str] = ("t", "q", "qd", "p")) -> str:
    """Python source of ``kernel_<name>(*arguments) -> list`` (the flat output): with the default
    arguments ``q[i]``, ``qd[i]``, ``p[i]`` and ``t`` may be floats (one state) or equally shaped
    arrays (many states, :data:`ARRAY_NAMESPACE`)."""
    def code(expr: se.Basic) -> str:
        return PLACEHOLDER.sub(lambda match: literal(kernel.constants[match.group(0)]), str(expr))

    lines = [f"def kernel_{kernel.name}({', '.join(arguments)}):"]
    lines += [f"    {symbol} = {code(expr)}" for symbol, expr in kernel.temporaries]
    lines.append("    return [" + ", ".join(code(expr) for expr in kernel.outputs) + "]")
    return "\n".join(lines) + "\n"


#: Kernels with more outputs than this get :func:`linear_cse` instead of ``symengine.cse``, whose
#: search for common subsets of sums' and products' arguments grows much faster than the expressions:
#: closed_chain(100, "absolute") (10 306 outputs, mostly M) 22-65 s, about like n^4.5, against 3-7 s,
#: but its forward dynamics about 16 % slower (its code shares no parts of products).  Above every
#: model with a forward-dynamics target (chains up to n = 80: 6 646 outputs; the robots of
#: example-robot-data, Talos 1 602), so that their code stays that of ``symengine.cse``.
LINEAR_CSE_OUTPUTS = 8000
#: Kernels whose expressions have more distinct subexpressions than this get :func:`linear_cse` too,
#: however few their outputs: ``symengine.cse``'s time grows with the size of the expression graph
#: (Cassie's ``h``, 29 outputs of 52 000 subexpressions: 92 s of CPU against 2.9 s; its whole
#: ``"dynamics"`` kernel, 90 000).  Above Talos's ``"dynamics"`` kernel (39 500, 12 s against 1.9 s;
#: the floating quadrupeds 7 500-8 400), so that the robots with a build target keep their code.
LINEAR_CSE_NODES = 60_000


def _more_nodes_than(exprs: Sequence[se.Basic], limit: int) -> bool:
    """Whether ``exprs`` have more than ``limit`` distinct subexpressions (counted up to ``limit``)."""
    seen: set[se.Basic] = set()
    stack = list(exprs)
    while stack:
        node = stack.pop()
        if node not in seen:
            seen.add(node)
            if len(seen) > limit:
                return True
            stack.extend(node.args)
    return False


def rebuilt(expr: se.Basic, args: Sequence[se.Basic]) -> se.Basic:
    """``expr`` of the same kind with ``args``."""
    if isinstance(expr, se.Add):
        return se.Add(*args)
    if isinstance(expr, se.Mul):
        return se.Mul(*args)
    if isinstance(expr, se.Pow):
        return se.Pow(*args)
    if isinstance(expr, se.Piecewise):  # SymEngine flattens the (value, condition) pairs
        return se.Piecewise(*zip(args[::2], args[1::2]))
    # SymEngine's relationals and boolean functions (a Piecewise's conditions) have no .func
    return (getattr(expr, "func", None) or type(expr))(*args)


def _operands(node: se.Basic, args: tuple[se.Basic, ...]) -> tuple[tuple[se.Basic, ...], bool]:
    """The operands :func:`linear_cse` sees in ``node`` (of arguments ``args``), and whether they are
    not its own arguments: a product ``c*a*b*...`` with a number ``c`` is ``c`` times the product
    ``a*b*...``, which is then shared with the same product elsewhere (``(1/2)*m*l*s`` beside ``m*l*s``)."""
    if isinstance(node, se.Mul) and len(args) > 2:
        numbers = [arg for arg in args if arg.is_Number]
        if len(numbers) == 1:
            return (numbers[0], se.Mul(*(arg for arg in args if not arg.is_Number))), True
    return args, False


def linear_cse(exprs: Sequence[se.Basic]) -> tuple[list[tuple[se.Symbol, se.Basic]], list[se.Basic]]:
    """Common-subexpression elimination in time linear in the distinct subexpressions of ``exprs``.

    Every composite subexpression used more than once (by distinct parents, or as several of
    ``exprs``) becomes one temporary ``x<k>``, the product of a numeric factor's other factors too
    (:func:`_operands`); no common subsets of arguments are searched for (``symengine.cse`` does:
    its code is faster, its time superlinear, see :data:`LINEAR_CSE_OUTPUTS`).  Returns
    ``(temporaries, outputs)`` as ``symengine.cse``: ``(symbol, expression)`` pairs in evaluation
    order (each uses only earlier ones) and ``exprs`` in terms of them.
    """
    # ``.args`` builds new Python objects each time: read once per distinct node, atoms (no
    # arguments) remembered with 0 uses
    uses: dict[se.Basic, int] = {}
    operands: dict[se.Basic, tuple[tuple[se.Basic, ...], bool]] = {}
    stack = list(exprs)
    while stack:
        node = stack.pop()
        seen = uses.get(node)
        if seen is not None:
            if seen:
                uses[node] = seen + 1
            continue
        args = node.args
        uses[node] = 1 if args else 0
        if args:
            operands[node] = _operands(node, args)
            stack.extend(operands[node][0])
    replaced: dict[se.Basic, se.Basic] = {}
    temporaries: list[tuple[se.Symbol, se.Basic]] = []
    for root in exprs:
        pending = [(root, False)]
        while pending:  # depth first, each node after its operands
            node, ready = pending.pop()
            if node in replaced or node not in operands:  # done, or an atom
                continue
            children, factored = operands[node]
            if not ready:
                pending.append((node, True))
                pending.extend((child, False) for child in children if child in operands and child not in replaced)
                continue
            args = [replaced.get(child, child) for child in children]
            if factored:
                value = se.Mul(*args)
            elif not any(map(operator.is_not, args, children)):  # in C: no generator frames
                value = node
            else:
                value = rebuilt(node, args)
            if uses[node] > 1:
                symbol = se.Symbol(f"x{len(temporaries)}")
                temporaries.append((symbol, value))
                value = symbol
            replaced[node] = value
    return temporaries, [replaced.get(expr, expr) for expr in exprs]


def cse_kernel(name: str, blocks: Sequence[Block], matrices: Sequence[list[list[se.Basic]]],
               constants: Mapping[str, float]) -> Kernel:
    """The :class:`Kernel` ``name`` of the converted ``matrices`` (one per block), with common
    subexpressions eliminated over all of them: ``symengine.cse``, or :func:`linear_cse` above
    :data:`LINEAR_CSE_OUTPUTS` outputs or :data:`LINEAR_CSE_NODES` distinct subexpressions."""
    flat = [entry for rows in matrices for row in rows for entry in row]
    large = len(flat) > LINEAR_CSE_OUTPUTS or _more_nodes_than(flat, LINEAR_CSE_NODES)
    eliminate = linear_cse if large else se.cse
    temporaries, outputs = eliminate(flat) if flat else ([], [])
    return Kernel(name, tuple(blocks), tuple(temporaries), tuple(outputs), dict(constants), large)


def python_functions(source: str, names: Sequence[str], namespace: Mapping[str, object]) -> dict[str, Callable]:
    """Run ``source`` (of :func:`python_source`: our own generated text, never user text) in
    ``namespace`` and return its functions ``kernel_<name>`` by ``name``.

    Raises
    ------
    NotImplementedError
        The source calls a function that ``namespace`` does not define.
    """
    code = compile(source, "<kronlag generated>", "exec")
    unknown = sorted({called for const in code.co_consts if hasattr(const, "co_names")
                      for called in const.co_names} - set(namespace))
    if unknown:
        raise NotImplementedError(f"no numeric implementation of the function(s) {', '.join(unknown)}")
    scope = dict(namespace, __builtins__={})
    exec(code, scope)  # our own generated source, never user text
    return {name: scope[f"kernel_{name}"] for name in names}


def input_renames(inputs: Sequence[tuple[str, object]]) -> dict[sp.Symbol, se.Symbol]:
    """The names the symbols of ``inputs`` take in generated code: a scalar argument's symbol its
    argument's name (``t``), the symbols of a vector argument ``argument[i]`` (``q[0]``, ``q[1]``, ...)."""
    renames: dict[sp.Symbol, se.Symbol] = {}
    for argument, symbols in inputs:
        if isinstance(symbols, sp.Symbol):
            renames[symbols] = se.Symbol(argument)
        else:
            renames.update({symbol: se.Symbol(f"{argument}[{i}]") for i, symbol in enumerate(symbols)})
    return renames


def expression_kernel(matrices: Mapping[str, sp.MatrixBase], inputs: Sequence[tuple[str, object]], *,
                      name: str = "expressions") -> Kernel:
    """The :class:`Kernel` ``name`` of the named ``matrices``, whose inputs are ``inputs``: pairs of an
    argument name and either one symbol (a scalar argument, e.g. the time) or a sequence of symbols
    (a vector argument, read as ``argument[i]``).  Print it with
    ``python_source(kernel, [argument for argument, _ in inputs])``."""
    converter = ExpressionConverter(input_renames(inputs))
    blocks = tuple(Block(key, sp.Matrix(matrix).shape) for key, matrix in matrices.items())
    converted = [converter.matrix(sp.Matrix(matrix), key) for key, matrix in matrices.items()]
    return cse_kernel(name, blocks, converted, converter.constants)


class ExpressionFunction:
    """Named matrices of SymPy expressions compiled into one Python function of named inputs.

    Parameters
    ----------
    matrices : mapping of str to SymPy matrix
        What to evaluate, by name.
    inputs : sequence of (str, sequence of sympy.Symbol)
        The arguments in order, each a name and the symbols whose values it carries (a vector;
        see :func:`expression_kernel`).
    name : str
        An identifier naming the kernel in errors.

    Examples
    --------
    >>> x, y = sp.symbols("x y")
    >>> evaluate = ExpressionFunction({"r": sp.Matrix([x * y, x + y])}, [("v", (x, y))])
    >>> evaluate([2.0, 3.0])["r"].tolist()
    [[6.0], [5.0]]
    """

    def __init__(self, matrices: Mapping[str, sp.MatrixBase], inputs: Sequence[tuple[str, Sequence[sp.Symbol]]],
                 *, name: str = "expressions"):
        self.kernel = expression_kernel(matrices, inputs, name=name)
        source = python_source(self.kernel, [argument for argument, _ in inputs])
        self._scalar = python_functions(source, [name], SCALAR_NAMESPACE)[name]
        self._array = python_functions(source, [name], ARRAY_NAMESPACE)[name]

    def __call__(self, *values) -> dict[str, np.ndarray]:
        """The matrices at one point (``values``: one float vector per input), each of its shape."""
        flat = np.array(self._scalar(*(np.asarray(value, dtype=float).tolist() for value in values)), dtype=float)
        return self.kernel.split(flat)

    def batch(self, *values) -> dict[str, np.ndarray]:
        """The matrices at N points (``values``: one (N, k) array per input), each (N, *shape)."""
        arrays = [np.asarray(value, dtype=float) for value in values]
        n = len(arrays[0])
        rows = self._array(*(array.T for array in arrays))
        flat = np.empty((n, self.kernel.size))
        for column, row in enumerate(rows):
            flat[:, column] = row
        return self.kernel.split(flat)
