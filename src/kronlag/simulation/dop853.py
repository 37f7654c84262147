"""scipy's DOP853 advanced step by step for :func:`~kronlag.simulation.stepping.march`, with the
state projected onto the constraints after every accepted step where asked; and its coefficient
tables as C for the compiled DOP853 (``c/dop853.c``), so that both run one set of numbers."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.integrate import DOP853
from scipy.integrate._ivp import dop853_coefficients

from .problem import MultibodyProblem, SolverOptions
from .stepping import Stepper

__all__ = ["DOP853Stepper", "c_coefficients"]


class DOP853Stepper(Stepper):
    """scipy's DOP853 on ``y' = problem.rhs(t, y)``; with ``project``, the state is
    projected onto the constraints after every accepted step (and at outputs)."""

    def __init__(self, problem: MultibodyProblem, options: SolverOptions, project: bool):
        self.problem, self.options, self.project = problem, options, project
        self.solver = DOP853(problem.rhs, problem.t0, problem.y0, problem.t1, rtol=options.rtol,
                             atol=options.atol, max_step=options.max_step)
        self.interpolant = None  # of the last step, built on the first output inside it

    @property
    def t(self) -> float:
        return self.solver.t

    @property
    def y(self) -> np.ndarray:
        return self.solver.y

    def step(self) -> str | None:
        solver = self.solver
        failure = solver.step()
        self.interpolant = None
        if solver.status == "failed":
            return failure
        if self.project:
            # The next step starts from the projected state; its first stage
            # (FSAL) is re-evaluated there, and the step's interpolant joins the
            # projected end points.
            solver.y = self.problem.project(solver.t, solver.y, self.options.projection_tol)
            solver.f = solver.fun(solver.t, solver.y)
        return None

    def interpolate(self, t: float) -> np.ndarray:
        if self.interpolant is None:
            self.interpolant = self.solver.dense_output()
        y = self.interpolant(t)
        return self.problem.project(t, y, self.options.projection_tol) if self.project else y

    def counters(self) -> tuple[int, int]:
        return self.solver.nfev, self.solver.njev

    def limit_step(self, max_step: float) -> None:
        self.solver.max_step = max_step
        self.solver.h_abs = min(self.solver.h_abs, max_step)


@lru_cache(maxsize=1)
def c_coefficients() -> str:
    """The Butcher tableau, error estimators and dense-output coefficients of scipy's DOP853 as C
    arrays (``KL8_A`` (16, 16), ``KL8_B`` (12,), ``KL8_C`` (16,), ``KL8_E3``, ``KL8_E5`` (13,),
    ``KL8_D`` (4, 16)), each number printed so that it reads back exactly."""
    tables = {"A": dop853_coefficients.A, "B": dop853_coefficients.B, "C": dop853_coefficients.C,
              "E3": dop853_coefficients.E3, "E5": dop853_coefficients.E5, "D": dop853_coefficients.D}

    def c_array(value: np.ndarray) -> str:
        if value.ndim == 1:
            return "{" + ", ".join(repr(float(x)) for x in value) + "}"
        return "{" + ",\n    ".join(c_array(row) for row in value) + "}"

    return "".join(f"static const double KL8_{name}{''.join(f'[{n}]' for n in value.shape)} = {c_array(value)};\n"
                   for name, value in tables.items())
