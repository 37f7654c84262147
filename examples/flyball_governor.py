"""Flyball governor (IFToMM A05)
=============================

IFToMM benchmark A05, stiff flyball governor, slider height against a Radau reference.

Writes ``flyball_governor.png``.  Run: ``python3 examples/flyball_governor.py``.
"""

from kronlag.benchmarks import iftomm

problem = iftomm.benchmark("A05")
trajectory = problem.simulate()
print(f"{trajectory.message} max error of the {problem.measure}: {problem.error(trajectory):.3g}")
trajectory.plot(path="flyball_governor.png")
