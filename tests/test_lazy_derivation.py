"""The derivation's matrices stay in SymEngine until asked for (lazy ``Equations``), the numeric model's
kernels read that form directly, the model's library holds what the integrators read, and a driver's
library reuses the compiled kernel parts of its model's.

Correctness only (no timings): the kernels built from the SymEngine form agree with those built
through SymPy (the route of equations that were substituted or unpickled) at random states, and the
lazily converted matrices satisfy Lagrange's equations written out independently.
"""

from __future__ import annotations

import pickle
import random

import numpy as np
import pytest
import sympy as sp
from helpers import assert_numerically_equal, needs_compiler

import kronlag
from kronlag import models
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.numeric.codegen import build
from kronlag.symbolic import matrices as catalogue

STORED = (*catalogue.STORED, "potential_energy", "C_christoffel")


def _free_top() -> kronlag.System:
    """A free spatial body in Euler parameters (their normalization a constraint) under gravity."""
    mass, a, b, c, g = sp.symbols("mass a b c g")
    body = free_body("top", mass=mass, inertia=sp.diag(a, b, c), dimension=3)
    return mechanism([body], parameters=[mass, a, b, c, g], gravity=(0, 0, -g), name="free_top")


MODELS = {
    "closed_chain_4_absolute": lambda: models.closed_chain(4, "absolute"),
    "closed_chain_7_relative": lambda: models.closed_chain(7, "relative"),
    "ur5": models.ur5,
    "heavy_top": models.heavy_top,
    "free_top": _free_top,
    "chaplygin_sleigh": models.chaplygin_sleigh,
}


def _values(eom: kronlag.Equations, seed: int = 1) -> dict[str, float]:
    rng = random.Random(seed)
    values = {p.name: rng.uniform(0.5, 2.0) for p in eom.parameters}
    if {"a", "b", "c"} <= values.keys():  # principal moments: the triangle inequality
        values.update(a=1.0, b=1.2, c=1.5)
    if {"Ixx", "Izz"} <= values.keys():
        values["Izz"] = min(values["Izz"], 2 * values["Ixx"])
    return values


def test_derive_converts_no_matrix_to_sympy_until_one_is_asked_for():
    eom = kronlag.derive(models.closed_chain(6, "relative"))
    eom.numeric(_values(eom), backend="python")
    assert not [name for name in STORED if name in eom.__dict__]
    assert eom.shape == (6, 2, 0)
    assert eom.M.shape == (6, 6) and "M" in eom.__dict__ and "C" not in eom.__dict__


@pytest.mark.parametrize("name", MODELS)
def test_kernels_from_symengine_agree_with_the_sympy_route(name):
    eom = kronlag.derive(MODELS[name]())
    through_sympy = eom.subs({})  # StoredMatrices: no SymEngine form, the kernels convert the SymPy matrices
    assert eom.symengine("M") is not None and through_sympy.symengine("M") is None
    values = _values(eom)
    native, reference = eom.numeric(values, backend="python"), through_sympy.numeric(values, backend="python")
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, qd = rng.uniform(-1.5, 1.5, eom.shape[0]), rng.uniform(-1.5, 1.5, eom.shape[0])
        expected = reference.dynamics_terms(q, qd)
        for block, value in native.dynamics_terms(q, qd).items():
            np.testing.assert_allclose(value, expected[block], rtol=1e-12,
                                       atol=1e-12 * max(1.0, np.abs(expected[block]).max(initial=0.0)))
        for accessor in ("C", "Cqd", "g", "Phi_q"):
            args = (q, qd) if accessor in catalogue.SPEED_DEPENDENT else (q,)
            np.testing.assert_allclose(getattr(native, accessor)(*args), getattr(reference, accessor)(*args),
                                       rtol=1e-12, atol=1e-12)
        assert native.potential_energy(q) == pytest.approx(reference.potential_energy(q), rel=1e-12, abs=1e-12)


