"""Symbolic kinematics of points: velocities and accelerations by Theorem 1 of Van Khang (2011),
``dr/dt = dr/dq (I ⊗ qd)``, in the speed and acceleration symbols ``q1d``, ``q1dd``, ..."""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp

from ..model.symbols import acceleration_symbol, speed_symbol
from .calculus import time_derivative

__all__ = ["point_velocity", "point_acceleration", "point_kinematics"]


def point_velocity(position, coordinates: Sequence[sp.Symbol]) -> sp.Matrix:
    """``v = dr/dt = dr/dq (I_1 ⊗ qd)`` (Theorem 1), in the speed symbols ``q1d, ...``."""
    coordinates = list(coordinates)
    return time_derivative(sp.Matrix(position), coordinates, [speed_symbol(q) for q in coordinates])


def point_acceleration(position, coordinates: Sequence[sp.Symbol]) -> sp.Matrix:
    """``a = dv/dt`` with ``v`` from :func:`point_velocity`, Theorem 1 over ``(q, qd)``.

    In the speed and acceleration symbols: ``a = J qdd + (dJ/dt) qd``, ``J = dr/dq``.
    """
    coordinates = list(coordinates)
    speeds = [speed_symbol(q) for q in coordinates]
    velocity = point_velocity(position, coordinates)
    return time_derivative(velocity, coordinates + speeds, speeds + [acceleration_symbol(q) for q in coordinates])


def point_kinematics(system, name: str) -> dict[str, sp.Matrix]:
    """Symbolic kinematics of the named point of ``system``.

    Returns
    -------
    dict
        ``position`` r (d, 1), ``J = dr/dq`` (d, m) and ``Jd_qd = (dJ/dt) qd`` (d, 1),
        so that ``v = J qd`` and ``a = J qdd + Jd_qd``.
    """
    position = sp.Matrix(system.point(name).position)
    coordinates = list(system.coordinates)
    speeds = sp.Matrix([speed_symbol(q) for q in coordinates])
    jacobian = position.jacobian(coordinates)
    return {"position": position, "J": jacobian,
            "Jd_qd": time_derivative(jacobian, coordinates, speeds) * speeds}
