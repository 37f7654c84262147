"""Universal Robots UR5 arm
========================

Universal Robots UR5 arm falling under gravity from a bent pose, joints unactuated.

Simulates the shipped model file and writes ``ur5.png``.
Run: ``python3 examples/ur5.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("ur5"))
print(trajectory.message)
trajectory.plot(path="ur5.png")
