"""Closed chain of four links
==========================

Closed chain of four links (a five-bar loop) in absolute angles.

Simulates the shipped model file and writes ``closed_chain_4.png``.
Run: ``python3 examples/closed_chain_4.py``.
"""

from kronlag.app.workflows import simulate_model
from kronlag.model.builtin import load_example

trajectory = simulate_model(load_example("closed_chain_4"))
print(trajectory.message)
trajectory.plot(path="closed_chain_4.png")
