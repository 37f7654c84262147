"""The faster paths of friction and sampled control keep their results: what each shortcut must still do.

No wall-clock assertions: the work saved is counted instead (Jacobians CVODE forms under a sampled
controller, right-hand sides the friction solve needs), and the results are checked against the
paths that do the full work.  The times are measured by bench/bench_controllers.py and
bench/bench_friction.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import (
    CART_POLE_VALUES,
    PIN_FRICTION_PENDULUM_VALUES,
    cart_pole_by_joints,
    pin_friction_pendulum,
)

import kronlag
from kronlag.numeric.codegen import python_backend
from kronlag.simulation import drivers

UPRIGHT = math.pi / 2


def _cart_pole_tilted(angle: float):
    model = kronlag.derive(cart_pole_by_joints()).numeric(CART_POLE_VALUES)
    lc = CART_POLE_VALUES["lc"]
    guess = [0, 0, 0, -lc * math.sin(angle), lc * math.cos(angle), UPRIGHT + angle]
    return model, *model.assemble(guess, fixed={"x_cart": 0.0, "theta_pole": UPRIGHT + angle})


def _feedback(t, q, qd):
    return {"u": -float(np.array([-3.0, 40.0, -4.0, 7.5]) @ [q[0], q[5] - UPRIGHT, qd[0], qd[5]])}


def test_cvode_under_a_sampled_controller_forms_no_jacobian_and_agrees_with_a_one_step_method():
    """CVODE restarts at every sample; its fixed-point corrector forms no difference-quotient Jacobian
    there (Newton formed one a sample: 2 m evaluations each), and the run still agrees with ALI3-P."""
    model, q0, qd0 = _cart_pole_tilted(0.1)
    times = np.linspace(0, 0.5, 51)
    runs = {method: kronlag.simulate(model, (0, 0.5), q0, qd0, method=method, t_eval=times, rtol=1e-10, atol=1e-12,
                                     controller=kronlag.Sampled(_feedback, period=0.005))
            for method in ("compiled", "ali3p")}
    assert runs["compiled"].success and runs["compiled"].njev == 0
    assert np.max(np.abs(runs["compiled"].q - runs["ali3p"].q)) < 1e-7


def _counting_solves(monkeypatch) -> list[int]:
    calls = [0]
    solve = python_backend.solve_dynamics_terms

    def counted(*arguments, **options):
        calls[0] += 1
        return solve(*arguments, **options)

    monkeypatch.setattr(python_backend, "solve_dynamics_terms", counted)
    return calls


@pytest.mark.parametrize(("speed", "solves"), [(0.0, 1), (1.5, 2)])
def test_the_friction_solve_skips_a_joint_whose_force_is_zero_whatever_the_load(monkeypatch, speed, solves):
    """The smooth law at rest: tanh(0) = 0 and no viscous term, so the pin's friction is zero whatever its
    load and needs no response (one right-hand side, as without friction); moving, it needs one.  The
    compiled solve gives the same accelerations and reactions as the Python reference."""
    system = pin_friction_pendulum(smoothing_velocity=0.01)
    python = kronlag.derive(system).numeric(PIN_FRICTION_PENDULUM_VALUES, backend="python")
    compiled = kronlag.derive(system).numeric(PIN_FRICTION_PENDULUM_VALUES)
    L, angle = PIN_FRICTION_PENDULUM_VALUES["L"], 0.3
    q = np.array([L / 2 * math.cos(angle), L / 2 * math.sin(angle), angle])
    qd = speed * np.array([-L / 2 * math.sin(angle), L / 2 * math.cos(angle), 1.0])
    calls = _counting_solves(monkeypatch)
    reference = python.forward_dynamics(q, qd)
    assert calls[0] == solves
    result = compiled.forward_dynamics(q, qd)
    np.testing.assert_allclose(result.qdd, reference.qdd, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(result.lam, reference.lam, rtol=1e-12, atol=1e-12)


def test_a_large_output_block_is_writable_and_of_its_size():
    """The output block of a run with outputs at every step (rows for max_steps, most never written) is
    mapped with small pages where the system allows: still a writable float array of the size asked."""
    size = (drivers._LARGE_BLOCK // 8) * 3 + 5
    block = drivers._block(size)
    assert block.shape == (size,) and block.dtype == np.float64 and block.flags.writeable
    block[[0, size // 2, size - 1]] = (1.0, 2.0, 3.0)
    assert block[size - 1] == 3.0
    assert drivers._block(10).shape == (10,)
