"""Numeric model: generated NumPy and C kernels against SymPy, parameters, the C contract."""

from __future__ import annotations

import ctypes
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import backend_params, derived, evaluate, needs_compiler, numeric, parameter_values, random_state

import kronlag
from kronlag.numeric import codegen
from kronlag.numeric.codegen import c_backend
from kronlag.symbolic.calculus import time_derivative

MODELS = ["four_bar", "quick_return", "double_pendulum", "slider_crank", "heavy_top", "chaplygin_sleigh",
          "closed_chain_4_relative"]
def sympy_reference(eom: kronlag.Equations, values: dict, q, qd, t) -> dict[str, np.ndarray]:
    """The matrices evaluated from the SymPy expressions (subs/evalf), independently of the codegen."""
    subs = {**{p: values[p.name] for p in eom.parameters}, **dict(zip(eom.coordinates, q)),
            **dict(zip(eom.speeds, qd)), eom.time: t}
    qd_vector = sp.Matrix(eom.speeds)
    symbolic = {
        "M": eom.M, "C": eom.C, "C_christoffel": eom.C_christoffel, "g": eom.g, "Phi": eom.Phi,
        "Phi_q": eom.Phi_q, "A": eom.A, "b": eom.b, "f_Q": eom.f_Q, "Cqd": eom.C * qd_vector,
        "gamma": -(time_derivative(eom.Phi_q, eom.coordinates, eom.speeds) * qd_vector),
        "gamma_nh": -(time_derivative(eom.A, eom.coordinates, eom.speeds) * qd_vector
                      + time_derivative(eom.b, eom.coordinates, eom.speeds)),
        "potential_energy": sp.Matrix([eom.potential_energy]),
        "kinetic_energy": sp.Matrix([eom.kinetic_energy]),
    }
    return {name: np.array(evaluate(matrix, subs), dtype=float).reshape(matrix.shape)
            for name, matrix in symbolic.items()}


def call(model: kronlag.NumericModel, name: str, q, qd, t):
    if name in ("M", "g", "Phi", "Phi_q", "A", "b", "potential_energy"):
        return getattr(model, name)(q, t)
    return getattr(model, name)(q, qd, t)


@pytest.mark.parametrize("backend", backend_params())
@pytest.mark.parametrize("name", MODELS)
def test_matrices_equal_sympy_values(name, backend):
    eom = derived(name)
    model = numeric(name, backend)
    m, r, s = eom.shape
    shapes = {"M": (m, m), "C": (m, m), "C_christoffel": (m, m), "g": (m,), "Phi": (r,), "Phi_q": (r, m),
              "A": (s, m), "b": (s,), "f_Q": (m,), "Cqd": (m,), "gamma": (r,), "gamma_nh": (s,)}
    for seed in (1, 2):
        q, qd, t = random_state(eom, seed)
        reference = sympy_reference(eom, parameter_values(name), q, qd, t)
        for matrix, expected in reference.items():
            actual = call(model, matrix, q, qd, t)
            if matrix in shapes:
                assert actual.shape == shapes[matrix], matrix
                assert actual.dtype == np.float64
            else:
                assert isinstance(actual, float)
            np.testing.assert_allclose(np.reshape(actual, expected.shape), expected, rtol=1e-12,
                                       atol=1e-12 * max(1.0, np.max(np.abs(expected), initial=0)),
                                       err_msg=f"{name} {backend} {matrix}")


@needs_compiler
@pytest.mark.parametrize("name", MODELS)
def test_c_backend_equals_numpy_backend(name):
    eom = derived(name)
    c_model, numpy_model = numeric(name, "c"), numeric(name, "python")
    q, qd, t = random_state(eom, 3)
    for key, value in c_model.dynamics_terms(q, qd, t).items():
        np.testing.assert_allclose(value, numpy_model.dynamics_terms(q, qd, t)[key], rtol=1e-13, atol=1e-13)
    a = c_model.forward_dynamics(q, qd, t, alpha=2.0, beta=3.0)
    b = numpy_model.forward_dynamics(q, qd, t, alpha=2.0, beta=3.0)
    scale = max(1.0, np.max(np.abs(a.qdd)))
    np.testing.assert_allclose(a.qdd, b.qdd, rtol=1e-9, atol=1e-10 * scale)
    np.testing.assert_allclose(a.lam, b.lam, rtol=1e-9, atol=1e-10 * scale)
    np.testing.assert_allclose(a.mu, b.mu, rtol=1e-9, atol=1e-10 * scale)
    assert (a.rank, a.unique_multipliers) == (b.rank, b.unique_multipliers)


def test_interface_attributes():
    model = numeric("four_bar", "python")
    assert (model.m, model.r, model.s) == (3, 2, 0)
    assert model.coordinate_names == ("q1", "q2", "q3")
    assert model.equations is derived("four_bar")
    assert model.backend == "python" and model.time_varying is False
    assert model.parameter_names == tuple(p.name for p in derived("four_bar").parameters)
    np.testing.assert_array_equal(model.parameter_vector(0.0),
                                  [parameter_values("four_bar")[n] for n in model.parameter_names])
    with pytest.raises(AttributeError, match="backend='c'"):
        model.c_source
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        model.M([1.0, 2.0])


