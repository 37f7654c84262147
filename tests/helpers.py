"""Shared test helpers, the one module test modules import from (no test module imports another).

- the built-in models, derived once per session, and comparison of symbolic matrices, exactly
  or at random numeric points;
- numeric models of the built-in models with random parameter values, on either backend;
- the paper's four-bar and quick-return, and a cart-pole, written as bodies + joints;
- a planar mechanism with redundant constraints (a parallelogram with a third crank);
- ``bench/bench_robots.py`` as a module and the example-robot-data files it names, skipping
  without Pinocchio or the data;
- trajectories built from closed-form kinematics, for testing graphics without
  :func:`kronlag.simulate` (kinematically exact, the constraints hold to rounding, but not
  dynamically meaningful: multipliers and energies are smooth stand-ins).
"""

from __future__ import annotations

import functools
import importlib.util
import random
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import sympy as sp

import kronlag
from kronlag import models
from kronlag.model.free_bodies import free_body, mechanism
from kronlag.numeric import codegen
from kronlag.simulation.trajectory import Trajectory

# -- symbolic models and comparisons ------------------------------------------------------------

#: Every built-in model, by the name the tests use.
MODEL_BUILDERS = {
    "four_bar": models.four_bar,
    "quick_return": models.quick_return,
    "double_pendulum": models.double_pendulum,
    "slider_crank": models.slider_crank,
    "slider_crank_engine": models.slider_crank_engine,
    "five_bar": models.five_bar,
    "heavy_top": models.heavy_top,
    "chaplygin_sleigh": models.chaplygin_sleigh,
    "closed_chain_4_absolute": functools.partial(models.closed_chain, 4, "absolute"),
    "closed_chain_4_relative": functools.partial(models.closed_chain, 4, "relative"),
    "pendulum_cartesian": models.pendulum_cartesian,
    "n_four_bar": models.n_four_bar,
    "andrews_squeezer": models.andrews_squeezer,
    "flyball_governor": models.flyball_governor,
    # Not models.bricard: its symbolic C (2 MB of text) is too large for the 30-digit
    # comparisons of the identity tests; tests/test_iftomm.py checks it numerically.
}

#: Digits of the numeric evaluations and the relative tolerance of comparisons.
DIGITS = 30
RELATIVE_TOLERANCE = 1e-12


@functools.cache
def derived(name: str) -> kronlag.Equations:
    """``kronlag.derive`` of the built-in model ``name`` (cached: Equations are immutable)."""
    return kronlag.derive(MODEL_BUILDERS[name]())


def state_symbols(equations: kronlag.Equations) -> set[sp.Symbol]:
    """Coordinates, speeds, accelerations and multipliers: the symbols that take signed values."""
    return {*equations.coordinates, *equations.speeds, *equations.accelerations,
            *equations.lambdas, *equations.mus}


def is_zero(expr) -> bool:
    """Symbolic test ``expr == 0`` (entry-wise for a matrix) via trig expansion and simplification."""
    entries = expr if isinstance(expr, sp.MatrixBase) else [expr]
    return all(sp.simplify(sp.expand_trig(sp.sympify(entry))) == 0 for entry in entries)


def random_values(symbols, rng: random.Random, signed=frozenset()) -> dict:
    """Random values: uniform in (-3, 3) for the ``signed`` symbols (angles, speeds,
    multipliers), in (0.5, 2) for the others (masses, lengths, inertias...)."""
    return {symbol: rng.uniform(-3, 3) if symbol in signed else rng.uniform(0.5, 2)
            for symbol in symbols}


def evaluate(matrix, values: dict) -> list[sp.Float]:
    """The entries of ``matrix`` (row by row) at ``values``, with :data:`DIGITS` digits."""
    floats = {symbol: sp.Float(value, DIGITS) for symbol, value in values.items()}
    entries = [sp.sympify(entry).xreplace(floats).evalf(DIGITS) for entry in sp.Matrix(matrix)]
    assert all(entry.is_number for entry in entries), "a symbol was left without a value"
    return entries


