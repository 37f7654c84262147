"""Spatial RSSR linkage: joint reactions
=====================================

Spatial RSSR linkage written as bodies + joints: the joint reactions of its free motion.

A crank on a vertical hinge (``crank_bearing``) is joined, through a coupler with a ball joint
at each end (``ball_1``, ``ball_2``), to a rocker on a horizontal hinge (``rocker_bearing``);
the same linkage as in docs/joints.md.  Each body has its own position and Euler parameters.
The crank is started at 10 rad/s and the linkage moves freely under gravity (along -z) for
0.7 s.  With these lengths the crank cannot turn round (its tip cannot get far enough from the
rocker): it swings between two limit positions, where crank and rocker turn back together and
the joint forces peak.  Writes ``rssr.png``: for every joint the force that its first body
exerts on the second (world components and magnitude) and the couple (ball joints transmit
none, hinges none about their axes).  Run: ``python3 examples/rssr.py``.
"""

import numpy as np
import sympy as sp

import kronlag
from kronlag import frames
from kronlag.model.free_bodies import free_body, mechanism

a, b, c, m1, m2, m3, g = sp.symbols("a b c m1 m2 m3 g")
values = dict(a=0.1, b=0.31, c=0.3, m1=0.5, m2=0.8, m3=0.6, g=9.81)  # m, kg, m/s^2


def rod(name: str, mass, length, axis: str):
    """A slender rod along its body ``axis`` with its own coordinates (position, Euler parameters)."""
    moments = [mass * length ** 2 / 12] * 3
    moments["xyz".index(axis)] = mass * length ** 2 / 1200
    return free_body(name, mass=mass, inertia=sp.diag(*moments), dimension=3)


rssr = mechanism([rod("crank", m1, a, "x"), rod("coupler", m2, b, "x"), rod("rocker", m3, c, "y")],
                 parameters=[a, b, c, m1, m2, m3, g], gravity=(0, 0, -g), name="rssr")
rssr.add_joint("revolute", "ground", "crank", at_b=(-a / 2, 0, 0), axis=(0, 0, 1), name="crank_bearing")
rssr.add_joint("spherical", "crank", "coupler", at_a=(a / 2, 0, 0), at_b=(-b / 2, 0, 0), name="ball_1")
rssr.add_joint("spherical", "rocker", "coupler", at_a=(0, c / 2, 0), at_b=(b / 2, 0, 0), name="ball_2")
rssr.add_joint("revolute", "ground", "rocker", at_a=(0.35, 0, 0.2), at_b=(0, -c / 2, 0), axis=(1, 0, 0),
               name="rocker_bearing")
model = kronlag.derive(rssr).numeric(values)

# Initial guess: crank along x, coupler from the crank tip to the rocker tip, rocker hanging from its hinge.
crank_tip, rocker_tip, rocker_hinge = np.array([0.1, 0, 0]), np.array([0.35, -0.18, -0.04]), np.array([0.35, 0, 0.2])
along = (rocker_tip - crank_tip) / np.linalg.norm(rocker_tip - crank_tip)
coupler_rotation = np.array(frames.axis_angle(np.cross([1, 0, 0], along), np.arccos(along[0])), dtype=float)
rocker_rotation = np.array(frames.elementary_rotation("x", np.arctan2(-0.8, -0.6)), dtype=float)
guess = np.concatenate([[0.05, 0, 0], [1, 0, 0, 0],
                        (crank_tip + rocker_tip) / 2, frames.euler_parameters_of(coupler_rotation),
                        (rocker_tip + rocker_hinge) / 2, frames.euler_parameters_of(rocker_rotation)])
q0, qd0 = model.assemble(guess, fixed=dict(e0_crank=1, e1_crank=0, e2_crank=0, e3_crank=0),
                         qd_fixed=dict(e0_crank=0, e1_crank=0, e2_crank=0, e3_crank=5.0))  # omega_z = 2 e3' = 10 rad/s

trajectory = kronlag.simulate(model, (0, 0.7), q0, qd0, t_eval=np.linspace(0, 0.7, 141))
print(trajectory.message)
print(f"constraint drift {np.max(np.abs(trajectory.position_residual)):.2g}, "
      f"energy drift {np.ptp(trajectory.total_energy):.2g} J")
for joint in rssr.joints:
    reaction = trajectory.reaction(joint.name)
    print(f"{joint.name:>15}: max |F| = {np.max(np.linalg.norm(reaction.force, axis=1)):6.2f} N, "
          f"max |T| = {np.max(np.linalg.norm(reaction.torque, axis=1)):6.3f} N m")
figure = trajectory.plot_reactions(path="rssr.png", units={"t": "s", "energy": "J"})
