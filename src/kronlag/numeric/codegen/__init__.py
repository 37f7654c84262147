"""Code generation for the numeric model: SymPy matrices -> NumPy or C kernels.

Every kernel evaluates a few matrices of an :class:`~kronlag.equations.Equations`
object at a state ``(t, q, qd, p)`` (``p``: the parameters in the order of
``Equations.parameters``) and writes their entries, row-major and one block
after the other, into a flat output.  The expressions are prepared once, for
both backends (:class:`KernelSource`): SymPy -> SymEngine (memoized, so shared
subexpressions are converted once), common-subexpression elimination with
``symengine.cse``, inputs renamed to ``t``, ``q[i]``, ``qd[i]``, ``p[i]``.
The two backends only print the result:

* ``"python"`` (:class:`PythonLibrary`): Python functions (our own generated
  source, compiled with :func:`compile`) run on floats with :mod:`math` for one
  state, on NumPy arrays for a batch of states; no compiler needed;
* ``"c"`` (:class:`CLibrary`): C compiled with the machine's C compiler
  (the solver at ``-O3``, the kernels at ``-O2``, long ones at ``-O1``; see
  :func:`compile_shared_library`) into a shared library, cached on disk under ``$KRONLAG_CACHE`` or
  ``~/.cache/kronlag`` (a private directory; keyed by a hash of the source and
  the flags, content hash checked before loading, the key the library exports checked after
  loading), loaded with :mod:`ctypes`
  and called through the fixed call layer ``kronlag.numeric.codegen._call`` built at install
  time (ctypes when it is missing).  Large kernels are split into functions of
  about :data:`C_CHUNK` characters (compilers are superlinear in the size of a
  function) and the source is compiled in parallel parts.

Both implement :class:`KernelLibrary`; :data:`BACKENDS` maps the backend names
to them.  Numbers reach the code as exact small integers and fractions or as
correctly rounded floating-point literals (see :class:`_SymengineConverter`).

The ``"dynamics"`` kernel holds everything forward dynamics needs, with one
common-subexpression elimination over all of it::

    M (m, m),  h = f_Q - C qd - g (m,),  Phi (r,),  Phi_q (r, m),  Phi_t (r,),
    gamma (r,),  A (s, m),  b (s,),  gamma_nh (s,)

with ``gamma = -(dPhi_q/dt) qd - 2 Phi_qt qd - Phi_tt`` and
``gamma_nh = -(dA/dt) qd - db/dt``, the time derivatives taken by Theorem 1
(``dX/dt = dX/dq (I ⊗ qd) + dX/dt|_q``, written as the sparse sum
``sum_k dX/dq_k qd_k``; the partials in ``t`` are nonzero for drives only).
The C library of the dynamics kernel also contains the solver of the augmented
system (``kronlag_forward_dynamics``, ``numeric/codegen/c/augmented.c``).
"""

from ...core.errors import CompilerError
from ...core.kernels import Block, Kernel, literal, python_source
from .build import (C_LARGE_SOURCE, KEY_FUNCTION, CCompiler, c_compiler, cache_directory,
                    compile_shared_library, library_parts, load_shared_library)
from .c_backend import FAST_CALL, CLibrary, batch_threads, c_file, c_kernel, solver_header
from .layouts import LAYOUTS, dynamics_shape, layout, layout_macros
from .python_backend import KernelLibrary, PythonLibrary
from .source import KernelSource

__all__ = [
    "Block",
    "Kernel",
    "KernelSource",
    "KernelLibrary",
    "PythonLibrary",
    "CLibrary",
    "BACKENDS",
    "FAST_CALL",
    "LAYOUTS",
    "layout",
    "layout_macros",
    "dynamics_shape",
    "solver_header",
    "c_file",
    "c_kernel",
    "c_compiler",
    "CCompiler",
    "cache_directory",
    "compile_shared_library",
    "load_shared_library",
    "library_parts",
    "KEY_FUNCTION",
    "batch_threads",
    "literal",
    "python_source",
    "C_LARGE_SOURCE",
    "CompilerError",
]

#: The backends :class:`~kronlag.numeric.NumericModel` can use, by the name users pass.
BACKENDS: dict[str, type] = {"c": CLibrary, "python": PythonLibrary}
