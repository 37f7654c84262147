"""Everything that can go wrong in kronlag, as one hierarchy of exceptions and warnings.

::

    KronlagError
    ├── InputError (ValueError)          a value given to kronlag is invalid; the message names it
    │   └── ModelError                   a model description is invalid (which body, constraint, ...)
    │       ├── ModelFileError           ... in a model file: "FILE: ENTRY: problem"
    │       └── ExpressionError          ... an expression text that is not admissible
    ├── NumericalError (RuntimeError)    a computation could not be completed; ``residual``
    │   ├── SingularConfigurationError   M is not positive definite on the null space of [Phi_q; A]
    │   ├── AssemblyError                no consistent state near a guess
    │   ├── ProjectionError              the projection onto the constraints did not converge
    │   └── EquilibriumError             no static equilibrium near a guess
    └── CompilerError (RuntimeError)     compiled code cannot be built or loaded

Input errors are also :class:`ValueError` and the others :class:`RuntimeError`, so code written
against the built-in classes keeps working; the command line maps the classes to exit codes
(:mod:`kronlag.app.cli`).  The warnings say that a result holds with a qualification.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "KronlagError",
    "InputError",
    "ModelError",
    "ModelFileError",
    "ExpressionError",
    "NumericalError",
    "SingularConfigurationError",
    "AssemblyError",
    "ProjectionError",
    "EquilibriumError",
    "CompilerError",
    "KronlagWarning",
    "RedundantConstraintsWarning",
    "ActuationWarning",
    "InitialStateWarning",
    "DrivesNotAppliedWarning",
    "CacheWarning",
    "CompilerWarning",
]


class KronlagError(Exception):
    """The root of kronlag's exceptions."""


class InputError(KronlagError, ValueError):
    """A value given to kronlag is invalid; the message names the offending item."""


class ModelError(InputError):
    """A model description is invalid; the message names the offending item."""


class ModelFileError(ModelError):
    """A model file is invalid; the message names the file, the entry and the problem."""


class ExpressionError(ModelError):
    """A text is not an admissible expression; the message names the text and the construct."""


class NumericalError(KronlagError, RuntimeError):
    """A numerical method could not complete; ``residual`` says how far it got (None where no residual applies)."""

    def __init__(self, message: str, residual: float | None = None):
        self.residual = residual
        super().__init__(message)


class SingularConfigurationError(NumericalError):
    """M is not positive definite on the null space of ``[Phi_q; A]`` at ``(q, qd, t)``."""

    def __init__(self, q: np.ndarray, qd: np.ndarray, t: float):
        self.q, self.qd, self.t = np.array(q, dtype=float), np.array(qd, dtype=float), float(t)
        super().__init__(f"singular configuration at t = {self.t!r}, q = {self.q.tolist()}, "
                         f"qd = {self.qd.tolist()}: M is not positive definite on the null space "
                         "of the constraint Jacobian [Phi_q; A], the accelerations are not determined")


class AssemblyError(NumericalError):
    """No consistent state was found near the guess; ``residual`` says how far."""


class ProjectionError(NumericalError):
    """The projection onto the constraint manifold did not converge; ``residual`` is ``max |Phi|``."""


class EquilibriumError(NumericalError):
    """No static equilibrium was found near the guess; ``residual`` says how far."""


class CompilerError(KronlagError, RuntimeError):
    """Compiled code cannot be built or loaded: the C compiler is missing or failed on the generated code
    (the message has its output), or a library the compiled integrators need is missing."""


class KronlagWarning(UserWarning):
    """The root of kronlag's warnings."""


class RedundantConstraintsWarning(KronlagWarning):
    """The constraint Jacobian ``[Phi_q; A]`` is rank deficient: the multipliers are not unique."""


class ActuationWarning(KronlagWarning):
    """More actuators than degrees of freedom: the actuator forces are not unique (minimum-norm split)."""


class InitialStateWarning(KronlagWarning):
    """The initial state violated the constraints and was projected onto them."""


class DrivesNotAppliedWarning(KronlagWarning):
    """A model file's ``[[drives]]`` were read but not added to its system (``ModelFile.driven()`` does)."""


class CacheWarning(KronlagWarning):
    """The cache directory of compiled code cannot be used (not the user's alone, not writable, or a
    library there does not carry its key): a private temporary directory is used instead."""


class CompilerWarning(KronlagWarning):
    """How kronlag chose its C compiler, reported once per process where it matters: a compiler found
    does not work (``$CC=/bin/false``: the line says why), ``zig cc`` of the ``ziglang`` package is used
    because no other is found or works, or there is none at all (the ``"auto"`` backend is then the
    Python one)."""
