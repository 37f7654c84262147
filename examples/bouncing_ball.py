"""Bouncing ball: impacts on a floor, against the closed form
============================================================

A ball dropped from ``h0 = 1 m`` onto the floor ``y >= 0`` (``System.add_limit``, restitution
``e = 0.7``) bounces with apex heights ``e^(2k) h0`` at the impact times ``t_k`` of the closed form,
until the Zeno rule makes the contact persistent and the ball rests with the contact force ``m g``.
The figure shows the height with the closed-form apexes, and the gap speed with every impact
marked and labelled with the limit's name (``trajectory.events``).

Writes ``bouncing_ball.png``.  Run: ``python3 examples/bouncing_ball.py``.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402

import kronlag  # noqa: E402

h0, e, g, m = 1.0, 0.7, 9.81, 0.2
y, m_, g_, e_ = sp.symbols("y m g e")
system = kronlag.System([y], parameters=[m_, g_, e_], gravity=(0, -g_), name="bouncing ball")
system.add_body(kronlag.PointMass("ball", mass=m_, position=[0, y]))
system.add_limit(y, lower=0, restitution=e_, name="floor")
model = kronlag.derive(system).numeric({"m": m, "g": g, "e": e})

t1 = np.sqrt(2 * h0 / g)
t_inf = t1 * (1 + 2 * e / (1 - e))  # where the impact times accumulate
trajectory = kronlag.simulate(model, (0, t_inf + 0.5), [h0], [0.0], t_eval=np.linspace(0, t_inf + 0.5, 3001))
impacts = [event for event in trajectory.events if event.kind == "impact"]
contact = next(event for event in trajectory.events if event.kind == "contact")

closed_form = t1 + np.concatenate([[0.0], np.cumsum([2 * e**k * t1 for k in range(1, len(impacts))])])
error = np.max(np.abs(np.array([event.t for event in impacts]) - closed_form) / closed_form)
print(f"{len(impacts)} impacts, impact times against the closed form: max relative error {error:.2e}")
print(f"{contact}; contact force / (m g) = {trajectory.limit_forces[-1, 0] / (m * g):.12f}")

figure, (height, speed) = plt.subplots(2, 1, sharex=True, figsize=(8, 6), layout="constrained")
height.plot(trajectory.t, trajectory.q[:, 0], label="height $y$")
apexes = closed_form[:6] + e ** np.arange(1, 7) * t1
height.plot(apexes, h0 * e ** (2 * np.arange(1, 7)), "o", label="closed form apex $e^{2k} h_0$")
height.set_ylabel("y (m)")
height.legend()
speed.plot(trajectory.t, trajectory.qd[:, 0], color="tab:green")
for k, event in enumerate(impacts):
    for axes in (height, speed):
        axes.axvline(event.t, color="tab:gray", linestyle="--", linewidth=0.6)
    if k < 6:
        speed.annotate(event.side, (event.t, 1.0), xycoords=("data", "axes fraction"), rotation=90, fontsize=7,
                       va="top", ha="right", color="tab:gray")
speed.axvline(contact.t, color="tab:red", linestyle=":", label="persistent contact (Zeno rule)")
speed.set_ylabel("gap speed $\\dot y$ (m/s)")
speed.set_xlabel("time t (s)")
speed.legend(loc="lower right")
figure.suptitle(f"Bouncing ball, e = {e}: impacts at the closed-form times (max rel. error {error:.1e})")
figure.savefig("bouncing_ball.png")
