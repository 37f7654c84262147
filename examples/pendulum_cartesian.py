"""Pendulum in Cartesian coordinates (IFToMM A01)
==============================================

IFToMM benchmark A01, simple pendulum in Cartesian coordinates, against its exact solution.

Writes ``pendulum_cartesian.png``.  Run: ``python3 examples/pendulum_cartesian.py``.
"""

from kronlag.benchmarks import iftomm

problem = iftomm.benchmark("A01")
trajectory = problem.simulate()
print(f"{trajectory.message} max error of the {problem.measure}: {problem.error(trajectory):.3g}")
trajectory.plot(path="pendulum_cartesian.png")
