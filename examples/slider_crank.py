"""Slider-crank
============

Slider-crank: the crank torque and the reaction forces at the pins.

Simulates the shipped model file and writes ``slider_crank.png``.
Run: ``python3 examples/slider_crank.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("slider_crank", apply_drives=False))
print(trajectory.message)
trajectory.plot(path="slider_crank.png")