def assert_numerically_equal(actual, expected, signed=frozenset(), *, points: int = 3, seed: int = 0) -> None:
    """``actual == expected`` at ``points`` random points, relative to the largest entry.

    All free symbols get random values (see :func:`random_values`).
    """
    actual, expected = sp.Matrix(actual), sp.Matrix(expected)
    assert actual.shape == expected.shape
    symbols = actual.free_symbols | expected.free_symbols
    rng = random.Random(seed)
    for _ in range(points):
        values = random_values(sorted(symbols, key=lambda s: s.name), rng, signed)
        a, b = evaluate(actual, values), evaluate(expected, values)
        scale = max((abs(x) for x in a + b), default=0)
        error = max((abs(x - y) for x, y in zip(a, b)), default=0)
        assert error <= RELATIVE_TOLERANCE * scale, (
            f"differ by {error:.3e} (scale {scale:.3e}) at {values}")


# -- numeric models ---------------------------------------------------------------------------------


BACKENDS = ["python", "c"]


needs_compiler = pytest.mark.skipif(codegen.c_compiler() is None, reason="no C compiler")


def backend_params(backends=BACKENDS):
    return [pytest.param(b, marks=needs_compiler) if b == "c" else b for b in backends]


def parameter_values(name: str) -> dict[str, float]:
    """Random values; a symmetric top's axial moment is capped at twice the transverse one
    (the triangle inequality of principal moments, which NumericModel checks)."""
    rng = random.Random(name)
    values = {p.name: value for p, value in random_values(derived(name).parameters, rng).items()}
    if {"Ixx", "Izz"} <= values.keys():
        values["Izz"] = min(values["Izz"], 2 * values["Ixx"])
    return values


@functools.cache
def numeric(name: str, backend: str) -> kronlag.NumericModel:
    return derived(name).numeric(parameter_values(name), backend=backend)


def random_state(eom: kronlag.Equations, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng(seed)
    m = len(eom.coordinates)
    return rng.uniform(-3, 3, m), rng.uniform(-3, 3, m), float(rng.uniform(0, 2))


# -- mechanisms as bodies + joints ------------------------------------------------------------------


FOUR_BAR_VALUES = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1, m2=3, m3=2.5, I1=0.0033, I2=0.09, I3=0.052,
                       g=9.81, tau=0.7)


QUICK_RETURN_VALUES = dict(l_BC=0.2, l_AB=0.3, l_AE=0.8, l_EF=0.3, l_AH=0.75, m1=1.0, m2=2.5, m3=0.8, m4=0.3,
                           m5=0.6, I1=0.004, I2=0.15, I3=0.006, g=9.81, tau=0.5)


def four_bar_by_joints():
    l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau = sp.symbols("l1 l2 l3 l4 m1 m2 m3 I1 I2 I3 g tau")
    bodies = [free_body("crank", mass=m1, inertia=I1), free_body("coupler", mass=m2, inertia=I2),
              free_body("follower", mass=m3, inertia=I3)]
    system = mechanism(bodies, parameters=[l1, l2, l3, l4, m1, m2, m3, I1, I2, I3, g, tau], gravity=(0, -g),
                       name="four_bar_by_joints")
    system.add_joint("revolute", "ground", "crank", at_b=(-l1 / 2, 0))
    system.add_joint("revolute", "crank", "coupler", at_a=(l1 / 2, 0), at_b=(-l2 / 2, 0))
    system.add_joint("revolute", "coupler", "follower", at_a=(l2 / 2, 0), at_b=(l3 / 2, 0))
    system.add_joint("revolute", "ground", "follower", at_a=(l4, 0), at_b=(-l3 / 2, 0))
    system.add_torque("crank", tau, name="drive")
    return system


