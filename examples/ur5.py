"""Universal Robots UR5 arm falling under gravity from a bent pose, joints unactuated.

Simulates the shipped model file and writes ``ur5.png``.
Run: ``python3 examples/ur5.py``.
"""

from kronlag.modelfile import load_example
from kronlag.workflows import simulate_model

trajectory = simulate_model(load_example("ur5"))
print(trajectory.message)
trajectory.plot(path="ur5.png")
