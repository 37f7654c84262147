"""Models built once, used many times: new parameter values without new code, and pickling."""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp

import kronlag

VALUES = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=3.0, I1=0.0033, I2=0.06, I3=0.0625, g=9.81,
              tau=0.0)
STATE = (np.array([1.0, 0.5583, 1.3347]), np.array([2.0, -0.5, 0.3]))


@pytest.fixture(scope="module")
def equations():
    return kronlag.derive(kronlag.models.four_bar())


@pytest.fixture(scope="module", params=["python", "c"])
def model(request, equations):
    if request.param == "c" and not kronlag.numeric.codegen.c_compiler():
        pytest.skip("no C compiler")
    return equations.numeric(VALUES, backend=request.param)


def test_with_parameters_equals_a_model_built_with_those_values_and_shares_the_code(model, equations):
    q, _ = model.assemble(STATE[0], fixed={"q1": 1.0})
    qd = np.array([2.0, 0.0, 0.0])
    _, qd = model.assemble(q, qd_guess=qd, qd_fixed={"q1": 2.0})
    heavy = model.with_parameters({"m2": 4.0}, g=1.62)
    reference = equations.numeric(dict(VALUES, m2=4.0, g=1.62), backend=model.backend)
    np.testing.assert_allclose(heavy.forward_dynamics(q, qd).qdd, reference.forward_dynamics(q, qd).qdd, rtol=1e-12)
    np.testing.assert_allclose(heavy.forward_dynamics(q, qd).lam, reference.forward_dynamics(q, qd).lam, rtol=1e-12)
    np.testing.assert_allclose(heavy.M(q), reference.M(q), rtol=1e-14)
    assert heavy._dynamics is model._dynamics  # the same compiled library, no new code
    assert model.parameter_values()["m2"] == 2.0  # the original is unchanged
    np.testing.assert_allclose(model.forward_dynamics(q, qd).qdd,
                               equations.numeric(VALUES, backend=model.backend).forward_dynamics(q, qd).qdd)


def test_with_parameters_names_unknown_parameters(model):
    with pytest.raises(ValueError, match="unknown parameter.*'mass'"):
        model.with_parameters(mass=1.0)
    torque = model.with_parameters({sp.Symbol("tau"): lambda t: 2.0 * t})
    assert torque.time_varying and torque.parameter_vector(0.5)[-1] == 1.0


def test_equations_pickle_with_and_without_the_christoffel_matrix(equations):
    fresh = kronlag.derive(kronlag.models.four_bar())
    restored = pickle.loads(pickle.dumps(fresh))  # Christoffel form not computed yet: its formula travels
    assert restored.M == fresh.M and restored.Phi_q == fresh.Phi_q and restored.gamma == fresh.gamma
    difference = (restored.C_christoffel - equations.C_christoffel).applyfunc(sp.simplify)
    assert difference == sp.zeros(3, 3)
    assert equations.C_christoffel.shape == (3, 3)  # now computed: the matrix itself travels
    assert pickle.loads(pickle.dumps(equations)).C_christoffel == equations.C_christoffel


def test_numeric_model_and_trajectory_pickle_into_another_process(model, tmp_path):
    q0, qd0 = model.assemble(STATE[0], fixed={"q1": 1.0}, qd_fixed={"q1": 2.0})
    variant = model.with_parameters(m3=5.0)
    trajectory = kronlag.simulate(variant, (0.0, 0.2), q0, qd0, method="projection")
    path = tmp_path / "objects.pickle"
    path.write_bytes(pickle.dumps((variant, trajectory)))
    script = ("import pickle, sys, numpy as np\n"
              "model, trajectory = pickle.loads(open(sys.argv[1], 'rb').read())\n"
              "q, qd = trajectory.q[-1], trajectory.qd[-1]\n"
              "print(model.backend, model.parameter_values()['m3'], *model.forward_dynamics(q, qd).qdd, "
              "*trajectory.q[-1])\n")
    output = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, check=True)
    backend, mass, *numbers = output.stdout.split()
    assert backend == model.backend and float(mass) == 5.0
    q, qd = trajectory.q[-1], trajectory.qd[-1]
    np.testing.assert_allclose([float(x) for x in numbers[:3]], variant.forward_dynamics(q, qd).qdd, rtol=1e-13)
    np.testing.assert_allclose([float(x) for x in numbers[3:]], q, rtol=0, atol=0)
