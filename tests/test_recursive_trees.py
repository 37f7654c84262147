"""Declared kinematic trees (System.add_tree_link): the recursive M and h of closed_chain(n, "relative")
and of hand-built planar and spatial trees against the flat kernel, a hand-written closed form and
Pinocchio (crba, nonLinearEffects; skipped without pin); forward dynamics with multipliers against the
flat path; wrong declarations refused with the body named."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import sympy as sp
from test_recursive_kernels import assert_same_dynamics, operations

import kronlag
from kronlag import models
from kronlag.core.errors import ModelError
from kronlag.core.kernels import (
    SCALAR_NAMESPACE,
    cse_kernel,
    python_functions,
    python_source,
)
from kronlag.model.bodies import PlanarBody
from kronlag.model.trees import TreeDeclarationWarning
from kronlag.numeric.codegen import KernelSource
from kronlag.numeric.codegen.recursive import dynamics_algorithm

cos, sin = sp.cos, sp.sin


def chain_values(n: int, seed: int = 0) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    values = {f"{name}{i}": float(rng.uniform(0.5, 1.5)) for name in "lmI" for i in range(1, n + 1)}
    return values | {"xg": 0.5, "yg": 0.3, "g": 9.81}


def flat_copy(system: kronlag.System) -> kronlag.System:
    """The same System without its declared tree (the flat kernel)."""
    system.tree.clear()
    return system


# -- which Systems get the recursive kernel ---------------------------------------------------------

@pytest.mark.parametrize("n", [2, 5, 12])
def test_relative_chain_is_recursive_absolute_is_not(n):
    assert dynamics_algorithm(models.closed_chain(n, "relative")) == "recursive"
    assert dynamics_algorithm(models.closed_chain(n, "absolute")).startswith("flat:")


@pytest.mark.parametrize("n", [3, 8])
def test_relative_chain_kernel_equals_the_flat_one(n):
    kernels = assert_same_dynamics(kronlag.derive(models.closed_chain(n, "relative")))
    if n >= 8:  # the recursion grows like n, the flat M like n^3
        assert operations(kernels["recursive"]) < operations(kernels["flat"])


# -- independent references --------------------------------------------------------------------------

def test_two_link_chain_against_its_closed_form():
    """M and h = -(C qd + g) of two uniform links in relative angles, written by hand."""
    model = kronlag.derive(models.closed_chain(2, "relative")).numeric(chain_values(2), backend="python")
    v = chain_values(2)
    l1, m1, m2, I1, I2, g = v["l1"], v["m1"], v["m2"], v["I1"], v["I2"], v["g"]
    a1, a2 = v["l1"] / 2, v["l2"] / 2
    rng = np.random.default_rng(3)
    for _ in range(3):
        (q1, q2), (u1, u2) = rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2)
        c2, s2 = np.cos(q2), np.sin(q2)
        coupling = I2 + m2 * (a2**2 + l1 * a2 * c2)
        M = np.array([[I1 + I2 + m1 * a1**2 + m2 * (l1**2 + a2**2 + 2 * l1 * a2 * c2), coupling],
                      [coupling, I2 + m2 * a2**2]])
        Cqd = np.array([-m2 * l1 * a2 * s2 * (2 * u1 * u2 + u2**2), m2 * l1 * a2 * s2 * u1**2])
        outer = m2 * a2 * g * np.cos(q1 + q2)
        G = np.array([(m1 * a1 + m2 * l1) * g * np.cos(q1) + outer, outer])
        terms = model.dynamics_terms([q1, q2], [u1, u2])
        assert np.allclose(terms["M"], M, rtol=1e-13, atol=1e-13)
        assert np.allclose(terms["h"], -(Cqd + G), rtol=1e-13, atol=1e-13)


def test_relative_chain_against_pinocchio():
    pin = pytest.importorskip("pinocchio")
    n = 6
    values = chain_values(n, seed=4)
    model = kronlag.derive(models.closed_chain(n, "relative")).numeric(values, backend="python")
    peer = pin.Model()
    parent, placement = 0, pin.SE3.Identity()
    for i in range(1, n + 1):
        joint = peer.addJoint(parent, pin.JointModelRZ(), placement, f"joint{i}")
        inertia = values[f"I{i}"]
        peer.appendBodyToJoint(joint, pin.Inertia(values[f"m{i}"], np.array([values[f"l{i}"] / 2, 0, 0]),
                                                  np.diag([inertia] * 3)), pin.SE3.Identity())
        parent, placement = joint, pin.SE3(np.eye(3), np.array([values[f"l{i}"], 0, 0]))
    peer.gravity.linear = np.array([0, -values["g"], 0])
    data = peer.createData()
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, qd = rng.uniform(-2, 2, n), rng.uniform(-2, 2, n)
        terms = model.dynamics_terms(q, qd)
        mass = pin.crba(peer, data, q)
        mass = np.triu(mass) + np.triu(mass, 1).T
        assert np.allclose(terms["M"], mass, rtol=1e-12, atol=1e-12)
        assert np.allclose(terms["h"], -pin.nonLinearEffects(peer, data, q, qd), rtol=1e-12, atol=1e-12)


def test_forward_dynamics_with_multipliers_equals_the_flat_path():
    n = 7
    values = chain_values(n, seed=1)
    recursive = kronlag.derive(models.closed_chain(n, "relative")).numeric(values, backend="python")
    flat = kronlag.derive(flat_copy(models.closed_chain(n, "relative"))).numeric(values, backend="python")
    rng = np.random.default_rng(2)
    q, qd = recursive.assemble(rng.uniform(-0.5, 0.5, n), qd_guess=rng.uniform(-1, 1, n))
    ours, theirs = recursive.forward_dynamics(q, qd), flat.forward_dynamics(q, qd)
    for key in ("qdd", "lam"):
        expected = getattr(theirs, key)
        assert np.abs(getattr(ours, key) - expected).max() <= 1e-12 * max(1.0, np.abs(expected).max())


# -- hand-built trees --------------------------------------------------------------------------------

def cart_pole() -> kronlag.System:
    """A cart on a prismatic joint carrying a pole (its angle from the downward vertical), with a
    spring on the cart, a damping force and a torque on the pole: loads the recursion leaves in h."""
    x, th = kronlag.coordinates("x th")
    m1, m2, I2, a, g, k = sp.symbols("m1 m2 I2 a g k")
    system = kronlag.System([x, th], parameters=[m1, m2, I2, a, g, k], gravity=(0, -g), name="cart_pole")
    system.add_body(PlanarBody("cart", mass=m1, inertia=0, position=(x, 0), angle=0))
    system.add_body(PlanarBody("pole", mass=m2, inertia=I2, position=(x + a * sin(th), -a * cos(th)),
                               angle=th - sp.pi / 2))
    system.add_tree_link("cart", x, joint="prismatic", axis=(1, 0))
    system.add_tree_link("pole", th, parent="cart", angle=-sp.pi / 2, centre=(a, 0))
    system.add_potential(k * x**2 / 2, name="spring")
    system.add_generalized_force([-0.3 * system.speeds[0], 0], name="damper")
    system.add_torque("pole", 0.2 * cos(th), name="motor")
    return system


def test_hand_built_planar_tree_with_loads():
    system = cart_pole()
    assert dynamics_algorithm(system) == "recursive"
    assert_same_dynamics(kronlag.derive(system))


def rodrigues(axis, angle) -> sp.Matrix:
    k = sp.Matrix([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return sp.eye(3) + sin(angle) * k + (1 - cos(angle)) * k * k


def spatial_arm() -> kronlag.System:
    """Two rigid links: a turn about z, then about a general axis in a tilted joint frame."""
    q1, q2 = kronlag.coordinates("q1 q2")
    m1, m2, g = sp.symbols("m1 m2 g")
    tilt = rodrigues((1, 0, 0), sp.Rational(3, 10))
    axis = (0, sp.Rational(3, 5), sp.Rational(4, 5))
    first = rodrigues((0, 0, 1), q1)
    second = first * tilt * rodrigues(axis, q2)
    c1, c2, elbow = sp.Matrix([0.1, 0, 0.2]), sp.Matrix([0.2, 0.05, 0]), sp.Matrix([0, 0, 0.4])
    tensor1 = sp.Matrix([[0.05, 0.001, 0.002], [0.001, 0.04, 0.003], [0.002, 0.003, 0.03]])
    tensor2 = sp.Matrix([[0.01, 0, 0.001], [0, 0.02, 0], [0.001, 0, 0.02]])
    system = kronlag.System([q1, q2], parameters=[m1, m2, g], gravity=(0, 0, -g), name="arm")
    system.add_body(kronlag.RigidBody("upper", mass=m1, inertia=tensor1, position=first * c1, rotation=first))
    system.add_body(kronlag.RigidBody("fore", mass=m2, inertia=tensor2, position=first * elbow + second * c2,
                                      rotation=second))
    system.add_tree_link("upper", q1, axis=(0, 0, 1), centre=c1)
    system.add_tree_link("fore", q2, parent="upper", origin=elbow, rotation=tilt, axis=axis, centre=c2)
    return system


def test_hand_built_spatial_tree():
    system = spatial_arm()
    assert dynamics_algorithm(system) == "recursive"
    assert_same_dynamics(kronlag.derive(system))


# -- wrong declarations --------------------------------------------------------------------------------

def test_a_wrong_declaration_keeps_the_flat_kernel_and_names_the_body():
    system = models.closed_chain(4, "relative")
    link = system.tree[2]
    system.tree[2] = type(link)(**{**link.__dict__, "centre": sp.ImmutableMatrix([link.centre[0] * 1.001, 0, 0])})
    reason = dynamics_algorithm(system)
    assert reason.startswith("flat: ") and "'link 3'" in reason and "centre of mass" in reason
    source = KernelSource(kronlag.derive(system))
    with pytest.warns(TreeDeclarationWarning, match="link 3"):
        kernel = source.kernel("dynamics")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert kernel == KernelSource(kronlag.derive(flat_copy(system))).kernel("dynamics")


def test_a_wrong_turn_is_refused():
    system = cart_pole()
    link = system.tree[1]
    system.tree[1] = type(link)(**{**link.__dict__, "rotation": sp.ImmutableMatrix(sp.eye(3))})
    reason = dynamics_algorithm(system)
    assert reason.startswith("flat: ") and "'pole'" in reason


def test_bodies_and_coordinates_outside_the_tree_are_refused():
    system = models.closed_chain(3, "relative")
    extra = kronlag.PointMass("weight", mass=sp.Symbol("m1"), position=(0, 0))
    system.add_body(extra)
    assert dynamics_algorithm(system) == "flat: body 'weight' is not in the declared tree"
    system = models.closed_chain(3, "relative")
    del system.tree[2]
    assert dynamics_algorithm(system) == "flat: body 'link 3' is not in the declared tree"


def test_malformed_declarations_raise_at_once():
    system = models.closed_chain(3, "absolute")
    q1, q2 = system.coordinates[:2]
    with pytest.raises(ModelError, match="no body named 'rod'"):
        system.add_tree_link("rod", q1)
    with pytest.raises(ModelError, match="parent 'link 2' must be 'ground' or a body declared before"):
        system.add_tree_link("link 1", q1, parent="link 2")
    system.add_tree_link("link 1", q1)
    with pytest.raises(ModelError, match="coordinate q1 already moves another link"):
        system.add_tree_link("link 2", q1, parent="link 1")
    with pytest.raises(ModelError, match="joint must be one of"):
        system.add_tree_link("link 2", q2, parent="link 1", joint="ball")
    with pytest.raises(ModelError, match="may not depend on the coordinates"):
        system.add_tree_link("link 2", q2, parent="link 1", origin=(q1, 0))


@pytest.mark.parametrize("system", [models.closed_chain(6, "relative"), cart_pole()], ids=["chain", "cart_pole"])
def test_structure_keeping_kernels_compiled_with_the_model(system):
    """g (recursive, with the loads' potentials), Phi_q and gamma (from Phi along the motion) equal the
    derivation's flat matrices."""
    equations = kronlag.derive(system)
    source = KernelSource(equations)
    rng = np.random.default_rng(7)
    m = equations.shape[0]
    for name in ("g", "Phi_q", "gamma"):
        ours = source.kernel(name)
        flat = cse_kernel(name, ours.blocks, [source.matrix(name)], source.convert.constants)
        assert ours != flat or not ours.outputs  # the structure-keeping form (a cart-pole has no Phi)
        functions = [python_functions(python_source(kernel), [name], SCALAR_NAMESPACE)[name] for kernel in (ours, flat)]
        for _ in range(3):
            q, qd = rng.uniform(-2, 2, m).tolist(), rng.uniform(-2, 2, m).tolist()
            p = rng.uniform(0.5, 1.5, len(equations.parameters)).tolist()
            mine, theirs = (np.array(function(0.0, q, qd, p)) for function in functions)
            assert np.abs(mine - theirs).max(initial=0) <= 1e-12 * max(1.0, np.abs(theirs).max(initial=0))


@pytest.mark.parametrize("builder", [lambda: models.closed_chain(5, "relative"), cart_pole, spatial_arm],
                         ids=["chain", "cart_pole", "spatial_arm"])
def test_tangent_kernel_is_the_exact_derivative(builder):
    """K = de/dq and D = de/dqd (ALI3-P's tangent) in forward mode through the recursion equal the
    derivatives of the derivation's flat residual, at random states, accelerations and multipliers."""
    equations = kronlag.derive(builder())
    source = KernelSource(equations)
    ours = source.kernel("tangent")
    flat = cse_kernel("tangent", ours.blocks, [source.matrix("K"), source.matrix("D")], source.convert.constants)
    functions = [python_functions(python_source(kernel), ["tangent"], SCALAR_NAMESPACE)["tangent"]
                 for kernel in (ours, flat)]
    m, r, s = equations.shape
    rng = np.random.default_rng(11)
    for _ in range(3):
        q, qd = rng.uniform(-2, 2, m).tolist(), rng.uniform(-2, 2, m).tolist()
        p = rng.uniform(0.5, 1.5, len(equations.parameters) + m + r + s).tolist()
        mine, theirs = (np.array(function(0.3, q, qd, p)) for function in functions)
        assert np.abs(mine - theirs).max() <= 1e-12 * max(1.0, np.abs(theirs).max())
