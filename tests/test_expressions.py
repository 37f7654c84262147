"""The model-file expression reader: a whitelist over Python's syntax tree that
builds SymPy objects and never runs anything."""

from __future__ import annotations

import ast
import builtins
import math
import os

import pytest
import sympy as sp
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from kronlag import ModelError
from kronlag.core.errors import ExpressionError
from kronlag.model.expressions import FUNCTIONS, MAX_DEPTH, MAX_EXPONENT, MAX_LENGTH, MAX_NODES, parse_expression

x, y, l1 = sp.symbols("x y l1")
SYMBOLS = {"x": x, "y": y, "l1": l1}


def parse(text: str) -> sp.Expr:
    return parse_expression(text, SYMBOLS, what="test.toml: bodies[0].mass")


@pytest.mark.parametrize("text, expected", [
    ("l1*cos(x) + y/2", l1 * sp.cos(x) + y / 2),
    ("-x**2 + +y", -x ** 2 + y),
    ("(x + 1)*(x - 1)", (x + 1) * (x - 1)),
    ("atan2(y, x) + abs(x) + sqrt(l1) + exp(log(x))", sp.atan2(y, x) + sp.Abs(x) + sp.sqrt(l1) + x),
    ("sin(pi/2)", sp.Integer(1)),
    ("2.5e-3 * x", sp.Float(2.5e-3) * x),
    ("x**-2 + x**(1/2)", x ** -2 + sp.sqrt(x)),
    ("asin(x) + acos(x) + atan(x) + tan(x) + sinh(x) + cosh(x) + tanh(x)",
     sp.asin(x) + sp.acos(x) + sp.atan(x) + sp.tan(x) + sp.sinh(x) + sp.cosh(x) + sp.tanh(x)),
    ("  3  ", sp.Integer(3)),
])
def test_reads_the_whitelisted_syntax(text, expected):
    assert parse(text) == expected


@pytest.mark.parametrize("text, problem", [
    ("z + 1", "unknown symbol 'z'"),
    ("l2", "did you mean 'l1'?"),
    ("x.real", "attribute access is not allowed"),
    ("x[0]", "subscript is not allowed"),
    ("lambda: 1", "lambda is not allowed"),
    ("[v for v in x]", "comprehension is not allowed"),
    ("sin(x=1)", "keyword arguments are not allowed"),
    ("'text'", "a string is not allowed"),
    ("__import__('os').system('echo hacked')", "calling \"__import__('os').system\" is not allowed"),
    ("__import__('os')", "calling '__import__' is not allowed"),
    ("float('inf')", "calling 'float' is not allowed"),
    ("1e999", "not finite"),
    ("eval('1')", "calling 'eval' is not allowed"),
    ("x**1000", f"size at most {MAX_EXPONENT}"),
    ("9**9**9", f"size at most {MAX_EXPONENT}"),
    ("(2**64)**100", "more than 4096 bits"),
    ("x^2", "write '**'"),
    ("x // 2", "'//' is not supported"),
    ("x % 2", "'%' is not supported"),
    ("x < y", "comparison is not allowed"),
    ("x if y else 1", "conditional expression is not allowed"),
    ("x and y", "boolean operator is not allowed"),
    ("True", "the constant True is not allowed"),
    ("None", "the constant None is not allowed"),
    ("1j", "the constant 1j is not allowed"),
    ("(x := 1)", "assignment expression is not allowed"),
    ("f'{x}'", "f-string is not allowed"),
    ("sin", "used without calling it"),
    ("sin(x, y)", "sin takes 1 argument, got 2"),
    ("atan2(x)", "atan2 takes 2 arguments, got 1"),
    ("sin(*x)", "starred"),
    ("x / 0", "division by zero"),
    ("0**-1", "division by zero"),
    ("x = 1", "syntax error"),
    ("import os", "syntax error"),
    ("", "empty"),
    ("x\x00", "syntax error"),
    ("~x", "Invert is not allowed"),
    ("(x, y)", "tuple is not allowed"),
    ("{1: 2}", "dict is not allowed"),
])
def test_rejects_with_a_message_naming_text_and_construct(text, problem):
    with pytest.raises(ExpressionError) as caught:
        parse(text)
    message = str(caught.value)
    assert message.startswith("test.toml: bodies[0].mass: cannot read ") or "longer than" in message
    assert problem in message, message
    assert isinstance(caught.value, ModelError)


