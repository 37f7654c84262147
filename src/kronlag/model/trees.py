"""Declared kinematic trees: how a System's bodies hang from each other by one-coordinate joints.

A builder that knows its mechanism is a tree of revolute and prismatic joints in joint coordinates
(a chain of links in relative angles, an arm) says so with :meth:`kronlag.System.add_tree_link`, one
:class:`TreeLink` per body, parents first.  The numeric layer may then compute ``M`` and
``C qd + g`` recursively (:func:`kronlag.numeric.codegen.recursive.dynamics_algorithm`) instead of
from the derivation's flat expressions.  A declaration is a claim, not a definition: the bodies'
own expressions stay what the equations mean, and the numeric layer checks the claim against them
(every body's pose at random states) before relying on it.

Frames.  A link's *joint frame* sits in its parent's frame (the parent link's frame; the world for
``"ground"``) at ``origin``, turned by ``rotation``; the *link frame* is the joint frame turned about
``axis`` by the coordinate (revolute) or slid along it by the coordinate (prismatic).  The link frame
has the body's orientation (a planar body's angle, a rigid body's rotation) and holds the body's
centre of mass at ``centre``.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from ..core.errors import KronlagWarning, ModelError
from .inputs import as_components

__all__ = ["TreeLink", "TreeDeclarationWarning", "TREE_JOINT_KINDS", "make_tree_link"]

#: The joints a declared tree takes (one coordinate each).
TREE_JOINT_KINDS = ("revolute", "prismatic")


class TreeDeclarationWarning(KronlagWarning):
    """A declared tree does not describe the System's bodies (a body outside it, or placed otherwise
    than its own expressions say): the flat kernel is used."""


@dataclass(frozen=True)
class TreeLink:
    """One body of a declared tree and the joint that moves it (see the module docstring for frames).

    Attributes
    ----------
    body : str
        The body the link is.
    parent : str
        The parent body, or ``"ground"``.
    joint : str
        ``"revolute"`` or ``"prismatic"``.
    coordinate : sympy.Symbol
        The joint's coordinate (angle or slide).
    origin : sympy.ImmutableMatrix
        (3, 1): the joint frame's origin in the parent's frame (a planar ``(x, y)`` gets ``z = 0``).
    rotation : sympy.ImmutableMatrix
        (3, 3): the joint frame's axes in the parent's frame (planar: a turn about z).
    axis : sympy.ImmutableMatrix
        (3, 1) unit vector in the joint frame (planar revolute: z).
    centre : sympy.ImmutableMatrix
        (3, 1): the body's centre of mass in the link frame.
    planar : bool
        Declared in the plane.
    """

    body: str
    parent: str
    joint: str
    coordinate: sp.Symbol
    origin: sp.ImmutableMatrix
    rotation: sp.ImmutableMatrix
    axis: sp.ImmutableMatrix
    centre: sp.ImmutableMatrix
    planar: bool


def make_tree_link(body: str, coordinate: sp.Symbol, *, parent: str, joint: str, origin, angle, rotation,
                   axis, centre, planar: bool) -> TreeLink:
    """A :class:`TreeLink` from the arguments of :meth:`kronlag.System.add_tree_link` (the System checks
    names and symbols); :class:`~kronlag.core.errors.ModelError` naming the body for a malformed one."""
    what = f"tree link {body!r}"
    if joint not in TREE_JOINT_KINDS:
        raise ModelError(f"{what}: joint must be one of {TREE_JOINT_KINDS}, got {joint!r}")
    size = 2 if planar else 3
    placement = _column(origin, f"{what} origin", size)
    middle = _column(centre, f"{what} centre", size)
    if planar:
        if rotation is not None:
            raise ModelError(f"{what}: a planar link turns by angle=, not rotation=")
        turn = sp.sympify(angle)
        frame = sp.ImmutableMatrix([[sp.cos(turn), -sp.sin(turn), 0], [sp.sin(turn), sp.cos(turn), 0], [0, 0, 1]])
        if joint == "revolute":
            if axis is not None:
                raise ModelError(f"{what}: a planar revolute joint turns about z; give no axis")
            direction = sp.Matrix([0, 0, 1])
        else:
            direction = _column((1, 0) if axis is None else axis, f"{what} axis", 2)
    else:
        if angle != 0:
            raise ModelError(f"{what}: a spatial link is placed by rotation=, not angle=")
        frame = sp.ImmutableMatrix(sp.eye(3) if rotation is None else sp.Matrix(rotation))
        if frame.shape != (3, 3):
            raise ModelError(f"{what} rotation: expected a 3x3 matrix, got shape {frame.shape}")
        if axis is None:
            raise ModelError(f"{what}: a spatial joint needs its axis")
        direction = _column(axis, f"{what} axis", 3)
    if not all(entry.is_number for entry in direction):
        raise ModelError(f"{what} axis: its entries must be numbers, got {tuple(direction)}")
    norm = sp.sqrt(sum(entry**2 for entry in direction))
    if norm == 0:
        raise ModelError(f"{what} axis: it must not be zero")
    return TreeLink(body, parent, joint, coordinate, placement, frame,
                    sp.ImmutableMatrix(direction / norm), middle, planar)


def _column(value, what: str, size: int) -> sp.ImmutableMatrix:
    """``value`` as a (3, 1) column (a planar pair gets ``z = 0``)."""
    entries = list(as_components(value, what, size))
    return sp.ImmutableMatrix([*entries, *([0] * (3 - size))])
