"""Double pendulum
===============

Double pendulum of two uniform rods: energy is conserved, the motion is chaotic.

Simulates the shipped model file and writes ``double_pendulum.png``.
Run: ``python3 examples/double_pendulum.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("double_pendulum"))
print(trajectory.message)
trajectory.plot(path="double_pendulum.png")
