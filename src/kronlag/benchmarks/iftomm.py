"""The IFToMM multibody benchmark library, problem set A, with independent references.

Each :class:`Benchmark` bundles a built-in model (:data:`kronlag.models.IFTOMM`)
with its parameter values, a consistent initial state (by ``model.assemble``),
the time span, the benchmark's own error measure and a reference for it that
does not use any of kronlag's integrators:

====  ===========================  ==========================================  ==========================================
code  problem                      measure                                     reference
====  ===========================  ==========================================  ==========================================
A01   simple pendulum (Cartesian)  bob position ``(x, y)`` over 10 s, m       exact solution (Jacobi elliptic functions)
A02   N four-bar mechanism         ``x`` of B0 (tip of the first crank), m     exact reduced 1-DOF motion, DOP853 at 1e-13
A03   Andrews' squeezer            the 7 angles at t = 0.03 s, rad             published (Test Set for IVP Solvers, PSIDE)
A04   Bricard mechanism            energy drift / (sum of m g L)               energy conservation: 0
A05   stiff flyball governor       slider height ``s`` over 10 s, m            scipy Radau at rtol 1e-11 on the same ODE
====  ===========================  ==========================================  ==========================================

The problem descriptions are those of the IFToMM library
(https://www.iftomm-multibody.org/benchmark/) as summarised in the model
docstrings of :mod:`kronlag.models`; Andrews' squeezer takes its parameters,
initial values and reference from the Bari Test Set for IVP Solvers (Mazzia,
Magherini, Iavernaro, release 2.4, problem ``andrews``; also Hairer & Wanner,
Solving ODEs II, Sec. VII.7).

Examples
--------
>>> from kronlag.benchmarks import iftomm
>>> problem = iftomm.benchmark("A02")
>>> round(float(problem.reference(np.array([10.0]))[0, 0]), 7)     # x of B0 at t = 10 s
0.3284581
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.special import ellipj, ellipk

from ..core.errors import InputError
from ..model import builtin as models
from ..model.system import System
from ..numeric.numeric_model import NumericModel
from ..simulation.simulate import simulate
from ..simulation.trajectory import Trajectory
from ..symbolic.derivation import derive

__all__ = ["Benchmark", "benchmark", "BENCHMARKS", "ANDREWS_REFERENCE_Q", "ANDREWS_REFERENCE_QD"]

G = 9.81

#: Tolerances of the independent reference integrations (scipy, not kronlag).
REFERENCE_RTOL = 1e-13


@dataclass(frozen=True)
class Benchmark:
    """One benchmark problem: model, numbers, error measure and reference.

    Attributes
    ----------
    code, title : str
        ``"A01"`` ... and a name.
    build : callable
        Returns the :class:`~kronlag.System`.
    parameters : mapping of str to float
        Value of every parameter of the system.
    q_guess, qd_guess : mapping of str to float
        Initial guesses by coordinate name (0 where missing), passed to
        ``model.assemble`` with ``fixed`` / ``qd_fixed`` held.
    t_span : (t0, t1)
    t_eval : (K,) array
        Output times at which the measure is compared.
    measure : str
        What :meth:`observe` returns, with its unit.
    source : str
        Where the reference comes from.
    observe : callable
        ``observe(trajectory) -> (N, k)``: the measured quantity at ``trajectory.t``.
    reference : callable
        ``reference(t) -> (len(t), k)``: its reference values.
    scale : float or None
        Magnitude for :meth:`digits`: the relative error is ``|error| / scale``,
        or component by component ``|error| / |reference|`` when ``None``.
    """

    code: str
    title: str
    build: Callable[[], System]
    parameters: Mapping[str, float]
    q_guess: Mapping[str, float]
    qd_guess: Mapping[str, float]
    t_span: tuple[float, float]
    t_eval: np.ndarray
    measure: str
    source: str
    observe: Callable[[Trajectory], np.ndarray]
    reference: Callable[[np.ndarray], np.ndarray]
    scale: float | None
    fixed: tuple[str, ...] = ()
    qd_fixed: tuple[str, ...] = ()
    options: Mapping[str, object] = field(default_factory=dict)

    def __repr__(self) -> str:
        return f"Benchmark({self.code!r}, {self.title!r})"

    def numeric(self, *, backend: str = "auto") -> NumericModel:
        """The numeric model with :attr:`parameters` (derived and compiled afresh)."""
        return derive(self.build(**self.options)).numeric(dict(self.parameters), backend=backend)

    def initial_state(self, model: NumericModel) -> tuple[np.ndarray, np.ndarray]:
        """Consistent ``(q0, qd0)`` by ``model.assemble`` from the guesses."""
        names = model.coordinate_names
        q = [self.q_guess.get(name, 0.0) for name in names]
        qd = [self.qd_guess.get(name, 0.0) for name in names]
        return model.assemble(q, fixed={name: self.q_guess.get(name, 0.0) for name in self.fixed},
                              qd_guess=qd, qd_fixed={name: self.qd_guess.get(name, 0.0) for name in self.qd_fixed})

    def simulate(self, model: NumericModel | None = None, *, method: str = "auto", rtol: float = 1e-8,
                 atol: float = 1e-10, t_eval=None) -> Trajectory:
        """:func:`kronlag.simulate` over :attr:`t_span` from :meth:`initial_state`, outputs at
        ``t_eval`` (default :attr:`t_eval`); ``model`` defaults to :meth:`numeric`."""
        model = self.numeric() if model is None else model
        q0, qd0 = self.initial_state(model)
        return simulate(model, self.t_span, q0, qd0, method=method, rtol=rtol, atol=atol,
                        t_eval=self.t_eval if t_eval is None else t_eval)

    def errors(self, trajectory: Trajectory) -> np.ndarray:
        """``observe(trajectory) - reference(t)`` at the trajectory's output times, shape (N, k);
        NaN where the reference is not known."""
        return self.observe(trajectory) - self.reference(np.asarray(trajectory.t))

    def error(self, trajectory: Trajectory) -> float:
        """Largest absolute error of the measure (NaN if there is nothing to compare)."""
        errors = np.abs(self.errors(trajectory))
        return float(np.nanmax(errors)) if np.isfinite(errors).any() else float("nan")

    def digits(self, trajectory: Trajectory) -> float:
        """Correct digits ``-log10`` of the largest relative error (see :attr:`scale`)."""
        errors = np.abs(self.errors(trajectory))
        if not np.isfinite(errors).any():
            return float("nan")
        scale = np.abs(self.reference(np.asarray(trajectory.t))) if self.scale is None else self.scale
        relative = float(np.nanmax(errors / scale))
        return float(-np.log10(relative)) if relative > 0 else float("inf")


# -- A01 simple pendulum ------------------------------------------------------------------------


def pendulum_exact(t: np.ndarray, *, L: float = 1.0, g: float = G) -> np.ndarray:
    """Bob position ``(x, y)`` (len(t), 2) of the pendulum released from rest at ``(-L, 0)``.

    With the angle ``phi`` from the downward vertical (``x = L sin phi``,
    ``y = -L cos phi``) and amplitude pi/2, ``sin(phi/2) = -k sn(K - w t, k^2)``,
    ``k = sin(pi/4)``, ``w = sqrt(g/L)``, ``K = K(k^2)``, so
    ``x = -2 L k sn dn`` and ``y = -L (1 - 2 k^2 sn^2)``.
    """
    parameter = 0.5                                   # k^2 = sin(pi/4)^2
    sn, _, dn, _ = ellipj(ellipk(parameter) - np.sqrt(g / L) * np.asarray(t, dtype=float), parameter)
    k = np.sqrt(parameter)
    return np.column_stack([-2 * L * k * sn * dn, -L * (1 - 2 * parameter * sn**2)])


def _bob(trajectory: Trajectory) -> np.ndarray:
    return np.asarray(trajectory.q)[:, :2]


def _pendulum() -> Benchmark:
    return Benchmark(
        code="A01", title="simple pendulum (Cartesian coordinates)", build=models.pendulum_cartesian,
        parameters={"m": 1.0, "L": 1.0, "g": G}, q_guess={"x": -1.0, "y": 0.0}, qd_guess={}, fixed=("x",),
        t_span=(0.0, 10.0), t_eval=np.linspace(0.0, 10.0, 1001), measure="bob position (x, y), m",
        source="exact solution by Jacobi elliptic functions (scipy.special.ellipj)",
        observe=_bob, reference=pendulum_exact, scale=1.0)


# -- A02 N four-bar mechanism -------------------------------------------------------------------


@functools.cache
def _four_bar_motion(n: int, L: float, m: float, g: float):
    """Dense solution of the reduced motion: all cranks at angle theta, couplers horizontal.

    ``T = 1/2 J_eff theta'^2`` with ``J_eff = (n+1) m L^2/3 + n m L^2`` (cranks
    about their pivots, couplers translating at speed ``L theta'``) and
    ``V = g m L sin(theta) ((n+1)/2 + n)``, so
    ``theta'' = -g m L cos(theta) ((n+1)/2 + n) / J_eff``, ``theta(0) = pi/2``,
    ``theta'(0) = -1``.
    """
    inertia = (n + 1) * m * L**2 / 3 + n * m * L**2
    weight = g * m * L * ((n + 1) / 2 + n)

    def rhs(_t, y):
        return [y[1], -weight * np.cos(y[0]) / inertia]

    solution = solve_ivp(rhs, (0.0, 10.0), [np.pi / 2, -1.0], method="DOP853", rtol=REFERENCE_RTOL,
                         atol=REFERENCE_RTOL, dense_output=True)
    return solution.sol


def four_bar_exact(t: np.ndarray, *, n: int = 2, L: float = 1.0, m: float = 1.0, g: float = G) -> np.ndarray:
    """Position of B0, the tip of the first crank, ``(x, y)`` (len(t), 2), on the physical branch."""
    theta = _four_bar_motion(n, L, m, g)(np.asarray(t, dtype=float))[0]
    return np.column_stack([L * np.cos(theta), L * np.sin(theta)])


FOUR_BAR_PARAMETERS = {"L": 1.0, "m": 1.0, "J": 1.0 / 12, "g": G}


def _b0_x(trajectory: Trajectory) -> np.ndarray:
    """x of B0 = L cos(phi0); ``phi0`` is the first coordinate."""
    return FOUR_BAR_PARAMETERS["L"] * np.cos(np.asarray(trajectory.q)[:, :1])


def _n_four_bar(n: int = 2) -> Benchmark:
    phi = {f"phi{k}": np.pi / 2 for k in range(n + 1)}
    return Benchmark(
        code="A02", title=f"N four-bar mechanism, N = {n}", build=models.n_four_bar, options={"n": n},
        parameters=FOUR_BAR_PARAMETERS, q_guess=phi, qd_guess={"phi0": -1.0},
        fixed=tuple(phi), qd_fixed=("phi0",), t_span=(0.0, 10.0), t_eval=np.linspace(0.0, 10.0, 1001),
        measure="x of B0 (tip of the first crank), m",
        source=f"exact reduced 1-DOF motion (all cranks parallel), scipy DOP853 at rtol {REFERENCE_RTOL:g}",
        observe=_b0_x, reference=lambda t: four_bar_exact(t, n=n)[:, :1], scale=1.0)


# -- A03 Andrews' squeezing mechanism -----------------------------------------------------------

#: Parameters of the test set's ``andrews`` problem (SI units; names as in the test set,
#: its i1..i7 written I1..I7).
ANDREWS_PARAMETERS: dict[str, float] = {
    "m1": 0.04325, "m2": 0.00365, "m3": 0.02373, "m4": 0.00706, "m5": 0.07050, "m6": 0.00706, "m7": 0.05498,
    "xa": -0.06934, "ya": -0.00227, "xb": -0.03635, "yb": 0.03273, "xc": 0.014, "yc": 0.072, "c0": 4530.0,
    "I1": 2.194e-6, "I2": 4.410e-7, "I3": 5.255e-6, "I4": 5.667e-7, "I5": 1.169e-5, "I6": 5.667e-7,
    "I7": 1.912e-5, "d": 28e-3, "da": 115e-4, "e": 2e-2, "ea": 1421e-5, "rr": 7e-3, "ra": 92e-5,
    "l0": 7785e-5, "ss": 35e-3, "sa": 1874e-5, "sb": 1043e-5, "sc": 18e-3, "sd": 2e-2, "ta": 2308e-5,
    "tb": 916e-5, "u": 4e-2, "ua": 1228e-5, "ub": 449e-5, "zf": 2e-2, "zt": 4e-2, "fa": 1421e-5, "mom": 33e-3,
}

#: Consistent initial angles of the test set (beta, theta, gamma, phi, delta, Omega, epsilon), at rest.
ANDREWS_Q0 = (-0.0617138900142764496358948458001, 0.0, 0.455279819163070380255912382449,
              0.222668390165885884674473185609, 0.487364979543842550225598953530,
              -0.222668390165885884674473185609, 1.23054744454982119249735015568)

#: Reference angles and speeds at t = 0.03 s (test set, PSIDE at rtol = atol = 1e-14).
ANDREWS_REFERENCE_Q = (0.1581077119629904e2, -0.1575637105984298e2, 0.4082224013073101e-1,
                       -0.5347301163226948, 0.5244099658805304, 0.5347301163226948, 0.1048080741042263e1)
ANDREWS_REFERENCE_QD = (0.1139920302151208e4, -0.1424379294994111e4, 0.1103291221937134e2,
                        0.1929337464421385e2, 0.5735699284790808, -0.1929337464421385e2, 0.3231791658026955)


def _angles(trajectory: Trajectory) -> np.ndarray:
    return np.asarray(trajectory.q)


def _andrews_reference(t: np.ndarray) -> np.ndarray:
    """The published angles at t = 0.03 s; NaN at other times (no published value)."""
    t = np.asarray(t, dtype=float)
    reference = np.full((len(t), len(ANDREWS_REFERENCE_Q)), np.nan)
    reference[np.abs(t - 0.03) <= 1e-12] = ANDREWS_REFERENCE_Q
    return reference


def _andrews() -> Benchmark:
    names = ("beta", "theta", "gamma", "phi", "delta", "Omega", "epsilon")
    return Benchmark(
        code="A03", title="Andrews' squeezing mechanism", build=models.andrews_squeezer,
        parameters=ANDREWS_PARAMETERS, q_guess=dict(zip(names, ANDREWS_Q0)), qd_guess={}, fixed=("beta",),
        t_span=(0.0, 0.03), t_eval=np.array([0.03]), measure="the 7 angles at t = 0.03 s, rad",
        source="published reference of the Test Set for IVP Solvers (Bari), problem andrews (PSIDE, tol 1e-14)",
        observe=_angles, reference=_andrews_reference, scale=None)


# -- A04 Bricard mechanism ----------------------------------------------------------------------

BRICARD_PARAMETERS = {"L": 1.0, "m": 1.0, "a": 0.1, "g": G}
#: Energy scale of the drift: the sum of m g L over the five rods, J.
BRICARD_ENERGY_SCALE = 5 * BRICARD_PARAMETERS["m"] * G * BRICARD_PARAMETERS["L"]


def _energy_drift(scale: float) -> Callable[[Trajectory], np.ndarray]:
    def drift(trajectory: Trajectory) -> np.ndarray:
        energy = np.asarray(trajectory.kinetic_energy) + np.asarray(trajectory.potential_energy)
        return ((energy - energy[0]) / scale)[:, None] if energy.size else np.empty((0, 1))
    return drift


def _zeros(t: np.ndarray) -> np.ndarray:
    return np.zeros((len(np.atleast_1d(t)), 1))


def _bricard() -> Benchmark:
    return Benchmark(
        code="A04", title="Bricard mechanism", build=models.bricard, parameters=BRICARD_PARAMETERS,
        q_guess={}, qd_guess={}, t_span=(0.0, 10.0), t_eval=np.linspace(0.0, 10.0, 1001),
        measure="energy drift (E(t) - E(0)) / (5 m g L)",
        source="energy conservation (no dissipation): the drift is 0", observe=_energy_drift(BRICARD_ENERGY_SCALE),
        reference=_zeros, scale=1.0)


# -- A05 stiff flyball governor -----------------------------------------------------------------

#: Masses from the density 3000 kg/m^3: 1 x 0.01 x 0.01 m shaft and rods, 0.1 m cube slider.
FLYBALL_PARAMETERS = {"L": 1.0, "w": 0.01, "b": 0.1, "d": 0.05, "m_shaft": 0.3, "m_rod": 0.3, "m_slider": 3.0,
                      "m_ball": 5.0, "k": 8e5, "c": 4e4, "l0": 0.5, "g": G}
FLYBALL_RTOL = 1e-11


@functools.cache
def _flyball_motion():
    """Dense scipy Radau solution of ``M qdd = f_Q - C qd - g`` (r = 0) from kronlag's matrices."""
    problem = _flyball()
    model = problem.numeric()
    q0, qd0 = problem.initial_state(model)
    m = model.m

    def rhs(t, y):
        return np.concatenate([y[m:], model.forward_dynamics(y[:m], y[m:], t).qdd])

    def jacobian(t, y):
        # Central differences with a fixed step: scipy's adaptive num_jac breaks down on the
        # column of the cyclic shaft angle psi, on which nothing depends.
        steps = 1e-6 * np.maximum(1.0, np.abs(y))
        columns = [(rhs(t, y + step * unit) - rhs(t, y - step * unit)) / (2 * step)
                   for step, unit in zip(steps, np.eye(len(y)))]
        return np.column_stack(columns)

    solution = solve_ivp(rhs, problem.t_span, np.concatenate([q0, qd0]), method="Radau", jac=jacobian,
                         rtol=FLYBALL_RTOL, atol=FLYBALL_RTOL, dense_output=True)
    if solution.status != 0:
        raise RuntimeError(f"the flyball governor reference integration failed: {solution.message}")
    return solution.sol


