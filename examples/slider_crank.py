"""Slider-crank: the crank torque and the reaction forces at the pins.

Simulates the shipped model file and writes ``slider_crank.png``.
Run: ``python3 examples/slider_crank.py``.
"""

from kronlag.modelfile import load_example
from kronlag.workflows import simulate_model

trajectory = simulate_model(load_example("slider_crank"))
print(trajectory.message)
trajectory.plot(path="slider_crank.png")
