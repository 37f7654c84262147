"""The layout of the kernels the C solvers and integrators read: one table, :data:`LAYOUTS`, from
which Python (:func:`layout`, :func:`split_terms`) and C (:func:`layout_macros`) both take their offsets."""

from __future__ import annotations

import functools
import math

import numpy as np

from ...core.kernels import Kernel
from ...symbolic import matrices

__all__ = ["LAYOUTS", "layout", "layout_macros", "split_terms", "dynamics_shape"]

#: The blocks of the kernels read by the C solvers and integrators, in output order (their shapes
#: are those of the catalogue, :mod:`kronlag.symbolic.matrices`).  Both the Python side
#: (:func:`layout`, ``NumericModel.dynamics_terms``) and the C side (offset macros
#: ``KRONLAG_<KERNEL>_<BLOCK>``, :func:`layout_macros`) derive their offsets from this table.
#:
#: ``"dynamics"``: ``h = f_Q - C qd - g``, ``Phi_t = dPhi/dt`` (drives), ``gamma = -d(Phi_q qd + Phi_t)/dt``
#: and ``gamma_nh = -d(A qd + b)/dt`` at fixed qd, so that ``[Phi_q; A] qdd = [gamma; gamma_nh]``.
#: ``"tangent"``: the derivatives of the dynamic residual
#: ``e = M a + C qd + g - f_Q + Phi_q^T nu + A^T mu`` at given accelerations ``a`` and
#: multipliers ``nu``, ``mu`` (inputs appended to ``p``): ``K = de/dq`` (stiffness, including
#: the multiplier term ``d(Phi_q^T nu)/dq``) and ``D = de/dqd`` (damping and gyroscopic terms).
LAYOUTS: dict[str, tuple[str, ...]] = {
    "dynamics": ("M", "h", "Phi", "Phi_q", "Phi_t", "gamma", "A", "b", "gamma_nh"),
    "tangent": ("K", "D"),
}


@functools.cache
def layout(kernel: str, m: int, r: int, s: int) -> tuple[tuple[str, int, tuple[int, ...]], ...]:
    """``(block, offset, shape)`` of every block of ``kernel`` (see :data:`LAYOUTS`); vectors have
    shape ``(n,)``, matrices ``(rows, columns)``."""
    result, offset = [], 0
    for name in LAYOUTS[kernel]:
        shape = matrices.shape(name, m, r, s)
        result.append((name, offset, shape))
        offset += math.prod(shape)
    return tuple(result)


def layout_macros(kernel: str, m: int, r: int, s: int) -> str:
    """``#define KRONLAG_<KERNEL>_<BLOCK> offset`` for every block and ``KRONLAG_<KERNEL>_SIZE``."""
    blocks = layout(kernel, m, r, s)
    prefix = f"KRONLAG_{kernel.upper()}"
    lines = [f"#define {prefix}_{name.upper()} {offset}" for name, offset, _ in blocks]
    name, offset, shape = blocks[-1]
    lines.append(f"#define {prefix}_SIZE {offset + math.prod(shape)}")
    return "\n".join(lines) + "\n"


def split_terms(shape: tuple[int, int, int], flat: np.ndarray) -> dict[str, np.ndarray]:
    """The blocks of the ``"dynamics"`` kernel's output by name (``M``, ``h``, ``Phi``, ...), as views.

    ``shape`` is ``(m, r, s)``; ``flat`` is (size,) for one state or (N, size) for N states (the
    blocks then have a leading N).
    """
    lead = flat.shape[:-1]
    return {name: flat[..., offset:offset + math.prod(block)].reshape(lead + block)
            for name, offset, block in layout("dynamics", *shape)}


def dynamics_shape(kernel: Kernel) -> tuple[int, int, int]:
    """``(m, r, s)`` from the blocks of the ``"dynamics"`` kernel."""
    rows = {block.name: block.shape[0] for block in kernel.blocks}
    return rows["M"], rows["Phi"], rows["A"]
