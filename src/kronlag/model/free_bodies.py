"""Bodies placed by their own coordinates, and a :class:`~kronlag.model.system.System` made of them:
a mechanism written as bodies and joints (redundant body coordinates)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp

from ..core.errors import ModelError
from .bodies import Body, PlanarBody, PointMass, RigidBody
from .rotations import euler_parameter_constraint, euler_parameters, euler_sequence
from .system import System

__all__ = ["FreeBody", "free_body", "mechanism"]


@dataclass(frozen=True)
class FreeBody:
    """A body placed by its own coordinates (see :func:`free_body`).

    Attributes
    ----------
    body : Body
        A PlanarBody, RigidBody or PointMass.
    coordinates : tuple of sympy.Symbol
    constraints : tuple of (name, expression)
        Constraints among its own coordinates (Euler-parameter normalization).
    """

    body: Body
    coordinates: tuple[sp.Symbol, ...]
    constraints: tuple[tuple[str, sp.Expr], ...] = ()


def _rotation_coordinates(rotation: str, name: str) -> tuple[tuple[sp.Symbol, ...], sp.Matrix, tuple]:
    if rotation == "euler_parameters":
        e = sp.symbols(f"e0_{name} e1_{name} e2_{name} e3_{name}")
        return e, euler_parameters(*e), ((f"{name}.normalization", euler_parameter_constraint(*e)),)
    angles = sp.symbols(" ".join(f"phi{i + 1}_{name}" for i in range(len(rotation))))
    return tuple(angles), euler_sequence(rotation, angles), ()


def free_body(name: str, *, mass, inertia=None, dimension: int = 2, rotation: str = "euler_parameters",
              simplify: bool = True) -> FreeBody:
    """A body with its own coordinates, for a mechanism written as bodies + joints.

    Planar (``dimension=2``): ``x_<name>, y_<name>`` (centre of mass) and
    ``theta_<name>``.  Spatial: ``x_, y_, z_<name>`` and either the Euler
    parameters ``e0_ .. e3_<name>`` (``rotation="euler_parameters"``, with the
    normalization constraint ``"<name>.normalization"``) or the angles
    ``phi1_<name>, ...`` of an intrinsic sequence such as ``"zxz"`` or ``"xyz"``.
    Without ``inertia`` the body is a point mass (position coordinates only).

    ``name`` must be a Python identifier (it becomes part of the symbol names).
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise ModelError(f"free_body: the name must be an identifier (it names the coordinates), got {name!r}")
    if dimension not in (2, 3):
        raise ModelError(f"free_body {name!r}: dimension must be 2 or 3, got {dimension!r}")
    position = sp.symbols(" ".join(f"{axis}_{name}" for axis in "xyz"[:dimension]))
    if inertia is None:
        return FreeBody(PointMass(name, mass=mass, position=position), tuple(position))
    if dimension == 2:
        theta = sp.Symbol(f"theta_{name}")
        body = PlanarBody(name, mass=mass, inertia=inertia, position=position, angle=theta)
        return FreeBody(body, (*position, theta))
    angles, matrix, constraints = _rotation_coordinates(rotation, name)
    body = RigidBody(name, mass=mass, inertia=inertia, position=position, rotation=matrix, simplify=simplify)
    return FreeBody(body, (*position, *angles), constraints)


def mechanism(bodies: Sequence[FreeBody], *, parameters: Sequence[sp.Symbol] = (), gravity=None,
              coordinates: Sequence[sp.Symbol] = (), name: str = "mechanism") -> System:
    """A :class:`System` of free bodies: their coordinates (then ``coordinates``), the bodies
    and their own constraints; add joints with :meth:`System.add_joint`."""
    all_coordinates = [q for body in bodies for q in body.coordinates] + list(coordinates)
    system = System(all_coordinates, parameters=parameters, gravity=gravity, name=name)
    for free in bodies:
        system.add_body(free.body)
        for constraint_name, expression in free.constraints:
            system.add_constraint(expression, name=constraint_name)
    return system
