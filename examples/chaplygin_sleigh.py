"""Chaplygin sleigh
================

Chaplygin sleigh: a nonholonomic knife-edge constraint, multiplier mu(t).

Simulates the shipped model file and writes ``chaplygin_sleigh.png``.
Run: ``python3 examples/chaplygin_sleigh.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("chaplygin_sleigh"))
print(trajectory.message)
trajectory.plot(path="chaplygin_sleigh.png")