def quick_return_by_joints():
    l_BC, l_AB, l_AE, l_EF, l_AH = sp.symbols("l_BC l_AB l_AE l_EF l_AH")
    m1, m2, m3, m4, m5, I1, I2, I3, g, tau = sp.symbols("m1 m2 m3 m4 m5 I1 I2 I3 g tau")
    bodies = [free_body("crank", mass=m1, inertia=I1), free_body("rocker", mass=m2, inertia=I2),
              free_body("link", mass=m3, inertia=I3), free_body("D", mass=m4), free_body("G", mass=m5)]
    system = mechanism(bodies, parameters=[l_BC, l_AB, l_AE, l_EF, l_AH, m1, m2, m3, m4, m5, I1, I2, I3, g, tau],
                       gravity=(0, -g), name="quick_return_by_joints")
    system.add_joint("revolute", "ground", "crank", at_a=(0, l_AB), at_b=(-l_BC / 2, 0))
    system.add_joint("revolute", "crank", "D", at_a=(l_BC / 2, 0))
    system.add_joint("pin_in_slot", "rocker", "D", axis=(1, 0))
    system.add_joint("revolute", "ground", "rocker", at_b=(-l_AE / 2, 0))
    system.add_joint("revolute", "rocker", "link", at_a=(l_AE / 2, 0), at_b=(-l_EF / 2, 0))
    system.add_joint("revolute", "link", "G", at_a=(l_EF / 2, 0))
    system.add_joint("pin_in_slot", "ground", "G", at_a=(0, l_AH), axis=(1, 0))
    system.add_torque("crank", tau, name="drive")
    return system


#: The cart-pole of examples/cart_pole.toml: cart M, pole m with its centre of mass lc from the pivot.
CART_POLE_VALUES = dict(M=1.0, m=0.2, lc=0.3, I=0.2 * 0.6 ** 2 / 12, Ic=0.1, g=9.81, u=0.0)


def cart_pole_by_joints():
    """The cart-pole of ``examples/cart_pole.toml`` in Python: a cart on a prismatic joint along x, a
    pole on a revolute joint at the cart's centre (``theta_pole`` = pi/2 upright), a force ``u`` on the cart."""
    M, m, lc, I, Ic, g, u = sp.symbols("M m lc I Ic g u")
    system = mechanism([free_body("cart", mass=M, inertia=Ic), free_body("pole", mass=m, inertia=I)],
                       parameters=[M, m, lc, I, Ic, g, u], gravity=(0, -g), name="cart_pole")
    system.add_joint("prismatic", "ground", "cart", axis=(1, 0), name="rail")
    system.add_joint("revolute", "cart", "pole", at_b=(-lc, 0), name="hinge")
    system.add_force(system.body("cart").position, (u, 0), name="push")
    return system


@functools.cache
def numeric_by_joints(builder, values_name):
    values = {"four_bar": FOUR_BAR_VALUES, "quick_return": QUICK_RETURN_VALUES}[values_name]
    return kronlag.derive(builder()).numeric(values, backend="python")


# -- closed-form trajectories for the graphics ----------------------------------------------------

#: Four-bar of a crank-rocker type: crank l1, coupler l2, follower l3, ground l4.
FOUR_BAR_PARAMETERS = {"l1": 1.0, "l2": 3.0, "l3": 2.5, "l4": 3.0, "m1": 1.0, "m2": 3.0, "m3": 2.5,
                       "I1": 0.08, "I2": 2.25, "I3": 1.3, "g": 9.81, "tau": 0.0}
HEAVY_TOP_PARAMETERS = {"m": 1.0, "l": 0.5, "g": 9.81, "Ixx": 0.1, "Izz": 0.05}