def test_lazy_matrices_satisfy_lagranges_equations_written_out_independently():
    """closed_chain(3, "relative"): T and V by hand, M = d2T/dqd2, C qd = d/dt(dT/dqd) - dT/dq - M qdd, g = dV/dq."""
    eom = kronlag.derive(models.closed_chain(3, "relative"))
    q, qd = sp.Matrix(eom.coordinates), sp.Matrix(eom.speeds)
    symbols = {s.name: s for s in eom.parameters}
    lengths, masses, inertias = ([symbols[f"{k}{i}"] for i in (1, 2, 3)] for k in "lmI")
    kinetic, potential, joint, angle = 0, 0, sp.Matrix([0, 0]), 0
    for i in range(3):
        angle += q[i]
        centre = joint + lengths[i] / 2 * sp.Matrix([sp.cos(angle), sp.sin(angle)])
        velocity = centre.jacobian(q) * qd
        kinetic += masses[i] * velocity.dot(velocity) / 2 + inertias[i] * sum(qd[:i + 1]) ** 2 / 2
        potential += masses[i] * symbols["g"] * centre[1]
        joint = joint + lengths[i] * sp.Matrix([sp.cos(angle), sp.sin(angle)])
    momentum = sp.Matrix([kinetic]).jacobian(qd).T
    mass_matrix = momentum.jacobian(qd)
    velocity_terms = momentum.jacobian(q) * qd - sp.Matrix([kinetic]).jacobian(q).T
    signed = {*q, *qd}
    assert_numerically_equal(eom.M, mass_matrix, signed)
    assert_numerically_equal(eom.Cqd, velocity_terms, signed)
    assert_numerically_equal(eom.C * qd, velocity_terms, signed)
    assert_numerically_equal(eom.C_christoffel * qd, velocity_terms, signed)
    assert_numerically_equal(eom.g, sp.Matrix([potential]).jacobian(q).T, signed)
    assert eom.C.subs({v: 0 for v in qd}) == sp.zeros(3, 3)
    model = eom.numeric(_values(eom), backend="python")
    assert np.all(np.linalg.eigvalsh(model.M(np.array([0.3, -1.1, 2.0]))) > 0)


def test_lazy_equations_pickle_and_simplify_like_stored_ones():
    eom = kronlag.derive(models.closed_chain(3, "absolute"))
    restored = pickle.loads(pickle.dumps(eom))
    assert restored.symengine("M") is None and restored.M == eom.M and restored.C == eom.C
    simplified = kronlag.derive(models.closed_chain(3, "absolute"), simplify=True)
    assert simplified.symengine("M") is None  # its kernels read the simplified matrices
    assert_numerically_equal(simplified.M, eom.M, set(eom.coordinates))


@needs_compiler
def test_a_drivers_library_reuses_the_kernel_parts_of_its_models(tmp_path, monkeypatch):
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    eom = kronlag.derive(models.closed_chain(4, "relative"))
    model = eom.numeric(_values(eom), backend="c")
    assert build.library_parts(model.c_source) >= 2
    compiled: list[str] = []
    command = build._compile_command

    def recording(compiler, flags, source, output):
        compiled.append(source.name)
        return command(compiler, flags, source, output)

    monkeypatch.setattr(build, "_compile_command", recording)
    extended = model.c_source + "#if KRONLAG_IN_PART(0)\nint kronlag_extra(void) { return 1; }\n#endif\n"
    library = build.load_shared_library(extended)
    assert compiled == ["model.c"]  # part 0 only: the kernel parts are the model's objects
    assert library.kronlag_extra() == 1


@needs_compiler
def test_the_first_simulation_compiles_no_kernel_library_again():
    eom = kronlag.derive(models.closed_chain(4, "relative"))
    values = _values(eom)
    values.update(xg=2.0, yg=0.5)
    model = eom.numeric(values, backend="c")
    q0, qd0 = model.assemble([0.6, -0.5, -0.6, -0.4])
    kronlag.simulate(model, (0.0, 0.05), q0, qd0)
    assert set(model._libraries) == {"dynamics"}
