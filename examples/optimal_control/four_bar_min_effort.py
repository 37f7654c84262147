"""Minimum-effort swing of the four-bar (CasADi, IPOPT)
====================================================

Minimum-effort swing of the four-bar crank with CasADi and IPOPT.

The four-bar of ``examples/four_bar.toml`` hangs at rest in its static
equilibrium (``model.equilibrium``).  Find the crank torque ``tau(t)``,
piecewise constant on N intervals, that swings the crank by SWING rad in
DURATION s and stops it there, with the least effort ``integral tau^2 dt``.

Direct multiple shooting: the state ``x = [q; qd]`` (6) at N + 1 nodes, the
forward dynamics of the constrained system (``kronlag.symbolic.interop.casadi_functions``:
``[[M, Phi_q^T], [Phi_q, 0]] [qdd; lambda] = [f_Q - C qd - g; gamma]``) integrated
by RK4 across each interval, continuity at the nodes, the crank angle and speed
prescribed at the end.  IPOPT ships with the casadi wheel.  The torque found is
then replayed through ``kronlag.simulate`` (an independent integrator) to check
that it does what the optimizer claims.  Writes ``four_bar_min_effort.png``.

Run: ``python3 examples/optimal_control/four_bar_min_effort.py``.
"""

import casadi as ca
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import kronlag
from kronlag.model.builtin import load_example
from kronlag.symbolic.interop import casadi_functions

SWING, DURATION, INTERVALS, RK4_STEPS = 1.0, 1.5, 30, 4

example = load_example("four_bar", apply_drives=False)
model = kronlag.derive(example.system).numeric(example.values)
rest = model.equilibrium([-1.5, -0.5, -1.5])
forward_dynamics = casadi_functions(model)["forward_dynamics"]
m = model.m
torque_index = model.parameter_names.index("tau")
values = model.parameter_vector()


def rate(x, torque):
    """``[qd; qdd]`` with the crank torque ``torque``."""
    p = ca.vertcat(values[:torque_index], torque, values[torque_index + 1:])
    qdd, _, _ = forward_dynamics(x[:m], x[m:], p, 0.0)
    return ca.vertcat(x[m:], qdd)


def interval(x, torque):
    """RK4 across one interval of length DURATION / INTERVALS."""
    h = DURATION / INTERVALS / RK4_STEPS
    for _ in range(RK4_STEPS):
        k1 = rate(x, torque)
        k2 = rate(x + h / 2 * k1, torque)
        k3 = rate(x + h / 2 * k2, torque)
        k4 = rate(x + h * k3, torque)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


x_sym, u_sym = ca.SX.sym("x", 2 * m), ca.SX.sym("u")
step = ca.Function("step", [x_sym, u_sym], [interval(x_sym, u_sym)])

opti = ca.Opti()
X = opti.variable(2 * m, INTERVALS + 1)
U = opti.variable(INTERVALS)
start = np.concatenate([rest.q, np.zeros(m)])
opti.subject_to(X[:, 0] == start)
for k in range(INTERVALS):
    opti.subject_to(X[:, k + 1] == step(X[:, k], U[k]))
opti.subject_to(X[0, INTERVALS] == rest.q[0] + SWING)
opti.subject_to(X[m, INTERVALS] == 0.0)
opti.minimize(ca.sumsqr(U) * DURATION / INTERVALS)
for k in range(INTERVALS + 1):  # guess: the crank turning evenly, the loop closed at every node
    crank = rest.q[0] + SWING * k / INTERVALS
    q_guess, qd_guess = model.assemble(rest.q, fixed={"q1": crank}, qd_fixed={"q1": SWING / DURATION})
    opti.set_initial(X[:, k], np.concatenate([q_guess, qd_guess]))
# a trial step of the line search may hit a singular configuration (NaN); IPOPT then backtracks
opti.solver("ipopt", {"print_time": False, "show_eval_warnings": False}, {"print_level": 0, "sb": "yes"})
solution = opti.solve()
torques = np.atleast_1d(solution.value(U))
nodes = solution.value(X)
effort = float(np.sum(torques ** 2) * DURATION / INTERVALS)


def torque_at(t: float) -> float:
    return float(torques[min(int(t / DURATION * INTERVALS), INTERVALS - 1)])


replay = kronlag.simulate(model.with_parameters(tau=torque_at), (0.0, DURATION), rest.q, np.zeros(m),
                         t_eval=np.linspace(0.0, DURATION, 151), rtol=1e-10, atol=1e-12)
print(f"effort integral tau^2 dt = {effort:.6g} N^2 m^2 s, peak torque {np.max(np.abs(torques)):.4g} N m")
print(f"crank angle at the end: optimizer {nodes[0, -1]:.6f}, replayed by kronlag.simulate "
      f"{replay.q[-1, 0]:.6f}, target {rest.q[0] + SWING:.6f}; crank speed replayed {replay.qd[-1, 0]:.2e} rad/s")

figure, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
times = np.linspace(0.0, DURATION, INTERVALS + 1)
top.plot(times, nodes[0], "o", label="q1 at the shooting nodes (CasADi)")
top.plot(replay.t, replay.q[:, 0], label="q1 replayed (kronlag.simulate)")
top.axhline(rest.q[0] + SWING, color="grey", linestyle=":", label="target")
top.set_ylabel("crank angle q1 (rad)")
top.legend()
bottom.step(times, np.append(torques, torques[-1]), where="post")
bottom.set_ylabel("torque tau (N m)")
bottom.set_xlabel("t (s)")
figure.suptitle(f"Minimum-effort swing of the four-bar crank by {SWING:g} rad in {DURATION:g} s")
figure.tight_layout()
figure.savefig("four_bar_min_effort.png", dpi=100)
