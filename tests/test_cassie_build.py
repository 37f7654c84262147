"""Building Cassie in seconds (issue 21, item 6): the rotation Jacobian of a robot file's long rotation
sequence, and a kernel of a large expression graph gets ``linear_cse`` whatever its number of outputs
(``symengine.cse`` took 92 s on Cassie's 29 entries of ``h``), with local C temporaries."""

import re

import numpy as np
import pytest
import symengine as se
import sympy as sp

import kronlag
from kronlag import codegen, models
from kronlag.core import kernels
from kronlag.model.rotations import EULER_PARAMETERS, RotationSequence
from kronlag.symbolic import derivation


def general_sequence() -> tuple[RotationSequence, list[sp.Symbol]]:
    """Euler parameters, then a joint about a general axis (floats, as a robot file's), a principal
    axis with a negated angle and constant turns: the factors the readers make."""
    e = sp.symbols("e0:4")
    a, b = sp.symbols("a b")
    axis = np.array([0.0012, -0.9975, 0.0706])
    axis /= np.linalg.norm(axis)
    moved = sp.Matrix(3, 3, [0.36, 0.48, -0.8, -0.8, 0.6, 0, 0.48, 0.64, 0.6]) * sp.Matrix(e[1:])
    factors = [(EULER_PARAMETERS, (e[0], *moved)), ("z", sp.pi / 2), (tuple(map(float, axis)), a),
               ("y", -b), ("x", sp.Float(1.5708)), ("z", sp.Float(-0.18949))]
    return RotationSequence(factors), [*e, a, b]


def test_rotation_jacobian_of_a_sequence_is_the_angular_velocity_of_its_matrix():
    """On the unit sphere ``J_R qd`` is the body-frame angular velocity ``vee(R^T Rd)`` of the SymPy matrix
    (``Rd`` by central differences)."""
    sequence, symbols = general_sequence()
    body = kronlag.RigidBody("b", mass=1, inertia=sp.eye(3), position=[0, 0, 0], rotation=sequence)
    q = [se.Symbol(s.name) for s in symbols]
    jacobian = derivation._rotation_jacobian(body, q)
    rng = np.random.default_rng(4)
    e = rng.normal(size=4)
    e /= np.linalg.norm(e)
    point = dict(zip(symbols, [*e, 0.7, -0.4]))
    speeds = rng.normal(size=len(symbols))
    speeds[:4] -= (speeds[:4] @ e) * e  # tangent to the sphere
    matrix = sp.lambdify(symbols, body.rotation)
    values, step = np.array(list(point.values())), 1e-6
    rate = (matrix(*(values + step * speeds)) - matrix(*(values - step * speeds))) / (2 * step)
    spin = matrix(*values).T @ rate
    omega = np.array([float(x) for x in jacobian.subs({se.Symbol(s.name): v for s, v in point.items()})])
    omega = omega.reshape(3, len(symbols)) @ speeds
    np.testing.assert_allclose(omega, [spin[2, 1], spin[0, 2], spin[1, 0]], atol=1e-8)  # central differences


def test_a_kernel_of_a_large_expression_graph_gets_linear_cse_and_local_temporaries(monkeypatch):
    """Above ``LINEAR_CSE_NODES`` distinct subexpressions (here lowered to a small chain's) the kernel is
    ``linear_cse``'s, marked ``large``, and its C keeps temporaries local; below, ``symengine.cse``'s (a
    chain in absolute angles: its kernels are the flat ones, not the recursive kernels of a declared tree)."""
    source = codegen.KernelSource(kronlag.derive(models.closed_chain(4, "absolute")))
    assert not source.kernel("dynamics").large
    monkeypatch.setattr(kernels, "LINEAR_CSE_NODES", 50)
    kernel = source.kernel("dynamics")
    assert kernel.large and len(kernel.outputs) < kernels.LINEAR_CSE_OUTPUTS
    assert re.search(r"const double x\d+ = ", codegen.c_kernel(kernel, 1)[0])


def test_a_model_built_with_linear_cse_by_its_graph_size_has_the_same_accelerations(monkeypatch):
    eom = kronlag.derive(models.closed_chain(4, "absolute"))
    values = {p.name: 1.0 for p in eom.parameters}
    values.update(xg=2.4, yg=0.0)
    reference = eom.numeric(values, backend="python")  # the C of such kernels: tests/test_build_locals.py
    monkeypatch.setattr(kernels, "LINEAR_CSE_NODES", 50)
    model = eom.numeric(values, backend="python")
    q, qd = reference.assemble(np.linspace(0.8, -0.8, 4))
    expected = reference.forward_dynamics(q, qd).qdd
    np.testing.assert_allclose(model.forward_dynamics(q, qd).qdd, expected, rtol=1e-12,
                               atol=1e-12 * np.max(np.abs(expected)))
