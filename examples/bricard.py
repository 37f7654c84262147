"""Bricard mechanism (IFToMM A04)
==============================

IFToMM benchmark A04, Bricard mechanism (a redundant closure constraint), energy drift.

Writes ``bricard.png``.  Run: ``python3 examples/bricard.py``.
"""

from kronlag.benchmarks import iftomm

problem = iftomm.benchmark("A04")
trajectory = problem.simulate()
print(f"{trajectory.message} max error of the {problem.measure}: {problem.error(trajectory):.3g}")
trajectory.plot(path="bricard.png")
