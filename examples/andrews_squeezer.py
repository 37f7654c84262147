"""Andrews' squeezing mechanism (IFToMM A03)
=========================================

IFToMM benchmark A03, Andrews' squeezing mechanism, against the published
solution of the Test Set for IVP Solvers at t = 0.03 s.

Writes ``andrews_squeezer.png``.  Run: ``python3 examples/andrews_squeezer.py``.
"""

import numpy as np

from kronlag.benchmarks import iftomm

problem = iftomm.benchmark("A03")
trajectory = problem.simulate(rtol=1e-10, t_eval=np.linspace(0.0, 0.03, 301))
print(f"{trajectory.message} correct digits at t = 0.03 s: {problem.digits(trajectory):.2f}")
trajectory.plot(path="andrews_squeezer.png")
