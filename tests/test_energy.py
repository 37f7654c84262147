"""Energy balance E(t) - E(0) = W(t) (kronlag.energy) for driven and damped models, and the
work of a constant crank torque against its closed form tau (q1(t) - q1(0))."""

import numpy as np
import sympy as sp

import kronlag

FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1, m2=3, m3=2.5, I1=0.0033, I2=0.09, I3=0.052, g=9.81)


def test_work_of_a_constant_crank_torque_is_tau_times_the_crank_rotation():
    model = kronlag.derive(kronlag.models.four_bar()).numeric({**FOUR_BAR, "tau": 1.5}, backend="python")
    q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 2.0})
    trajectory = kronlag.simulate(model, (0, 1.0), q0, qd0, method="projection", rtol=1e-10, atol=1e-12,
                                  t_eval=np.linspace(0, 1.0, 201))
    gain = np.ptp(trajectory.total_energy)
    assert gain > 0.1
    assert np.allclose(trajectory.nonconservative_work, 1.5 * (trajectory.q[:, 0] - q0[0]), atol=1e-6 * gain)
    assert np.max(np.abs(trajectory.energy_balance)) < 1e-6 * gain


def test_damped_slider_crank_engine_balances_its_energy():
    """A damper between the main bearing and the piston: the energy falls by the damper's work."""
    engine = kronlag.models.slider_crank_engine()
    c = sp.Symbol("c")
    engine.parameters = (*engine.parameters, c)
    engine.add_damper(engine.point("main").position, engine.point("wrist").position, coefficient=c)
    values = dict(l1=0.05, l2=0.2, m1=2.0, m2=0.8, m3=0.5, I1=0.05 ** 2 * 2 / 3, I2=0.8 * 0.04 / 12, I3=1e-4,
                  g=9.81, tau=0.0, c=20.0)
    model = kronlag.derive(engine).numeric(values, backend="python")
    guess = np.zeros(model.m)
    guess[[0, 3, 6]] = 0.025, 0.15, 0.25
    q0, qd0 = model.assemble(guess, fixed={"theta_crank": 0.0}, qd_fixed={"theta_crank": 50.0})
    trajectory = kronlag.simulate(model, (0, 0.2), q0, qd0, method="projection", rtol=1e-10, atol=1e-12,
                                  t_eval=np.linspace(0, 0.2, 401))
    loss = -trajectory.nonconservative_work[-1]
    assert loss > 0.1 * trajectory.total_energy[0]
    assert np.max(np.abs(trajectory.energy_balance)) < 1e-6 * loss
