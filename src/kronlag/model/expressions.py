"""A safe reader for the expressions written in model files.

Model files hold formulas as text (``"l1*cos(q1) + l2/2"``).  They are read
here by walking Python's ``ast`` against a whitelist and building SymPy
objects directly; nothing is ever evaluated, ``sympify``'d or imported, so a
file cannot run code.  What is admitted:

* numbers (integers and finite decimals),
* the declared symbol names passed in, and the constant ``pi`` (written exactly: Python
  folds identifiers to their NFKC form, so a fullwidth ``ｍ1`` would silently mean ``m1``;
  such a name is refused),
* ``+ - * / **``, unary ``-`` and ``+``, parentheses,
* calls of :data:`FUNCTIONS` with positional arguments.

Everything else (attribute access, subscripts, strings, keyword arguments,
lambdas, comprehensions, comparisons, calls of other names, ...) raises
:class:`ExpressionError`, which names the text and the offending construct.
Sizes are capped (:data:`MAX_LENGTH`, :data:`MAX_NODES`, :data:`MAX_DEPTH`; a flat
sum ``a + b + ... + z`` or product counts as one level, however many terms it has) and
numeric powers are limited (:data:`MAX_EXPONENT`, :data:`MAX_POWER_BITS`) so
that no text can make the reader run for long or exhaust memory.
"""

from __future__ import annotations

import ast
import difflib
import math
from collections.abc import Mapping

import sympy as sp

from ..core.errors import ExpressionError

__all__ = [
    "ExpressionError",
    "parse_expression",
    "FUNCTIONS",
    "CONSTANTS",
    "RESERVED_NAMES",
    "MAX_LENGTH",
    "MAX_NODES",
    "MAX_DEPTH",
    "MAX_EXPONENT",
    "MAX_POWER_BITS",
]

#: Functions an expression may call, with their number of arguments.
FUNCTIONS: dict[str, tuple[type[sp.Function] | type[sp.Basic], int]] = {
    "sin": (sp.sin, 1), "cos": (sp.cos, 1), "tan": (sp.tan, 1),
    "asin": (sp.asin, 1), "acos": (sp.acos, 1), "atan": (sp.atan, 1), "atan2": (sp.atan2, 2),
    "sinh": (sp.sinh, 1), "cosh": (sp.cosh, 1), "tanh": (sp.tanh, 1),
    "sqrt": (sp.sqrt, 1), "exp": (sp.exp, 1), "log": (sp.log, 1), "abs": (sp.Abs, 1),
    "min": (sp.Min, 2), "max": (sp.Max, 2), "heaviside": (sp.Heaviside, 1),  # heaviside(0) = 1/2
}

#: Named constants.
CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi}

#: Names that cannot be used for symbols.
RESERVED_NAMES: frozenset[str] = frozenset(FUNCTIONS) | frozenset(CONSTANTS)

#: Longest accepted text, in characters.
MAX_LENGTH = 5000
#: Most syntax-tree nodes in one expression.
MAX_NODES = 2000
#: Deepest nesting of the syntax tree.
MAX_DEPTH = 60
#: Largest ``|exponent|`` of a power whose exponent is a number.
MAX_EXPONENT = 100
#: Largest size, in bits, of a number computed by a power of two numbers.
MAX_POWER_BITS = 4096

