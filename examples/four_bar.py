"""Four-bar of Van Khang (2011)
============================

Section 4.1 of the paper, end to end.

Derives the equations (corrected Eqs. 29-34), simulates 3 s from the shipped
model file and writes ``four_bar.png`` (q, qd, lambda, energy, drift) and
``four_bar.gif`` (the mechanism moving).  Run: ``python3 examples/four_bar.py``.
"""

import kronlag
from kronlag.app.workflows import simulate_model, summarize
from kronlag.model.builtin import load_example

equations = kronlag.derive(kronlag.models.four_bar()).simplify()
for name in ("M", "C", "g", "Phi_q"):
    print(f"{name} =", getattr(equations, name))

trajectory = simulate_model(load_example("four_bar", apply_drives=False))
print(summarize(trajectory).report())
trajectory.plot(path="four_bar.png")
trajectory.animate("four_bar.gif", fps=20)
