"""Quick-return mechanism
======================

Quick-return mechanism of Van Khang (2011), Section 4.2: crank-driven rocker and slider.

Simulates the shipped model file and writes ``quick_return.png``.
Run: ``python3 examples/quick_return.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("quick_return", apply_drives=False))
print(trajectory.message)
trajectory.plot(path="quick_return.png")
