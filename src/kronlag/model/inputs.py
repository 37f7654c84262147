"""User input turned into SymPy scalars, vectors and matrices, with a :class:`ModelError` naming the item."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import sympy as sp

from ..core.errors import ModelError

__all__ = ["as_scalar", "as_matrix", "as_vector", "as_components"]


def as_scalar(value, what: str) -> sp.Expr:
    if isinstance(value, str):
        raise ModelError(f"{what}: got the string {value!r}; give a SymPy expression or a number "
                         "(model files are read by kronlag.modelfile, which parses strings safely)")
    try:
        expr = sp.sympify(value, strict=True)
    except (sp.SympifyError, TypeError) as error:
        raise ModelError(f"{what}: expected a SymPy expression or a number, got {type(value).__name__}") from error
    if isinstance(expr, sp.MatrixBase) or not isinstance(expr, sp.Expr):
        raise ModelError(f"{what}: expected a scalar expression, got {type(expr).__name__}")
    return expr


def as_matrix(value, shape: tuple[int, int], what: str) -> sp.ImmutableMatrix:
    """Convert to an immutable matrix of the given shape; a vector may be any 1-d sequence."""
    try:
        if shape[1] == 1 and not isinstance(value, sp.MatrixBase):
            rows = [[entry] for entry in value]
        else:
            rows = value
        matrix = sp.Matrix(rows) if not isinstance(rows, sp.MatrixBase) else rows
    except (TypeError, ValueError, sp.SympifyError) as error:
        raise ModelError(f"{what}: expected shape {shape}, could not read {value!r}") from error
    if shape[1] == 1 and matrix.shape == (1, shape[0]):
        matrix = matrix.T
    if matrix.shape != shape:
        raise ModelError(f"{what}: expected shape {shape}, got shape {matrix.shape}")
    return sp.ImmutableMatrix([[as_scalar(matrix[i, j], f"{what}[{i},{j}]") for j in range(shape[1])]
                               for i in range(shape[0])])


def as_vector(value, what: str, lengths: Sequence[int]) -> sp.ImmutableMatrix:
    if isinstance(value, str) or not isinstance(value, Iterable | sp.MatrixBase):
        raise ModelError(f"{what}: expected a vector of length {' or '.join(map(str, lengths))}, "
                         f"got {type(value).__name__}")
    entries = list(value) if not isinstance(value, sp.MatrixBase) else list(value)
    if isinstance(value, sp.MatrixBase) and 1 not in value.shape:
        raise ModelError(f"{what}: expected a vector, got a matrix of shape {value.shape}")
    if len(entries) not in lengths:
        raise ModelError(f"{what}: expected a vector of length {' or '.join(map(str, lengths))}, "
                         f"got length {len(entries)}")
    return as_matrix(entries, (len(entries), 1), what)


def as_components(value, what: str, length: int) -> sp.Matrix:
    """A column of ``length`` scalars (coordinates of a point or a direction); ModelError naming ``what``
    and the count otherwise."""
    try:
        entries = list(value)
    except TypeError as error:
        raise ModelError(f"{what}: expected {length} entries, got {type(value).__name__}") from error
    if len(entries) != length:
        raise ModelError(f"{what}: expected {length} entries, got {len(entries)}")
    return sp.Matrix([as_scalar(entry, f"{what}[{i}]") for i, entry in enumerate(entries)])
