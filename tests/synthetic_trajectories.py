"""Trajectories built from closed-form kinematics, for testing graphics without :func:`kronlag.simulate`.

The motions are kinematically exact (the constraints hold to rounding) but
not dynamically meaningful: multipliers and energies are smooth stand-ins.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from kronlag import models
from kronlag.trajectory import Trajectory

#: Four-bar of a crank-rocker type: crank l1, coupler l2, follower l3, ground l4.
FOUR_BAR_PARAMETERS = {"l1": 1.0, "l2": 3.0, "l3": 2.5, "l4": 3.0, "m1": 1.0, "m2": 3.0, "m3": 2.5,
                       "I1": 0.08, "I2": 2.25, "I3": 1.3, "g": 9.81, "tau": 0.0}
HEAVY_TOP_PARAMETERS = {"m": 1.0, "l": 0.5, "g": 9.81, "Ixx": 0.1, "Izz": 0.05}



class ParameterModel:
    """Stand-in for :class:`kronlag.numeric.NumericModel` with what the graphics read from it:
    the system (``equations.system``) and constant parameter values."""

    time_varying = False

    def __init__(self, system, parameters: dict[str, float]):
        self.equations = SimpleNamespace(system=system)
        self.parameter_names = tuple(parameter.name for parameter in system.parameters)
        self._values = np.array([parameters[name] for name in self.parameter_names])

    def parameter_vector(self, t: float = 0.0) -> np.ndarray:
        return self._values.copy()


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
                      method="closed-form", status=0, message="synthetic", nfev=0, njev=0, steps=len(t),
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