_BINARY = {ast.Add: sp.Add, ast.Sub: None, ast.Mult: sp.Mul, ast.Div: None, ast.Pow: None}
#: Operators read as one flat chain: a sum of terms or a product of factors.
_CHAINS = {ast.Add: "sum", ast.Sub: "sum", ast.Mult: "product", ast.Div: "product"}
_OPERATOR_HINTS = {
    ast.BitXor: "'^' is not a power; write '**'",
    ast.FloorDiv: "'//' is not supported; write '/'",
    ast.Mod: "'%' is not supported",
    ast.MatMult: "'@' is not supported",
}
_CONSTRUCT_NAMES = {
    ast.Attribute: "attribute access", ast.Subscript: "subscript", ast.Lambda: "lambda",
    ast.ListComp: "comprehension", ast.SetComp: "comprehension", ast.DictComp: "comprehension",
    ast.GeneratorExp: "comprehension", ast.Compare: "comparison", ast.BoolOp: "boolean operator",
    ast.IfExp: "conditional expression", ast.List: "list", ast.Tuple: "tuple", ast.Dict: "dict",
    ast.Set: "set", ast.Starred: "starred expression", ast.NamedExpr: "assignment expression",
    ast.JoinedStr: "f-string", ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield",
    ast.Slice: "slice",
}


class _Reader:
    """Converts one parsed expression to SymPy, rejecting anything off the whitelist."""

    def __init__(self, text: str, symbols: Mapping[str, sp.Symbol], what: str):
        self.text = text
        self.symbols = symbols
        self.what = what

    def fail(self, problem: str, node: ast.AST | None = None) -> ExpressionError:
        where = ""
        if node is not None and hasattr(node, "col_offset"):
            segment = ast.get_source_segment(self.text, node)
            where = f" (at column {node.col_offset + 1}" + (f": {segment!r})" if segment else ")")
        return ExpressionError(f"{self.what}: cannot read {self.text!r}: {problem}{where}")

    def convert(self, node: ast.AST, depth: int = 0) -> sp.Expr:
        if depth > MAX_DEPTH:
            raise self.fail(f"nested more than {MAX_DEPTH} levels deep")
        if isinstance(node, ast.Constant):
            return self.constant(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp):
            return self.unary(node, depth)
        if isinstance(node, ast.BinOp):
            return self.binary(node, depth)
        if isinstance(node, ast.Call):
            return self.call(node, depth)
        construct = _CONSTRUCT_NAMES.get(type(node), f"'{type(node).__name__}' syntax")
        raise self.fail(f"{construct} is not allowed", node)

    def constant(self, node: ast.Constant) -> sp.Expr:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, int | float):
            kind = "a string" if isinstance(value, str) else f"the constant {value!r}"
            raise self.fail(f"{kind} is not allowed (only numbers are)", node)
        if isinstance(value, int):
            return sp.Integer(value)
        if not math.isfinite(value):
            raise self.fail("the number is not finite", node)
        return sp.Float(value)

    def name(self, node: ast.Name) -> sp.Expr:
        written = ast.get_source_segment(self.text, node)
        if written is not None and written != node.id:
            raise self.fail(f"the name {written!r} is not plain text: Python reads it as {node.id!r} "
                            f"(its NFKC form); write {node.id!r}", node)
        if node.id in self.symbols:
            return self.symbols[node.id]
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        if node.id in FUNCTIONS:
            raise self.fail(f"the function {node.id!r} is used without calling it", node)
        close = difflib.get_close_matches(node.id, list(self.symbols) + list(CONSTANTS), n=1, cutoff=0.5)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise self.fail(f"unknown symbol {node.id!r} (declare it as a coordinate or parameter){hint}", node)

    def unary(self, node: ast.UnaryOp, depth: int) -> sp.Expr:
        operand = self.convert(node.operand, depth + 1)
        if isinstance(node.op, ast.USub):
            return -operand
        if isinstance(node.op, ast.UAdd):
            return operand
        raise self.fail(f"the operator {type(node.op).__name__} is not allowed", node)

    def binary(self, node: ast.BinOp, depth: int) -> sp.Expr:
        if type(node.op) not in _BINARY:
            hint = _OPERATOR_HINTS.get(type(node.op), f"the operator {type(node.op).__name__} is not allowed")
            raise self.fail(hint, node)
        group = _CHAINS.get(type(node.op))
        if group is None:
            return self.power(self.convert(node.left, depth + 1), self.convert(node.right, depth + 1), node)
        # A chain a + b - c + ... (or a * b / c ...) parses as a left-nested tree; it is read
        # as one level without recursion, so that a flat sum of many terms is not "deep".
        links = []
        while isinstance(node, ast.BinOp) and _CHAINS.get(type(node.op)) is group:
            links.append(node)
            node = node.left
        operands = [self.convert(node, depth + 1)]
        for link in reversed(links):
            right = self.convert(link.right, depth + 1)
            if isinstance(link.op, ast.Sub):
                right = -right
            elif isinstance(link.op, ast.Div):
                if right.is_zero:
                    raise self.fail("division by zero", link)
                right = 1 / right
            operands.append(right)
        return sp.Add(*operands) if group == "sum" else sp.Mul(*operands)

    def power(self, base: sp.Expr, exponent: sp.Expr, node: ast.BinOp) -> sp.Expr:
        if exponent.is_number:
            if not exponent.is_real or abs(exponent) > MAX_EXPONENT:
                raise self.fail(f"the exponent {exponent} is not a real number of size at most {MAX_EXPONENT}",
                                node)
            if base.is_zero and exponent.is_negative:
                raise self.fail("division by zero (0 to a negative power)", node)
            if base.is_Rational and exponent.is_Integer:
                size = max(abs(int(base.p)), int(base.q)).bit_length() * abs(int(exponent))
                if size > MAX_POWER_BITS:
                    raise self.fail(f"the power is a number of more than {MAX_POWER_BITS} bits", node)
        return base ** exponent

    def call(self, node: ast.Call, depth: int) -> sp.Expr:
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            callee = ast.get_source_segment(self.text, node.func) or type(node.func).__name__
            raise self.fail(f"calling {callee!r} is not allowed; the functions are " + ", ".join(FUNCTIONS), node)
        function, arity = FUNCTIONS[node.func.id]
        if node.keywords:
            raise self.fail(f"keyword arguments are not allowed in a call of {node.func.id!r}", node)
        if any(isinstance(argument, ast.Starred) for argument in node.args):
            raise self.fail("starred arguments are not allowed", node)
        if len(node.args) != arity:
            raise self.fail(f"{node.func.id} takes {arity} argument{'s' if arity > 1 else ''}, "
                            f"got {len(node.args)}", node)
        return function(*(self.convert(argument, depth + 1) for argument in node.args))


