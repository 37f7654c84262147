"""Heavy symmetric top
===================

Heavy symmetric top (z-x-z Euler angles): precession and nutation.

Simulates the shipped model file and writes ``heavy_top.png``.
Run: ``python3 examples/heavy_top.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("heavy_top"))
print(trajectory.message)
trajectory.plot(path="heavy_top.png")