def test_missing_parameters_are_all_listed():
    eom = derived("four_bar")
    with pytest.raises(ValueError) as error:
        eom.numeric({"l1": 1.0, "m2": 1.0}, backend="python")
    message = str(error.value)
    for name in ("l2", "l3", "l4", "m1", "m3", "I1", "I2", "I3", "g", "tau"):
        assert name in message
    assert "'l1'" not in message and "m2," not in message


def test_unknown_and_invalid_parameters():
    eom = derived("double_pendulum")
    values = dict.fromkeys(("l1", "l2", "m1", "m2", "I1", "I2", "g"), 1.0)
    with pytest.raises(ValueError, match="unknown parameter.*'tau'"):
        eom.numeric({**values, "tau": 1.0}, backend="python")
    with pytest.raises(ValueError, match="expected a number"):
        eom.numeric({**values, "g": "heavy"}, backend="python")
    with pytest.raises(ValueError, match="backend"):
        eom.numeric(values, backend="fortran")
    by_symbol = eom.numeric({sp.Symbol(name): value for name, value in values.items()}, backend="python")
    np.testing.assert_array_equal(by_symbol.parameter_vector(), np.ones(7))


def test_time_varying_parameter_must_not_enter_mass_matrix_or_constraints():
    values = parameter_values("four_bar")
    with pytest.raises(ValueError, match="l2 enter M or the constraints"):
        derived("four_bar").numeric({**values, "l2": lambda t: 1 + t}, backend="python")


@pytest.mark.parametrize("backend", backend_params())
def test_time_varying_torque(backend):
    eom = derived("four_bar")
    values = parameter_values("four_bar")
    model = eom.numeric({**values, "tau": lambda t: 2.0 * t}, backend=backend)
    assert model.time_varying
    assert model.parameter_vector(1.5)[model.parameter_names.index("tau")] == 3.0
    q, qd, _ = random_state(eom, 4)
    for t, tau in ((0.0, 0.0), (1.5, 3.0)):
        constant = eom.numeric({**values, "tau": tau}, backend=backend)
        np.testing.assert_allclose(model.f_Q(q, qd, t), constant.f_Q(q, qd, t), rtol=1e-14)
        np.testing.assert_allclose(model.forward_dynamics(q, qd, t).qdd, constant.forward_dynamics(q, qd, t).qdd,
                                   rtol=1e-12)


@needs_compiler
def test_auto_backend_is_c_with_a_compiler():
    assert derived("double_pendulum").numeric(parameter_values("double_pendulum")).backend == "c"


@needs_compiler
def test_c_source_is_self_contained_and_matches_the_interface(tmp_path):
    model = numeric("slider_crank", "c")
    source = tmp_path / "model.c"
    source.write_text(model.c_source)
    library = tmp_path / "model.so"
    subprocess.run([*codegen.c_compiler().command, "-O1", "-shared", "-fPIC", "-o", str(library), str(source), "-lm"],
                   check=True)
    function = ctypes.CDLL(str(library)).kronlag_forward_dynamics
    double_p = ctypes.POINTER(ctypes.c_double)
    function.argtypes = [ctypes.c_double, double_p, double_p, double_p, ctypes.c_double, ctypes.c_double,
                         double_p, double_p, double_p]
    function.restype = ctypes.c_int
    q, qd, t = random_state(model.equations, 5)
    p = model.parameter_vector(t)
    qdd, lam, mu = np.zeros(model.m), np.zeros(model.r), np.zeros(1)
    pointer = lambda array: array.ctypes.data_as(double_p)  # noqa: E731
    assert function(t, pointer(q), pointer(qd), pointer(p), 0.5, 1.5, pointer(qdd), pointer(lam), pointer(mu)) == 0
    expected = model.forward_dynamics(q, qd, t, alpha=0.5, beta=1.5)
    np.testing.assert_allclose(qdd, expected.qdd, rtol=1e-13)
    np.testing.assert_allclose(lam, expected.lam, rtol=1e-13)


@needs_compiler
def test_compiled_library_is_cached_on_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    values = parameter_values("double_pendulum")
    first = derived("double_pendulum").numeric(values, backend="c")
    libraries = list(tmp_path.glob("kronlag_*.so"))
    assert len(libraries) == 1

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(subprocess, "run", no_compiler)
    monkeypatch.setattr(subprocess, "Popen", no_compiler)
    second = derived("double_pendulum").numeric({**values, "g": 1.0}, backend="c")  # parameters are inputs
    assert list(tmp_path.glob("kronlag_*.so")) == libraries
    assert first.c_source == second.c_source


def test_unsupported_function_is_a_clear_error():
    q1, = kronlag.coordinates("q1")
    system = kronlag.System([q1], name="odd")
    system.add_body(kronlag.PointMass("p", mass=1, position=(q1, 0)))
    system.add_potential(sp.Function("mystery")(q1))
    with pytest.raises((NotImplementedError, ValueError), match="mystery"):
        kronlag.derive(system).numeric({}, backend="python").g([0.0])