def parse_expression(text: str, symbols: Mapping[str, sp.Symbol], *, what: str = "expression") -> sp.Expr:
    """Read an expression written in the model-file syntax.

    Parameters
    ----------
    text : str
        The expression, e.g. ``"l1*cos(q1) + l2/2"``.
    symbols : mapping of str to sympy.Symbol
        The names the expression may use.
    what : str
        How error messages refer to the expression (e.g. a file and entry).

    Returns
    -------
    sympy.Expr

    Raises
    ------
    ExpressionError
        The text is not an admissible expression; the message names ``what``,
        the text and the offending construct.
    """
    reader = _Reader(text, symbols, what)
    if not isinstance(text, str):
        raise ExpressionError(f"{what}: expected an expression as a string, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"{what}: the expression is longer than {MAX_LENGTH} characters")
    if not text.strip():
        raise reader.fail("the expression is empty")
    if "\x00" in text:  # Python 3.11.2 raises ValueError for it, later 3.11 releases SyntaxError: say it alike
        raise reader.fail("syntax error (source code string cannot contain null bytes)")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as error:
        raise reader.fail(f"syntax error ({error.msg})") from None
    except (ValueError, RecursionError, MemoryError) as error:
        raise reader.fail(f"unreadable ({type(error).__name__})") from None
    reader.text = text.strip()
    if sum(1 for _ in ast.walk(tree)) > MAX_NODES:
        raise reader.fail(f"more than {MAX_NODES} syntax nodes")
    try:
        result = reader.convert(tree.body)
    except RecursionError:
        raise reader.fail("too deeply nested") from None
    if result.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        raise reader.fail("the expression is not finite")
    return result
