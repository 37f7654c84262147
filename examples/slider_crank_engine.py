"""Slider-crank engine: bearing reactions
======================================

Slider-crank engine written as bodies + joints: bearing reactions over one revolution.

The crank of the shipped model file ``slider_crank_engine`` turns at a constant
1500 rpm (a drive: inverse dynamics along the prescribed crank angle); the joints' multipliers
become named reactions (the force the first body of each joint exerts on the second).
Writes ``slider_crank_engine.png``: the magnitude of the main-bearing, crank-pin and
wrist-pin forces, the cylinder's side force on the piston and the drive torque, over
the crank angle.  Run: ``python3 examples/slider_crank_engine.py``.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import kronlag
from kronlag.model.builtin import load_example
from kronlag.numeric.reactions import joint_reaction

engine = load_example("slider_crank_engine")
omega = 1500 * 2 * np.pi / 60  # rad/s
engine.system.add_drive("theta_crank", omega * kronlag.t)  # the crank turns at a constant speed
model = kronlag.derive(engine.system).numeric(engine.values)
times = np.linspace(0, 2 * np.pi / omega, 181)
run = kronlag.inverse_dynamics(model, times, engine.guess_vectors()[0])  # drive torque: run.forces
angle = np.degrees(omega * run.t)

figure, (forces, torque) = plt.subplots(2, 1, sharex=True, figsize=(8, 7), height_ratios=(2, 1))
for name in ("main_bearing", "crank_pin", "wrist_pin"):
    reaction = joint_reaction(model, name, run.t, run.q, run.lam)
    forces.plot(angle, np.linalg.norm(reaction.force, axis=1), label=f"|F| {name}")
    print(f"{name:>12}: max |F| = {np.max(np.linalg.norm(reaction.force, axis=1)):8.1f} N")
side = joint_reaction(model, "cylinder", run.t, run.q, run.lam).force[:, 1]
forces.plot(angle, side, "--", label="cylinder side force Fy on the piston")
forces.set_ylabel("force [N]")
forces.legend()
forces.grid(True)
forces.set_title("Slider-crank engine at 1500 rpm: joint reactions (gravity only, no gas force)")
torque.plot(angle, run.forces[:, 0], color="black")
torque.set_ylabel("drive torque [N m]")
torque.set_xlabel("crank angle [deg]")
torque.grid(True)
figure.tight_layout()
figure.savefig("slider_crank_engine.png", dpi=100)
print(f"drive torque: {run.forces[:, 0].min():.1f} .. {run.forces[:, 0].max():.1f} N m")