def test_size_limits():
    with pytest.raises(ExpressionError, match=f"longer than {MAX_LENGTH} characters"):
        parse("x+" * MAX_LENGTH + "x")
    with pytest.raises(ExpressionError, match=f"more than {MAX_NODES} syntax nodes"):
        parse("+".join(["x*y"] * (MAX_NODES // 2)))
    with pytest.raises(ExpressionError, match="nested|syntax error|unreadable"):
        parse("(" * 300 + "x" + ")" * 300)
    with pytest.raises(ExpressionError, match=f"nested more than {MAX_DEPTH} levels"):
        parse("-" * (MAX_DEPTH + 5) + "x")
    with pytest.raises(ExpressionError):
        parse("-" * (MAX_LENGTH - 1) + "x")
    assert parse("sin(" * 20 + "x" + ")" * 20).has(sp.sin)


def test_non_string_input():
    with pytest.raises(ExpressionError, match="expected an expression as a string, got int"):
        parse_expression(3, SYMBOLS)


# -- properties -----------------------------------------------------------------------

DANGEROUS = ["__import__('os').system('touch CANARY')", "kronlag_canary()", "open('CANARY', 'w')",
             "exec('kronlag_canary()')", "eval('kronlag_canary()')", "x.__class__", "().__class__",
             "globals()", "[kronlag_canary() for _ in x]", "(lambda: kronlag_canary())()"]

atoms = st.one_of(
    st.sampled_from(["x", "y", "l1", "pi", "z", "__builtins__", "sin", "kronlag_canary"]),
    st.integers(-1000, 1000).map(str),
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),
    st.sampled_from(["1e999", "'s'", "True", "None", "1j", "..."]),
    st.sampled_from(DANGEROUS),
)


def _compound(children):
    binary = st.tuples(children, st.sampled_from(["+", "-", "*", "/", "**", "^", "//", "%", "<", " and ", "@"]),
                       children).map(lambda t: f"({t[0]}{t[1]}{t[2]})")
    unary = st.tuples(st.sampled_from(["-", "+", "~", "not "]), children).map(lambda t: f"{t[0]}({t[1]})")
    call = st.tuples(st.sampled_from([*FUNCTIONS, "getattr", "__import__", "kronlag_canary", "float"]),
                     st.lists(children, max_size=3)).map(lambda t: f"{t[0]}({', '.join(t[1])})")
    other = st.tuples(children, st.sampled_from([".real", "[0]", "(x=1)", " if x else 1"])).map("".join)
    return st.one_of(binary, unary, call, other)


expression_texts = st.recursive(atoms, _compound, max_leaves=25)


@pytest.fixture
def canaries(tmp_path):
    """Calls of a builtin canary and of os.system (each also raises); no CANARY file may appear."""
    calls: list[str] = []

    def recorder(name):
        def record(*args, **kwargs):
            calls.append(name)
            raise AssertionError(f"{name} was called")
        return record

    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(tmp_path)
        patch.setattr(builtins, "kronlag_canary", recorder("canary"), raising=False)
        patch.setattr(os, "system", recorder("os.system"))
        yield calls
    assert not (tmp_path / "CANARY").exists()


def _check_outcome(text: str) -> None:
    """The text parses to an expression in the known symbols or raises ExpressionError,
    without calling eval or exec or compiling anything but a syntax tree."""
    compile_source = builtins.compile

    def forbidden(*args, **kwargs):
        raise AssertionError("the parser evaluated code")

    def tree_only(source, filename, mode, flags=0, *args, **kwargs):
        if not flags & ast.PyCF_ONLY_AST:
            raise AssertionError("the parser compiled code")
        return compile_source(source, filename, mode, flags, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(builtins, "eval", forbidden)
        patch.setattr(builtins, "exec", forbidden)
        patch.setattr(builtins, "compile", tree_only)
        try:
            result = parse(text)
        except ExpressionError:
            return
    assert isinstance(result, sp.Expr)
    assert result.free_symbols <= set(SYMBOLS.values())


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=expression_texts)
def test_random_syntax_trees_give_an_expression_or_expression_error(canaries, text):
    _check_outcome(text)
    assert canaries == []


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.lists(st.sampled_from([*"xyl1 ()+-*/.,[]'_=:^%<>{}!@#ij09e", "sin", "__", "**", "pi"]),
                     max_size=40).map("".join))
def test_random_strings_give_an_expression_or_expression_error(canaries, text):
    _check_outcome(text)
    assert canaries == []


def test_dangerous_texts_never_run(canaries):
    for text in DANGEROUS:
        with pytest.raises(ExpressionError):
            parse(text)
        _check_outcome(text)
    assert canaries == []


safe_atoms = st.one_of(st.sampled_from(["x", "y", "l1", "pi"]), st.integers(1, 9).map(str),
                       st.floats(0.1, 10, allow_nan=False).map(lambda v: repr(round(v, 3))))


def _safe_compound(children):
    binary = st.tuples(children, st.sampled_from(["+", "-", "*", "/"]), children).map(
        lambda t: f"({t[0]} {t[1]} {t[2]})")
    power = st.tuples(children, st.integers(-3, 3)).map(lambda t: f"({t[0]})**{t[1]}")
    call = st.tuples(st.sampled_from(["sin", "cos", "atan", "tanh", "abs", "exp"]), children).map(
        lambda t: f"{t[0]}({t[1]})")
    return st.one_of(binary, power, call, children.map(lambda c: f"-{c}"))


@settings(max_examples=200, deadline=None)
@given(text=st.recursive(safe_atoms, _safe_compound, max_leaves=12))
def test_values_match_python_arithmetic(text):
    point = {"x": 0.7, "y": -1.3, "l1": 2.1}
    namespace = {"__builtins__": {}, "pi": math.pi, "abs": abs,
                 **{name: getattr(math, name) for name in ("sin", "cos", "atan", "tanh", "exp")}, **point}
    try:
        expected = eval(text, namespace)  # the test's own generated arithmetic, as an oracle
    except (ZeroDivisionError, OverflowError, ValueError):
        assume(False)
    assume(isinstance(expected, float | int) and math.isfinite(expected) and abs(expected) < 1e12)
    try:
        result = parse(text)
    except ExpressionError as error:
        assert "division by zero" in str(error)
        return
    value = complex(result.evalf(30, subs={SYMBOLS[k]: v for k, v in point.items()}))
    assert value.imag == pytest.approx(0, abs=1e-9 * max(1, abs(expected)))
    assert value.real == pytest.approx(expected, rel=1e-9, abs=1e-9)
