"""Five-bar parallel robot: motor torques and joint reactions
==========================================================

Five-bar parallel robot: motor torques and joint reactions while the end effector draws a circle.

The end effector of the shipped model ``five_bar`` (base joints 0.2 m apart, links 0.2 m
and 0.3 m, in a vertical plane) is driven once round a circle of radius 5 cm in 1 s: two
drives, on its x and y coordinates.  Inverse dynamics with the actuators on the base
joints ``theta1``, ``theta2`` (the drives only prescribe the motion) gives the motor
torques and the multipliers, which become the named reactions of the joints ``elbow_1``,
``elbow_2`` and ``tip``.  The base angles are checked against the closed-form inverse
kinematics (each elbow at distance l1 from its base joint and l2 from the end effector,
elbows out).  Writes ``five_bar.png``: the robot and the circle, the motor torques and
the joint forces.  Run: ``python3 examples/five_bar.py``.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import sympy as sp

import kronlag
from kronlag.model.builtin import load_example
from kronlag.numeric.reactions import joint_reaction

robot = load_example("five_bar", apply_drives=False)
values = robot.numeric_values()
d, l1, l2 = values["d"], values["l1"], values["l2"]
centre, radius, omega = (0.0, 0.35), 0.05, 2 * np.pi  # m, m, rad/s
t = kronlag.t
target = sp.Matrix([centre[0] + radius * sp.cos(omega * t), centre[1] + radius * sp.sin(omega * t)])
end_effector = robot.system.point("end_effector").position
robot.system.add_drive(end_effector[0], target[0], name="end effector x")
robot.system.add_drive(end_effector[1], target[1], name="end effector y")
model = kronlag.derive(robot.system).numeric(values)
run = kronlag.inverse_dynamics(model, np.linspace(0, 2 * np.pi / omega, 101), robot.guess_vectors()[0],
                               actuated=["theta1", "theta2"])
assert run.success, run.message


def base_angle(base_x: float, elbow_side: int) -> sp.Expr:
    """The angle of the link from (base_x, 0) whose far end is l1 from the base and l2 from the target."""
    reach = target - sp.Matrix([base_x, 0])
    distance = sp.sqrt(reach.dot(reach))
    return sp.atan2(reach[1], reach[0]) + elbow_side * sp.acos((l1 ** 2 + distance ** 2 - l2 ** 2) / (2 * l1 * distance))


closed_form = np.column_stack([sp.lambdify(t, base_angle(x, side))(run.t) for x, side in ((-d / 2, 1), (d / 2, -1))])
path = run.points["end_effector"]["position"]
expected = np.column_stack([sp.lambdify(t, entry)(run.t) for entry in target])
print(f"end effector off the circle by at most {np.max(np.abs(path - expected)):.2g} m")
print(f"base angles off the closed-form inverse kinematics by at most {np.max(np.abs(run.q[:, :2] - closed_form)):.2g} rad")
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
