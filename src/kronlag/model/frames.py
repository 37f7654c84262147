"""Frames and points fixed in a body.

A frame is an origin and a rotation ``R`` that maps frame components to world components
(``r_world = origin + R r_frame``; the rotations themselves are built in
:mod:`kronlag.model.rotations`):

- :class:`Frame`: an origin and a rotation, composed with ``*``;
- :func:`body_frame`, :func:`body_point`: the world position of a point given in
  body coordinates (relative to the body's centre of mass, in its body frame);
- :class:`BodyPoint`: a named point fixed in a body (:meth:`kronlag.System.add_point`).

Their velocities and accelerations are in :mod:`kronlag.symbolic.kinematics`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp

from ..core.errors import ModelError
from .inputs import as_components

if TYPE_CHECKING:
    from .bodies import Body

__all__ = [
    "Frame",
    "body_frame",
    "body_point",
    "BodyPoint",
    "GROUND",
]


@dataclass(frozen=True)
class Frame:
    """A frame: ``origin`` (d,) and ``rotation`` (d, d) in world components, d = 2 or 3.

    ``frame.point(r)`` is ``origin + rotation r``; ``parent * child`` places a frame
    given relative to ``parent`` in the world (``origin_p + R_p origin_c``, ``R_p R_c``).
    """

    origin: sp.ImmutableMatrix
    rotation: sp.ImmutableMatrix

    def __init__(self, origin=(0, 0, 0), rotation=None):
        origin = sp.ImmutableMatrix(as_components(origin, "Frame origin", len(list(origin))))
        if origin.rows not in (2, 3):
            raise ModelError(f"Frame origin: expected 2 or 3 entries, got {origin.rows}")
        rotation = sp.eye(origin.rows) if rotation is None else sp.Matrix(rotation)
        if rotation.shape != (origin.rows, origin.rows):
            raise ModelError(f"Frame rotation: expected shape {(origin.rows, origin.rows)} to match the "
                             f"origin, got {rotation.shape}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "rotation", sp.ImmutableMatrix(rotation))

    @property
    def dimension(self) -> int:
        return self.origin.rows

    def point(self, local) -> sp.Matrix:
        """World position of the point with frame coordinates ``local``."""
        return sp.Matrix(self.origin) + self.rotation * as_components(local, "point", self.dimension)

    def direction(self, local) -> sp.Matrix:
        """World components of the direction with frame components ``local``."""
        return sp.Matrix(self.rotation * as_components(local, "direction", self.dimension))

    def __mul__(self, child: Frame) -> Frame:
        if not isinstance(child, Frame):
            return NotImplemented
        if child.dimension != self.dimension:
            raise ModelError(f"cannot compose a {self.dimension}-d frame with a {child.dimension}-d frame")
        return Frame(self.point(child.origin), self.rotation * child.rotation)

    def inverse(self) -> Frame:
        """The world frame seen from this frame: ``(-R^T origin, R^T)``."""
        return Frame(-self.rotation.T * self.origin, self.rotation.T)


def body_frame(body: Body) -> Frame:
    """The body frame: origin at the centre of mass, axes of the body's rotation.

    A point mass has no orientation; its frame has the world axes.
    """
    return body.pose().frame


def body_point(body: Body, local: Iterable) -> sp.Matrix:
    """World position ``r_c + R s`` of the point with body coordinates ``s`` (from the centre of mass)."""
    return body.point(local)


@dataclass(frozen=True)
class BodyPoint:
    """A named point fixed in a body (see :meth:`kronlag.System.add_point`).

    Attributes
    ----------
    name : str
    body : str
        Name of the body, or ``"ground"`` for a point fixed in the world.
    local : (d,) body coordinates (from the centre of mass, body axes; world coordinates on ground).
    position : (d,) world position, an expression of q.
    """

    name: str
    body: str
    local: sp.ImmutableMatrix
    position: sp.ImmutableMatrix


#: The body name of points fixed in the world (and of the first body of a joint to the ground).
GROUND = "ground"


def make_body_point(system, name: str, body: str, local) -> BodyPoint:
    """The :class:`BodyPoint` ``name`` at body coordinates ``local`` of ``body`` of ``system``."""
    dimension = system.dimension
    if body == GROUND:
        if dimension is None:
            raise ModelError(f"point {name!r} on the ground: the system's dimension is not known yet "
                             "(give gravity or add a body first)")
        position = as_components(local, f"point {name!r} position", dimension)
    else:
        target = system.body(body)
        position = body_point(target, as_components(local, f"point {name!r} on body {body!r}", target.dimension))
    return BodyPoint(name, body, sp.ImmutableMatrix(as_components(local, f"point {name!r}", position.rows)),
                     sp.ImmutableMatrix(position))
