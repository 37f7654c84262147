"""Writing derived equations out: standalone code in other languages, and reports.

:func:`export_code` turns :class:`~kronlag.Equations` into self-contained
functions in C, Fortran, Octave/MATLAB, Julia or Python, printed with SymPy's
code printers after common-subexpression elimination.  Every generated function
has the same arguments ``(t, q, qd, p)`` -- time, coordinates, speeds and
parameters, in the orders listed in the file's header comment -- and returns
(or, in C and Fortran, writes to ``out``) one matrix: ``M``, ``C``, ``g``, ``Phi``,
``Phi_q``, ``Phi_t``, ``gamma``, ``A``, ``b`` and ``f_Q`` (:data:`EXPORTED`, from the
catalogue :mod:`kronlag.symbolic.matrices`, which gives their shapes and meanings).

:func:`format_equations` writes the equations as text, LaTeX, Markdown or JSON.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import sympy as sp

from ..core.errors import InputError
from . import matrices as catalogue
from .equations import MATRIX_NAMES, Equations

__all__ = ["LANGUAGES", "FORMATS", "export_code", "exported_matrices", "format_equations", "file_stem"]

#: Functions every export defines, in order.
EXPORTED = catalogue.EXPORTED
_TEMPORARY = "w"


@dataclass(frozen=True)
class _Language:
    """How one language indexes, prints and wraps a function."""

    comment: str
    origin: int  # index of the first array element
    element: Callable[[str, str], str]  # (array, index text) -> element text
    assign: Callable[[str, sp.Expr], str]  # (lhs, rhs) -> statement
    define: Callable[[_Function, int, int], str]  # (function, m, number of parameters) -> text
    prologue: str
    note: str = ""  # how results are returned, for the header
    declare: str = ""  # written before the name of a temporary
    flat: bool = False  # out is a flat row-major array
    exact_pi: bool = True  # False: print pi as a number


@dataclass(frozen=True)
class _Function:
    """One generated function: its name, result shape and body statements."""

    name: str
    rows: int
    cols: int
    vector: bool
    body: list[str]

    def shape(self, vector_shape: str, matrix_shape: str) -> str:
        """The result shape written with ``{rows}`` / ``{cols}`` templates."""
        return (vector_shape if self.vector else matrix_shape).format(rows=self.rows, cols=self.cols)


def _c_function(function: _Function, m: int, n_p: int) -> str:
    lines = [f"void {function.name}(double t, const double *q, const double *qd, const double *p, double *out)",
             "{", "    (void)t; (void)q; (void)qd; (void)p;",
             f"    for (int k = 0; k < {function.rows * function.cols}; ++k) out[k] = 0.0;"]
    return "\n".join(lines + [f"    {line}" for line in function.body] + ["}"])


def _fortran_function(function: _Function, m: int, n_p: int) -> str:
    temporaries = sorted({match for line in function.body for match in re.findall(rf"\b{_TEMPORARY}\d+\b", line)},
                         key=lambda text: int(text[len(_TEMPORARY):]))
    lines = [f"subroutine {function.name}(t, q, qd, p, out)", "    implicit none",
             "    real(8), intent(in) :: t", f"    real(8), intent(in) :: q({m}), qd({m}), p({n_p})",
             f"    real(8), intent(out) :: out({function.shape('{rows}', '{rows}, {cols}')})"]
    lines += [f"    real(8) :: {temporary}" for temporary in temporaries]
    lines += ["    out = 0.0d0"]
    return "\n".join(lines + [f"    {line}" for line in function.body] + [f"end subroutine {function.name}"])


def _octave_function(function: _Function, m: int, n_p: int) -> str:
    lines = [f"function out = {function.name}(t, q, qd, p)", f"  out = zeros({function.rows}, {function.cols});"]
    return "\n".join(lines + [f"  {line}" for line in function.body] + ["end"])


def _julia_function(function: _Function, m: int, n_p: int) -> str:
    lines = [f"function {function.name}(t, q, qd, p)", f"    out = zeros({function.shape('{rows}', '{rows}, {cols}')})"]
    return "\n".join(lines + [f"    {line}" for line in function.body] + ["    return out", "end"])


def _python_function(function: _Function, m: int, n_p: int) -> str:
    lines = [f"def {function.name}(t, q, qd, p):",
             f"    out = numpy.zeros({function.shape('{rows}', '({rows}, {cols})')})"]
    return "\n".join(lines + [f"    {line}" for line in function.body] + ["    return out"])


def _fortran_assign(lhs: str, rhs: sp.Expr) -> str:
    return sp.fcode(rhs, assign_to=sp.Symbol(lhs), source_format="free", standard=95)


def _assignment(printer: Callable[[sp.Expr], str], end: str = "") -> Callable[[str, sp.Expr], str]:
    """``lhs = <printed rhs><end>``."""
    return lambda lhs, rhs: f"{lhs} = {printer(rhs)}{end}"


def _brackets(array: str, index: str) -> str:
    return f"{array}[{index}]"


def _parentheses(array: str, index: str) -> str:
    return f"{array}({index})"


_LANGUAGE_TABLE: dict[str, _Language] = {
    "c": _Language("//", 0, _brackets, _assignment(lambda e: sp.ccode(e, standard="c99"), ";"), _c_function,
                   "#include <math.h>", note="Each writes its matrix to out in row-major order (out[i*cols + j]).",
                   declare="const double ", flat=True, exact_pi=False),
    "fortran": _Language("!", 1, _parentheses, _fortran_assign, _fortran_function, "",
                         note="Each is a subroutine writing its matrix to the last argument, out.",
                         exact_pi=False),
    "octave": _Language("%", 1, _parentheses, _assignment(sp.octave_code, ";"), _octave_function,
                        "1;  % a script file defining several functions"),
    "julia": _Language("#", 1, _brackets, _assignment(sp.julia_code), _julia_function, ""),
    "python": _Language("#", 0, _brackets, _assignment(lambda e: sp.pycode(e, fully_qualified_modules=True)),
                        _python_function, "import math\n\nimport numpy"),
}

#: Languages :func:`export_code` writes.
LANGUAGES = tuple(_LANGUAGE_TABLE)


def exported_matrices(eom: Equations) -> dict[str, sp.ImmutableMatrix]:
    """The matrices :func:`export_code` writes, by function name; ``Phi_t = dPhi/dt`` (drives),
    ``gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt``."""
    return {name: getattr(eom, name) for name in EXPORTED}


def _parameter_order(eom: Equations, parameters) -> tuple[list[sp.Symbol], dict[sp.Symbol, sp.Expr]]:
    """``(symbols in p, fixed values)`` from the ``parameters`` option of :func:`export_code`."""
    by_name = {symbol.name: symbol for symbol in eom.parameters}

    def symbol(key) -> sp.Symbol:
        name = key.name if isinstance(key, sp.Symbol) else key
        if name not in by_name:
            raise InputError(f"{key!r} is not a parameter of the model; parameters are {', '.join(by_name)}")
        return by_name[name]

    if parameters is None:
        return list(eom.parameters), {}
    if isinstance(parameters, Mapping):
        fixed = {symbol(key): sp.Float(value) for key, value in parameters.items()}
        return [p for p in eom.parameters if p not in fixed], fixed
    if isinstance(parameters, str) or not isinstance(parameters, Sequence):
        raise TypeError("parameters must be a sequence of names (the order of p) or a mapping of values")
    order = [symbol(key) for key in parameters]
    missing = [p.name for p in eom.parameters if p not in order]
    if missing or len(set(order)) != len(order):
        raise InputError(f"parameters must list every parameter once; missing: {', '.join(missing) or 'none'}")
    return order, {}


def _identifier(name: str) -> str:
    """``name`` as an identifier valid in every language: ASCII letters, digits and ``_``, a letter first."""
    cleaned = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return cleaned if re.match(r"[A-Za-z]", cleaned) else f"model_{cleaned}"


#: Characters of user text (model and symbol names) kept in comments; every other one becomes ``?``:
#: no line break of any kind (it would end the comment), no backslash (it continues a C ``//`` comment).
_COMMENT_UNSAFE = re.compile(r"[^A-Za-z0-9_ .,:;=+\-*/()\[\]'<>]")


def _comment_text(text: str) -> str:
    """User ``text`` safe inside a one-line comment of any exported language."""
    return _COMMENT_UNSAFE.sub("?", text)


def file_stem(name: str) -> str:
    """A file name made from the model name ``name`` that stays in the directory it is written to.

    ASCII letters, digits, ``-``, ``_`` and ``.`` are kept, every other character
    (path separators included) becomes ``_``, and leading dots are dropped, so
    that ``Path(file_stem(name) + suffix)`` is a plain file in the working directory.
    """
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name).lstrip(".") or "model"


def export_code(eom: Equations, lang: str, *, parameters: Sequence | Mapping | None = None) -> str:
    """Standalone source code evaluating the equations' matrices.

    Parameters
    ----------
    eom : Equations
    lang : {'c', 'fortran', 'octave', 'julia', 'python'}
    parameters : sequence or mapping, optional
        A sequence of parameter names or symbols sets the order of the
        parameter vector ``p`` (default: the model's declaration order); a
        mapping of names to numbers builds those values into the code and
        leaves the other parameters in ``p``.

    Returns
    -------
    str
        A header comment listing the arguments ``t, q, qd, p`` element by
        element, then one function per matrix named ``<model>_<matrix>`` (see
        the module docstring).  C functions write ``out`` in row-major order;
        Fortran subroutines take ``out`` shaped like the matrix.
    """
    if lang not in _LANGUAGE_TABLE:
        raise InputError(f"unknown language {lang!r}; choose from {', '.join(LANGUAGES)}")
    language = _LANGUAGE_TABLE[lang]
    order, fixed = _parameter_order(eom, parameters)
    m = len(eom.coordinates)
    names: dict[sp.Symbol, sp.Symbol] = {}
    for array, symbols in (("q", eom.coordinates), ("qd", eom.speeds), ("p", order)):
        for k, symbol in enumerate(symbols):
            names[symbol] = sp.Symbol(language.element(array, str(k + language.origin)))
    if not language.exact_pi:
        names[sp.pi] = sp.Float(sp.pi, 17)
    prefix = _identifier(eom.system.name)
    functions = []
    for name, matrix in exported_matrices(eom).items():
        matrix = matrix.xreplace(fixed)
        function = _Function(f"{prefix}_{name}", matrix.rows, matrix.cols, name in catalogue.VECTORS,
                             _function_body(language, matrix, name in catalogue.VECTORS, names))
        functions.append(language.define(function, m, len(order)))
    header = _header(eom, language, prefix, order, fixed)
    parts = [header, language.prologue] if language.prologue else [header]
    return "\n\n".join(parts + functions) + "\n"


def _function_body(language: _Language, matrix: sp.MatrixBase, vector: bool, names: dict) -> list[str]:
    entries = [(i, j, matrix[i, j]) for i in range(matrix.rows) for j in range(matrix.cols) if matrix[i, j] != 0]
    temporaries, reduced = sp.cse([entry for _, _, entry in entries],
                                  symbols=sp.numbered_symbols(_TEMPORARY), optimizations="basic")
    lines = []

    def statement(lhs: str, rhs: sp.Expr) -> None:
        lines.append(language.assign(lhs, rhs.xreplace(names)))

    for temporary, value in temporaries:
        statement(language.declare + temporary.name, value)
    for (i, j, _), value in zip(entries, reduced):
        if language.flat:
            index = str(i * matrix.cols + j)
        elif vector:
            index = str(i + language.origin)
        else:
            index = f"{i + language.origin}, {j + language.origin}"
        statement(language.element("out", index), value)
    return lines


def _header(eom: Equations, language: _Language, prefix: str, order: list[sp.Symbol], fixed: dict) -> str:
    m, r, s = eom.shape
    origin = language.origin

    def listing(array: str, symbols) -> str:
        return ", ".join(f"{language.element(array, str(k + origin))} = {_comment_text(symbol.name)}"
                         for k, symbol in enumerate(symbols)) or "(empty)"

    lines = [
        f"Equations of motion of '{_comment_text(eom.system.name)}', generated by kronlag "
        "(Van Khang 2011, Eq. 23):",
        "    M(q) qdd + C(q, qd) qd + Phi_q^T lambda + A^T mu + g(q) = f_Q",
        "    Phi(q) = 0,  Phi_q qdd = gamma,  A(q) qd + b(q) = 0",
        f"m = {m} coordinates, r = {r} holonomic and s = {s} nonholonomic constraints.",
        "Every function takes (t, q, qd, p):",
        "  t  time",
        f"  q  {listing('q', eom.coordinates)}",
        f"  qd {listing('qd', eom.speeds)}",
        f"  p  {listing('p', order)}",
    ]
    if fixed:
        lines.append("Built-in parameter values: " + ", ".join(f"{_comment_text(k.name)} = {v}"
                                                               for k, v in fixed.items()))
    lines.append("Functions: " + ", ".join(f"{prefix}_{name} {catalogue.shape(name, m, r, s)}" for name in EXPORTED))
    if language.note:
        lines.append(language.note)
    return "\n".join(f"{language.comment} {line}".rstrip() for line in lines)


# -- reports -------------------------------------------------------------------------

#: Formats :func:`format_equations` writes.
FORMATS = ("text", "latex", "markdown", "json")


def format_equations(eom: Equations, fmt: str = "text") -> str:
    """The matrices of ``eom`` and Eq. 23 as ``"text"``, ``"latex"``, ``"markdown"`` or ``"json"``.

    Empty matrices (no constraints of a kind) are left out except in JSON.
    """
    if fmt not in FORMATS:
        raise InputError(f"unknown format {fmt!r}; choose from {', '.join(FORMATS)}")
    present = [name for name in MATRIX_NAMES if getattr(eom, name).rows]
    if fmt == "json":
        return json.dumps({
            "model": eom.system.name,
            "coordinates": [q.name for q in eom.coordinates],
            "speeds": [qd.name for qd in eom.speeds],
            "parameters": [p.name for p in eom.parameters],
            "shape": dict(zip("mrs", eom.shape)),
            "matrices": {name: [[sp.sstr(entry) for entry in getattr(eom, name).row(i)]
                                for i in range(getattr(eom, name).rows)] for name in MATRIX_NAMES},
            "equations": [sp.sstr(row) + " = 0" for row in eom.residual],
        }, indent=2)
    if fmt == "text":
        equations = "\n".join(f"  {sp.sstr(row)} = 0" for row in eom.residual)
        return f"{eom}\n\nEq. 23 (each row = 0):\n{equations}\n"
    if fmt == "latex":
        blocks = [f"% {name}\n{name} = {eom.latex(name)}" for name in present]
        return "\n\n".join(blocks + [f"% Eq. 23\n{eom.latex()}"]) + "\n"
    blocks = [f"# {_comment_text(eom.system.name)}", f"m = {eom.shape[0]}, r = {eom.shape[1]}, s = {eom.shape[2]}"]
    blocks += [f"## {name}\n\n$$\n{eom.latex(name)}\n$$" for name in present]
    blocks.append(f"## Eq. 23\n\n$$\n{eom.latex()}\n$$")
    return "\n\n".join(blocks) + "\n"
