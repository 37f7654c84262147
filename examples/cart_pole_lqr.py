"""Cart-pole balanced by LQR
=========================

A cart-pole built with joints (a prismatic joint for the cart, a revolute joint for the pole, a
force ``u`` on the cart) is linearized at its upright equilibrium with :func:`kronlag.linearize`;
``control.lqr`` gives the gain of the state feedback ``u = -K x``, which closes the loop on the
nonlinear model through ``kronlag.simulate(..., controller=...)``, once as a continuous controller
and once as a digital one sampled at 50 Hz (:class:`kronlag.Sampled`, zero-order hold).  The plot
shows the cart position ``x``, the pole angle ``theta`` from upright and the force ``u``.  The
same loop from a model file: ``kronlag simulate examples/cart_pole.toml`` (its ``[controller]``
table holds this gain).  Needs python-control.  Run: ``python3 examples/cart_pole_lqr.py``.
"""

import control
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402

import kronlag  # noqa: E402

# The cart (M) slides along x; the pole (m, length 2 lc, centre of mass lc from the pivot) turns
# about the cart's centre; theta_pole = pi/2 is upright.
M, m, lc, I, Ic, g, u = sp.symbols("M m lc I Ic g u")
system = kronlag.mechanism([kronlag.free_body("cart", mass=M, inertia=Ic),
                            kronlag.free_body("pole", mass=m, inertia=I)],
                           parameters=[M, m, lc, I, Ic, g, u], gravity=(0, -g), name="cart_pole")
system.add_joint("prismatic", "ground", "cart", axis=(1, 0), name="rail")
system.add_joint("revolute", "cart", "pole", at_b=(-lc, 0), name="hinge")
system.add_force(system.body("cart").position, (u, 0), name="push")
model = kronlag.derive(system).numeric(dict(M=1.0, m=0.2, lc=0.3, I=0.2 * 0.6 ** 2 / 12, Ic=0.1, g=9.81, u=0.0))

# Linearize at the upright equilibrium in the independent coordinates x_cart, theta_pole.
upright = {"x_cart": 0.0, "theta_pole": np.pi / 2}
q_up, _ = model.assemble([0, 0, 0, 0, 0.3, np.pi / 2], fixed=upright)
linear = kronlag.linearize(model, q_up, independent=list(upright), inputs=["u"])
K, _, poles = control.lqr(linear.to_control(), np.diag([10.0, 100.0, 1.0, 1.0]), np.eye(1))
K = np.asarray(K)[0]
print("LQR gain K =", K, "closed-loop poles:", np.round(poles, 3))

x_cart, theta_pole = (model.coordinate_names.index(name) for name in upright)


def state_feedback(t, q, qd):
    """u = -K (x - x_ref): the state in the linearization's order [x, theta, xd, thetad]."""
    x = np.array([q[x_cart], q[theta_pole] - np.pi / 2, qd[x_cart], qd[theta_pole]])
    return {"u": -float(K @ x)}


# Released with the pole 0.1 rad from upright.
q0, qd0 = model.assemble([0, 0, 0, -0.03, 0.3, np.pi / 2 + 0.1], fixed={"x_cart": 0.0, "theta_pole": np.pi / 2 + 0.1})
times = np.linspace(0, 5, 1001)
continuous = kronlag.simulate(model, (0, 5), q0, qd0, t_eval=times, controller=state_feedback)
digital = kronlag.simulate(model, (0, 5), q0, qd0, t_eval=times,
                           controller=kronlag.Sampled(state_feedback, period=0.02))
print(continuous.message, f"({continuous.wall_time:.3f} s);", digital.message, f"({digital.wall_time:.3f} s)")

figure, axes = plt.subplots(3, 1, sharex=True, figsize=(7, 7))
for trajectory, label in ((continuous, "continuous"), (digital, "sampled at 50 Hz")):
    axes[0].plot(trajectory.t, trajectory.q[:, x_cart], label=label)
    axes[1].plot(trajectory.t, trajectory.q[:, theta_pole] - np.pi / 2, label=label)
    axes[2].plot(trajectory.t, trajectory.inputs["u"], label=label, drawstyle="steps-post")
for axis, text in zip(axes, ("cart x [m]", "pole angle from upright [rad]", "force u [N]")):
    axis.set_ylabel(text)
    axis.grid(True)
axes[0].legend()
axes[-1].set_xlabel("t [s]")
figure.suptitle("Cart-pole under LQR state feedback (nonlinear model)")
figure.tight_layout()
figure.savefig("cart_pole_lqr.png", dpi=100)