class ParameterModel:
    """Stand-in for :class:`kronlag.numeric.NumericModel` with what the graphics read from it:
    the system (``equations.system``), constant parameter values and no applied forces (``f_Q = 0``,
    so the energy balance's work ``W`` is zero)."""

    time_varying = False

    def __init__(self, system, parameters: dict[str, float]):
        self.equations = SimpleNamespace(system=system, constraints_do_work=False)
        self.parameter_names = tuple(parameter.name for parameter in system.parameters)
        self._values = np.array([parameters[name] for name in self.parameter_names])

    def parameter_vector(self, t: float = 0.0) -> np.ndarray:
        return self._values.copy()

    def f_Q(self, q: np.ndarray, qd: np.ndarray, t: float = 0.0) -> np.ndarray:
        return np.zeros(len(q))

    def evaluate_batch(self, name: str, q: np.ndarray, qd: np.ndarray | None = None, t=0.0) -> np.ndarray:
        if name != "f_Q":
            raise NotImplementedError(f"the stand-in model has no {name}")
        return np.zeros(np.shape(q))


def four_bar_joints(q1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joints B (crank tip) and C (coupler-follower), shape (N, 2), for crank angles ``q1``.

    C is the upper intersection of the circle of radius l2 about B and the
    circle of radius l3 about the ground pivot D = (l4, 0).
    """
    p = FOUR_BAR_PARAMETERS
    b = np.column_stack([p["l1"] * np.cos(q1), p["l1"] * np.sin(q1)])
    to_d = np.array([p["l4"], 0.0]) - b
    distance = np.linalg.norm(to_d, axis=1)
    along = (p["l2"] ** 2 - p["l3"] ** 2 + distance ** 2) / (2 * distance)
    height = np.sqrt(p["l2"] ** 2 - along ** 2)
    unit = to_d / distance[:, None]
    normal = np.column_stack([-unit[:, 1], unit[:, 0]])
    c = b + along[:, None] * unit + height[:, None] * normal
    return b, c


def _trajectory(system, t: np.ndarray, q: np.ndarray, qd: np.ndarray, position_residual: np.ndarray,
                velocity_residual: np.ndarray, parameters: dict[str, float]) -> Trajectory:
    n_constraints = position_residual.shape[1]
    phase = t[:, None] + np.arange(n_constraints)[None, :]
    kinetic = 0.5 * np.sum(qd ** 2, axis=1)
    model = ParameterModel(system, parameters)
    return Trajectory(t=t, q=q, qd=qd, qdd=np.gradient(qd, t, axis=0), lam=np.sin(phase),
                      mu=np.zeros((len(t), 0)), kinetic_energy=kinetic, potential_energy=np.cos(t) - kinetic,
                      position_residual=position_residual, velocity_residual=velocity_residual,
                      coordinate_names=tuple(c.name for c in system.coordinates), model=model,
                      method="closed-form", message="synthetic", nfev=0, njev=0, steps=len(t),
                      wall_time=0.0)


def four_bar_trajectory(t: np.ndarray, *, crank_speed: float = 2 * np.pi) -> Trajectory:
    """The four-bar driven at constant crank speed, ``q1 = crank_speed * t``, from the position analysis."""
    p = FOUR_BAR_PARAMETERS
    q1 = crank_speed * t
    b, c = four_bar_joints(q1)
    q2 = np.unwrap(np.arctan2(c[:, 1] - b[:, 1], c[:, 0] - b[:, 0]))
    q3 = np.unwrap(np.arctan2(c[:, 1], c[:, 0] - p["l4"]))
    # Velocity loop closure: [-l2 sin q2, l3 sin q3; l2 cos q2, -l3 cos q3] [q2d; q3d] = crank_speed l1 [sin q1; -cos q1].
    matrix = np.stack([np.stack([-p["l2"] * np.sin(q2), p["l3"] * np.sin(q3)], axis=-1),
                       np.stack([p["l2"] * np.cos(q2), -p["l3"] * np.cos(q3)], axis=-1)], axis=1)
    rhs = crank_speed * p["l1"] * np.column_stack([np.sin(q1), -np.cos(q1)])
    q23d = np.linalg.solve(matrix, rhs[..., None])[..., 0]
    q = np.column_stack([q1, q2, q3])
    qd = np.column_stack([np.full_like(t, crank_speed), q23d])
    position_residual = np.column_stack([
        p["l1"] * np.cos(q1) + p["l2"] * np.cos(q2) - p["l3"] * np.cos(q3) - p["l4"],
        p["l1"] * np.sin(q1) + p["l2"] * np.sin(q2) - p["l3"] * np.sin(q3)])
    velocity_residual = np.einsum("nij,nj->ni", matrix, q23d) - rhs
    return _trajectory(models.four_bar(), t, q, qd, position_residual, velocity_residual, FOUR_BAR_PARAMETERS)


def heavy_top_trajectory(t: np.ndarray) -> Trajectory:
    """A steadily precessing, spinning top: ``psi = t``, ``theta = 0.4``, ``phi = 20 t``."""
    rates = np.array([1.0, 0.0, 20.0])
    q = np.column_stack([t, np.full_like(t, 0.4), 20.0 * t])
    qd = np.broadcast_to(rates, q.shape).copy()
    empty = np.zeros((len(t), 0))
    return _trajectory(models.heavy_top(), t, q, qd, empty, empty, HEAVY_TOP_PARAMETERS)


# -- a mechanism with redundant constraints -------------------------------------------------------


def double_parallelogram() -> kronlag.System:
    """Three equal cranks (pivots at x = 0, d, 2 d) carrying one coupler: overconstrained (Grübler: 0 dof).

    Coordinates: crank angles q1, q3, q4 and coupler angle q2; crank 2 (q3) pins the
    coupler's midpoint, crank 3 (q4) its end.  Really one degree of freedom.
    """
    cos, sin = sp.cos, sp.sin
    q1, q2, q3, q4 = kronlag.coordinates("q1 q2 q3 q4")
    l, d, m, m_c, inertia, inertia_c, g = sp.symbols("l d m m_c J J_c g")
    system = kronlag.System([q1, q2, q3, q4], parameters=[l, d, m, m_c, inertia, inertia_c, g],
                            gravity=(0, -g), name="double_parallelogram")
    for i, (angle, x) in enumerate(((q1, 0), (q3, d), (q4, 2 * d))):
        system.add_body(kronlag.PlanarBody(f"crank {i + 1}", mass=m, inertia=inertia, angle=angle,
                                           position=(x + l / 2 * cos(angle), l / 2 * sin(angle))))
    start = (l * cos(q1), l * sin(q1))
    system.add_body(kronlag.PlanarBody("coupler", mass=m_c, inertia=inertia_c, angle=q2,
                                       position=(start[0] + d * cos(q2), start[1] + d * sin(q2))))
    for i, (angle, x, distance) in enumerate(((q3, d, d), (q4, 2 * d, 2 * d))):
        system.add_constraint(start[0] + distance * cos(q2) - x - l * cos(angle), name=f"x{i}")
        system.add_constraint(start[1] + distance * sin(q2) - l * sin(angle), name=f"y{i}")
    return system


#: Values of :func:`double_parallelogram`.
DOUBLE_PARALLELOGRAM_VALUES = dict(l=0.7, d=1.3, m=1.2, m_c=2.5, J=0.09, J_c=0.6, g=9.81)


# -- a uniform bar on a pin at one end, as model files (tests of friction, stiction, limits, controllers) -----


def bar_on_a_pin_file(*, name: str, body: str, parameters: str, joint: str = "", tables: str = "") -> str:
    """The model file of a uniform bar ``body`` (mass ``m``, length ``L``, angle ``th``) on the pin ``pivot``
    at one end, under gravity ``g``: ``parameters`` the lines of its ``[parameters]`` (``m``, ``L``, ``g``
    and any other), ``joint`` more lines of the pin's ``[[joints]]`` entry, ``tables`` more tables."""
    return f"""
name = "{name}"
coordinates = ["x", "y", "th"]
gravity = [0, "-g"]

[parameters]
{parameters.strip()}

[[bodies]]
name = "{body}"
type = "planar"
mass = "m"
inertia = "m*L**2/12"
position = ["x", "y"]
angle = "th"

[[joints]]
name = "pivot"
type = "revolute"
body_a = "ground"
body_b = "{body}"
at_b = ["-L/2", 0]
{joint.strip()}
{tables}"""


#: The pin-friction pendulum's parameter values: mass, length, gravity, friction coefficient and pin radius.
PIN_FRICTION_PENDULUM_VALUES = {"m": 2.0, "L": 0.9, "g": 9.81, "mu": 0.1, "r": 0.01}


def pin_friction_pendulum_file(friction: str) -> str:
    """The model file of a uniform bar (mass ``m``, length ``L``) on a pin at one end, whose joint has
    ``friction = <friction>`` (a TOML inline table)."""
    return bar_on_a_pin_file(name="pendulum", body="bar", joint=f"friction = {friction}", parameters="""
m = {value = 2.0, unit = "kg"}
L = {value = 0.9, unit = "m"}
g = {value = 9.81, unit = "m/s^2"}
mu = 0.1
r = {value = 0.01, unit = "m"}
""")


def rod_on_a_stop_file(*, name: str = "pendulum_on_a_stop", parameters: str = "", tables: str = "") -> str:
    """A uniform rod (2 kg, 800 mm) on a pin at one end with the stop ``th >= -pi/2`` (limit ``stop``,
    restitution ``e`` = 0.6); ``parameters`` more lines of ``[parameters]``, ``tables`` more tables."""
    return bar_on_a_pin_file(name=name, body="rod", parameters=f"""
m = {{value = 2, unit = "kg"}}
L = {{value = 800, unit = "mm"}}
g = {{value = 9.81, unit = "m/s^2"}}
e = {{value = 0.6}}
{parameters.strip()}
""", tables=f"""
[[limits]]
name = "stop"
expression = "th"
lower = "-pi/2"
restitution = "e"
{tables}""")


def pin_friction_pendulum(**friction):
    """The same bar built with the API: ``Friction(kinetic=mu, radius=r, **friction)`` on its pin."""
    m, L, g, mu, r = sp.symbols("m L g mu r")
    system = mechanism([free_body("bar", mass=m, inertia=m * L ** 2 / 12)], parameters=[m, L, g, mu, r],
                       gravity=(0, -g))
    system.add_joint("revolute", "ground", "bar", at_b=(-L / 2, 0), name="pivot",
                     friction=kronlag.Friction(kinetic=mu, radius=r, **friction))
    return system


# -- a mass on a line under a sampled PID of its model file (tests of controllers, of the energy balance) --

#: ``m xdd = u``, u from the file's PID on x (setpoint 0.5 m, period 0.02 s), for 2 s.
MASS_ON_A_LINE = """
name = "mass_on_a_line"
coordinates = ["x"]
[parameters]
m = {value = 2.0, unit = "kg"}
u = {value = 0.0, unit = "N"}
[[bodies]]
name = "block"
type = "point"
mass = "m"
position = ["x", 0]
[[forces]]
point = ["x", 0]
force = ["u", 0]
[controller]
type = "pid"
input = "u"
coordinate = "x"
setpoint = 0.5
kp = {value = 8, unit = "N/m"}
ki = 4.0
kd = {value = 3, unit = "N*s/m"}
period = 0.02
[simulation]
t_end = 2.0
"""


# -- bench/bench_robots.py and example-robot-data ----------------------------------------------------


@functools.cache
def robots_bench():
    """``bench/bench_robots.py`` as a module: its robot tables (``ROBOTS``, ``FLOATING``) and the
    Pinocchio references (loaded from its file; ``bench/`` is no package)."""
    spec = importlib.util.spec_from_file_location(
        "bench_robots", Path(__file__).resolve().parents[1] / "bench" / "bench_robots.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def example_robot(relative: str) -> Path:
    """The example-robot-data file at ``relative`` (under its robots folder, e.g.
    ``robots_bench().ROBOTS["ur5"]``); the test is skipped without Pinocchio or the data."""
    pytest.importorskip("pinocchio")
    folder = robots_bench().robots_folder()
    if folder is None:
        pytest.skip("example-robot-data is not installed")
    return folder / relative