BENCH = Path(__file__).resolve().parents[1] / "bench"


@needs_compiler
@pytest.mark.parametrize("script, arguments, peer, expected", [
    pytest.param("bench_build.py", ["--n", "4"], None, ["closed_chain(4, 'relative')", "compilation"],
                 marks=pytest.mark.slow),
    pytest.param("bench_forward_dynamics.py", ["--n", "3", "--quick"], "pinocchio", ["pinocchio constraintDynamics"],
                 marks=pytest.mark.slow),
    pytest.param("bench_arms.py", ["--arms", "ur5", "--quick"], "pinocchio", ["pinocchio aba", "ur5"],
                 marks=pytest.mark.slow),
    ("bench_accessors.py", ["--quick"], "pinocchio", ["pinocchio crba", "nonLinearEffects"]),
    ("bench_batch.py", ["--states", "2000"], None, ["batch speed-up over the loop"]),
])
def test_bench_smoke(script, arguments, peer, expected):
    """The benchmarks run (quick mode) and print their tables."""
    if peer:
        pytest.importorskip(peer)
    process = subprocess.run([sys.executable, str(BENCH / script), *arguments], capture_output=True, text=True,
                             timeout=1800)
    assert process.returncode == 0, process.stdout + process.stderr
    assert all(text in process.stdout for text in expected), process.stdout


@needs_compiler
def test_fast_call_layer_and_ctypes_fallback_agree(monkeypatch):
    fast = numeric("quick_return", "c")
    monkeypatch.setattr(c_backend, "FAST_CALL", None)
    fallback = derived("quick_return").numeric(parameter_values("quick_return"), backend="c")
    reference = numeric("quick_return", "python")
    q, qd, t = random_state(fast.equations, 6)
    expected = reference.forward_dynamics(q, qd, t, alpha=1.0, beta=2.0)
    for model in (fast, fallback):
        result = model.forward_dynamics(list(q), list(qd), t, alpha=1.0, beta=2.0)
        np.testing.assert_allclose(result.qdd, expected.qdd, rtol=1e-9)
        np.testing.assert_allclose(result.lam, expected.lam, rtol=1e-9)
        assert result.qdd.dtype == np.float64 and result.mu.shape == (0,)
        np.testing.assert_allclose(model.M(tuple(q), t), reference.M(q, t), rtol=1e-12)
        np.testing.assert_allclose(model.Cqd(q[::-1][::-1], qd, t), reference.Cqd(q, qd, t), rtol=1e-12)
        with pytest.raises(ValueError, match=r"q must have shape \(3,\)"):
            model.forward_dynamics(q[:2], qd)
        with pytest.raises(ValueError, match=r"qd must have shape \(3,\)"):
            model.Cqd(q, np.zeros((3, 1)))


@pytest.mark.parametrize("backend", ["python", "c"])
def test_single_coordinate_model_keeps_matrix_shapes(backend):
    """A simple pendulum in one coordinate: M is 1 x 1 and qdd = -g/l sin q."""
    angle, = kronlag.coordinates("q")
    mass, length, gravity = sp.symbols("m l g")
    system = kronlag.System([angle], parameters=[mass, length, gravity], gravity=(0, -gravity))
    system.add_body(kronlag.PointMass("bob", mass=mass, position=(length * sp.sin(angle), -length * sp.cos(angle))))
    model = kronlag.derive(system).numeric({"m": 2.0, "l": 0.5, "g": 9.81}, backend=backend)
    assert model.M([0.3]).shape == (1, 1) and model.Phi_q([0.3]).shape == (0, 1)
    assert model.kinetic_energy([0.3], [2.0]) == pytest.approx(0.5 * 2.0 * 0.5**2 * 2.0**2)
    np.testing.assert_allclose(model.forward_dynamics([0.3], [2.0]).qdd, [-9.81 / 0.5 * np.sin(0.3)], rtol=1e-12)


@needs_compiler
def test_C_and_C_christoffel_are_compiled_once_together(monkeypatch):
    """The two Coriolis matrices, the largest kernels, are built lazily in one library: the first
    call of either compiles once, the other compiles nothing more (and both agree with SymPy)."""
    eom = derived("four_bar")
    values = parameter_values("four_bar")
    model = eom.numeric(values, backend="c")
    compiled = []
    original = c_backend.load_shared_library
    monkeypatch.setattr(c_backend, "load_shared_library",
                        lambda source, **options: compiled.append(source) or original(source, **options))
    q, qd, t = random_state(eom, 5)
    C = model.C(q, qd, t)
    C_christoffel = model.C_christoffel(q, qd, t)
    assert len(compiled) == 1 and "kronlag_C_christoffel" in compiled[0] and "kronlag_C(" in compiled[0]
    reference = sympy_reference(eom, values, q, qd, t)
    np.testing.assert_allclose(C, reference["C"], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(C_christoffel, reference["C_christoffel"], rtol=1e-10, atol=1e-12)
