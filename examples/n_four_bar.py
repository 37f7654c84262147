"""N four-bar mechanism (IFToMM A02)
=================================

IFToMM benchmark A02, N four-bar mechanism (N = 2), against its exact 1-DOF motion.

The mechanism passes through the singular configuration where all bars are
horizontal; the error shows whether the run stayed on the physical branch.

Writes ``n_four_bar.png``.  Run: ``python3 examples/n_four_bar.py``.
"""

from kronlag.benchmarks import iftomm

problem = iftomm.benchmark("A02")
trajectory = problem.simulate()
print(f"{trajectory.message} max error of the {problem.measure}: {problem.error(trajectory):.3g}")
trajectory.plot(path="n_four_bar.png")
