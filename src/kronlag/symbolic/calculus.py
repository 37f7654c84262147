"""Matrix calculus of Van Khang (2011), Section 2.

The derivative of a matrix function with respect to a vector (Definition 1),
the Kronecker product, the time derivative of a matrix (Theorem 1) and the
product rule (Theorem 2).  These are the literal formulas of the paper [1]_ on
SymPy matrices; :func:`kronlag.derive` uses sparse equivalents of them in its
hot path and the tests check that both agree.

References
----------
.. [1] N. Van Khang, "Kronecker product and a new matrix form of Lagrangian equations with
   multipliers for constrained multibody systems", Mechanics Research Communications 38 (2011)
   294-299, https://doi.org/10.1016/j.mechrescom.2011.04.004
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp

from ..core.errors import InputError

__all__ = ["matrix_derivative", "kron", "time_derivative", "product_derivative"]


def _as_matrix(value, name: str) -> sp.Matrix:
    try:
        matrix = sp.Matrix(value)
    except (TypeError, ValueError) as error:
        raise TypeError(f"{name} must be a matrix or a vector, got {type(value).__name__}") from error
    return matrix


def _as_vector(value, name: str) -> sp.Matrix:
    vector = _as_matrix(value, name)
    if vector.cols != 1 and vector.rows != 1:
        raise InputError(f"{name} must be a vector, got shape {vector.shape}")
    return vector.reshape(len(vector), 1)


def matrix_derivative(A, x: Sequence[sp.Expr] | sp.Matrix) -> sp.Matrix:
    """Partial derivative of a matrix with respect to a vector (Definition 1).

    Every entry ``a_ij`` of ``A`` (shape ``a x b``) is replaced by its row
    gradient ``[da_ij/dx_1 ... da_ij/dx_k]``.

    Parameters
    ----------
    A : matrix, shape (a, b)
    x : vector of symbols, length k

    Returns
    -------
    sympy.Matrix, shape (a, b*k)
        Entry ``(i, j*k + l)`` is ``dA_ij/dx_l`` (0-based indices).
    """
    A = _as_matrix(A, "A")
    x = _as_vector(x, "x")
    k = len(x)
    result = sp.zeros(A.rows, A.cols * k)
    for i in range(A.rows):
        for j in range(A.cols):
            entry = A[i, j]
            for l, variable in enumerate(x):
                result[i, j * k + l] = sp.diff(entry, variable)
    return result


def kron(A, B) -> sp.Matrix:
    """Kronecker product ``A ⊗ B = [a_ij B]``.

    Parameters
    ----------
    A : matrix, shape (m, p)
    B : matrix, shape (q, s)

    Returns
    -------
    sympy.Matrix, shape (m*q, p*s)
    """
    A = _as_matrix(A, "A")
    B = _as_matrix(B, "B")
    result = sp.zeros(A.rows * B.rows, A.cols * B.cols)
    for i in range(A.rows):
        for j in range(A.cols):
            if A[i, j] != 0:
                result[i * B.rows:(i + 1) * B.rows, j * B.cols:(j + 1) * B.cols] = A[i, j] * B
    return result


def time_derivative(A, x, xd) -> sp.Matrix:
    """Time derivative of ``A(x(t))`` by Theorem 1: ``dA/dt = dA/dx (I_b ⊗ xd)``.

    ``I_b`` is the identity of the column size ``b`` of ``A`` (the paper
    prints ``I_n``, which is conformable only when ``b`` equals ``len(x)``).

    Parameters
    ----------
    A : matrix, shape (a, b)
    x : vector of symbols, length k
    xd : vector, length k
        The time derivatives of ``x`` (plain symbols or expressions).

    Returns
    -------
    sympy.Matrix, shape (a, b)
    """
    A = _as_matrix(A, "A")
    x = _as_vector(x, "x")
    xd = _as_vector(xd, "xd")
    if len(xd) != len(x):
        raise InputError(f"xd must have the length of x ({len(x)}), got {len(xd)}")
    return matrix_derivative(A, x) * kron(sp.eye(A.cols), xd)


def product_derivative(A, B, x) -> sp.Matrix:
    """Derivative of a product by Theorem 2: ``d(AB)/dx = dA/dx (B ⊗ I_k) + A dB/dx``.

    Parameters
    ----------
    A : matrix, shape (a, p)
    B : matrix, shape (p, s)
    x : vector of symbols, length k

    Returns
    -------
    sympy.Matrix, shape (a, s*k)
    """
    A = _as_matrix(A, "A")
    B = _as_matrix(B, "B")
    x = _as_vector(x, "x")
    if A.cols != B.rows:
        raise InputError(f"A and B are not conformable: A is {A.shape}, B is {B.shape}")
    return matrix_derivative(A, x) * kron(B, sp.eye(len(x))) + A * matrix_derivative(B, x)
