"""Franka Emika Panda arm
======================

Franka Emika Panda arm falling under gravity from a bent pose, joints unactuated.

Simulates the shipped model file and writes ``panda.png``.
Run: ``python3 examples/panda.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("panda"))
print(trajectory.message)
trajectory.plot(path="panda.png")