def flyball_reference(t: np.ndarray) -> np.ndarray:
    """Slider height ``s`` (len(t), 1) by scipy's Radau at rtol = atol = 1e-11."""
    return _flyball_motion()(np.asarray(t, dtype=float))[3][:, None]


def _slider(trajectory: Trajectory) -> np.ndarray:
    return np.asarray(trajectory.q)[:, 3:4]


def _flyball() -> Benchmark:
    return Benchmark(
        code="A05", title="stiff flyball governor", build=models.flyball_governor, parameters=FLYBALL_PARAMETERS,
        q_guess={"theta1": np.pi / 6, "theta2": np.pi / 6, "s": 0.5}, qd_guess={"psi": 2 * np.pi},
        t_span=(0.0, 10.0), t_eval=np.linspace(0.0, 10.0, 1001), measure="slider height s, m",
        source=f"scipy Radau at rtol = atol = {FLYBALL_RTOL:g} on the same equations of motion",
        observe=_slider, reference=flyball_reference, scale=0.5)


#: Benchmark factories by code; ``A02`` takes the number of loops ``n``.
BENCHMARKS: dict[str, Callable[..., Benchmark]] = {
    "A01": _pendulum,
    "A02": _n_four_bar,
    "A03": _andrews,
    "A04": _bricard,
    "A05": _flyball,
}


def benchmark(code: str, **options) -> Benchmark:
    """The benchmark ``code`` (``"A01"`` ... ``"A05"``); ``benchmark("A02", n=4)`` for N = 4."""
    if code not in BENCHMARKS:
        raise InputError(f"unknown IFToMM benchmark {code!r}; choose from {', '.join(BENCHMARKS)}")
    return BENCHMARKS[code](**options)
