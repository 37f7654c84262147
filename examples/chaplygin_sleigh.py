"""Chaplygin sleigh: a nonholonomic knife-edge constraint, multiplier mu(t).

Simulates the shipped model file and writes ``chaplygin_sleigh.png``.
Run: ``python3 examples/chaplygin_sleigh.py``.
"""

from kronlag.modelfile import load_example
from kronlag.workflows import simulate_model

trajectory = simulate_model(load_example("chaplygin_sleigh"))
print(trajectory.message)
trajectory.plot(path="chaplygin_sleigh.png")
