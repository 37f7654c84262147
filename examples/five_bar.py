"""Five-bar parallel robot: motor torques and joint reactions while the end effector draws a circle.

The end effector of the shipped model ``five_bar`` (base joints 0.2 m apart, links 0.2 m
and 0.3 m, in a vertical plane) goes once round a circle of radius 5 cm in 1 s.  The base
angles come from the closed-form inverse kinematics (each elbow at distance l1 from its base
joint and l2 from the end effector, elbows out); inverse dynamics along them gives the motor
torques on ``theta1``, ``theta2`` and the multipliers, which become the named reactions of
the joints ``elbow_1``, ``elbow_2`` and ``tip``.  Writes ``five_bar.png``: the robot and
the circle, the motor torques and the joint forces.  Run: ``python3 examples/five_bar.py``.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import sympy as sp

import kronlag
from kronlag.modelfile import load_example
from kronlag.reactions import joint_reaction
from kronlag.workflows import inverse_dynamics_along

robot = load_example("five_bar")
values = robot.numeric_values()
d, l1, l2 = values["d"], values["l1"], values["l2"]
centre, radius, omega = (0.0, 0.35), 0.05, 2 * np.pi  # m, m, rad/s
t = kronlag.t
target = sp.Matrix([centre[0] + radius * sp.cos(omega * t), centre[1] + radius * sp.sin(omega * t)])


def base_angle(base_x: float, elbow_side: int) -> sp.Expr:
    """The angle of the link from (base_x, 0) whose far end is l1 from the base and l2 from the target."""
    reach = target - sp.Matrix([base_x, 0])
    distance = sp.sqrt(reach.dot(reach))
    return sp.atan2(reach[1], reach[0]) + elbow_side * sp.acos((l1 ** 2 + distance ** 2 - l2 ** 2) / (2 * l1 * distance))


drives = {"theta1": base_angle(-d / 2, +1), "theta2": base_angle(d / 2, -1)}
model = kronlag.derive(robot.system).numeric(values)
run = inverse_dynamics_along(robot, drives, np.linspace(0, 2 * np.pi / omega, 101), numeric=model)
assert run.success, run.message
path = np.array([model.point_position("end_effector", q) for q in run.q])
expected = np.array([[float(x) for x in target.subs(t, time)] for time in run.t])
print(f"end effector off the circle by at most {np.max(np.abs(path - expected)):.2g} m")
for k, name in enumerate(run.actuated):
    print(f"motor torque on {name}: {run.forces[:, k].min():.3f} .. {run.forces[:, k].max():.3f} N m")

figure, (layout, torques, forces) = plt.subplots(1, 3, figsize=(15, 4.8), width_ratios=(1, 1.2, 1.2),
                                                 layout="constrained")
for k in range(0, len(run.t) - 1, 25):
    links = np.array([model.point_position(name, run.q[k])
                      for name in ("base_1", "elbow_1", "end_effector", "elbow_2", "base_2")])
    layout.plot(*links.T, "o-", color="0.3", alpha=0.4 + 0.6 * k / len(run.t))
layout.plot(*path.T, color="tab:red", label="end effector")
layout.set_aspect("equal")
layout.set_title("five-bar robot, t = 0, 0.25, 0.5, 0.75 s")
layout.set_xlabel("x [m]")
layout.set_ylabel("y [m]")
layout.legend(loc="upper right")
for k, name in enumerate(run.actuated):
    torques.plot(run.t, run.forces[:, k], label=f"motor on {name}")
torques.set_title("motor torques (gravity and inertia)")
torques.set_ylabel("torque [N m]")
for name in ("elbow_1", "elbow_2", "tip"):
    reaction = joint_reaction(model, name, run.t, run.q, run.lam)
    forces.plot(run.t, np.linalg.norm(reaction.force, axis=1), label=f"|F| {name}")
forces.set_title("joint reaction forces")
forces.set_ylabel("force [N]")
for axes in (torques, forces):
    axes.set_xlabel("time [s]")
    axes.grid(True, alpha=0.3)
    axes.legend()
figure.savefig("five_bar.png", dpi=100)
