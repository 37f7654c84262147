"""The trees the recursive kernels run on (:mod:`kronlag.numeric.codegen.recursive`), and the
conversion of a declared tree (:meth:`kronlag.System.add_tree_link`) into one, checked first.

A declared tree is a claim about the bodies: the recursion computes ``M`` and ``C qd + g`` from the
links' placements and the bodies' masses and inertias, while the equations are defined by the
bodies' own expressions.  :func:`declared_recursion` therefore accepts the declaration only when
it covers every body and coordinate with bodies whose kinetic energy the recursion reproduces
(planar bodies, rigid bodies, point masses) and when the links, composed from the root, place every
body's centre of mass and orientation where the body's own expressions do, at a few random states
and parameter values, to :data:`~kronlag.numeric.tolerances.TREE_POSE_RTOL`.  The masses and
inertias are the bodies' own (read from them, not declared).  Otherwise it gives the reason, naming
the first body that disagrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import symengine as se
import sympy as sp

from ...core.kernels import ExpressionConverter
from ...model.bodies import PlanarBody, PointMass, RigidBody
from ...model.frames import GROUND
from ...model.symbols import free_symbols
from ...model.system import System
from ...model.trees import TreeLink
from ..tolerances import TREE_POSE_RTOL

__all__ = ["RecursionLink", "Recursion", "declared_recursion"]

#: Random states (and parameter values) at which a declared tree must place every body.
POSE_CHECK_STATES = 3


@dataclass(frozen=True)
class RecursionLink:
    """A moving body of the tree: its name, joint kind, parent body (``"ground"``: the fixed root), its
    frame in the parent body's frame (SymPy: ``origin``, ``rotation``, expressions of its coordinate),
    the joint axis in its own frame, its coordinate's index and its inertial (mass, centre of mass in
    its frame (numbers or expressions of the parameters), central inertia tensor; ``None``: massless)."""

    name: str
    kind: str
    parent: str
    origin: sp.Matrix
    rotation: sp.Matrix
    axis: tuple[float, float, float]
    index: int
    inertial: tuple[sp.Expr, tuple, sp.Matrix] | None


@dataclass(frozen=True)
class Recursion:
    """The tree of a qualifying System, parents before children."""

    links: tuple[RecursionLink, ...]


def declared_recursion(system: System) -> tuple[Recursion | None, str]:
    """The recursion of the System's declared tree (``system.tree``), or ``None`` and the reason it
    cannot be used (naming the body)."""
    linked = {link.body: link for link in system.tree}
    for body in system.bodies:
        if body.name not in linked:
            return None, f"body {body.name!r} is not in the declared tree"
        if type(body) not in (PlanarBody, RigidBody, PointMass):
            return None, f"body {body.name!r} is a {type(body).__name__}, which the recursion does not take"
    bodies = {body.name: body for body in system.bodies}
    missing = [link.body for link in system.tree if link.body not in bodies]
    if missing:
        return None, f"the declared tree's body {missing[0]!r} is not in the system"
    moved = {link.coordinate for link in system.tree}
    unmoved = [q.name for q in system.coordinates if q not in moved]
    if unmoved:
        return None, f"coordinate {unmoved[0]} moves no link of the declared tree"
    if system.gravity is not None and free_symbols(system.gravity) & {*system.coordinates, *system.speeds}:
        return None, "gravity is not constant"
    index = {q: i for i, q in enumerate(system.coordinates)}
    links = tuple(RecursionLink(link.body, link.joint, link.parent, *_joint_motion(link), tuple(link.axis),
                                index[link.coordinate], _inertial(bodies[link.body], link))
                  for link in system.tree)
    wrong = _misplaced_body(system, links, bodies)
    if wrong is not None:
        return None, wrong
    return Recursion(links), "recursive"


def _joint_motion(link: TreeLink) -> tuple[sp.Matrix, sp.Matrix]:
    """The link frame in its parent's: origin and rotation as expressions of the coordinate."""
    q = link.coordinate
    axis = sp.Matrix(link.axis)
    if link.joint == "prismatic":
        return sp.Matrix(link.origin) + sp.Matrix(link.rotation) * axis * q, sp.Matrix(link.rotation)
    cross = sp.Matrix([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    c, s = sp.cos(q), sp.sin(q)
    # R = cos(q) I + sin(q) [a]x + (1 - cos(q)) a a^T, only the nonzero terms (SymPy arithmetic is slow)
    turn = sp.Matrix(3, 3, lambda i, j: sp.Add(*(
        ([c] if i == j else []) + ([cross[i, j] * s] if cross[i, j] != 0 else [])
        + ([axis[i] * axis[j] * (1 - c)] if axis[i] * axis[j] != 0 else []))))
    if link.rotation == sp.eye(3):
        return sp.Matrix(link.origin), turn
    return sp.Matrix(link.origin), sp.Matrix(3, 3, lambda i, j: sp.Add(*(link.rotation[i, k] * turn[k, j]
                                                                        for k in range(3))))


def _inertial(body, link: TreeLink) -> tuple[sp.Expr, tuple, sp.Matrix]:
    """The body's mass, centre in the link frame (declared) and central inertia tensor in that frame
    (the body's: the link frame has the body's orientation)."""
    if isinstance(body, RigidBody):
        tensor = sp.Matrix(body.inertia)
    elif isinstance(body, PlanarBody):
        tensor = sp.diag(0, 0, body.inertia)
    else:
        tensor = sp.zeros(3, 3)
    return body.mass, tuple(link.centre), tensor


def _misplaced_body(system: System, links: tuple[RecursionLink, ...], bodies: dict) -> str | None:
    """The reason the composed links do not place some body as its own expressions do (centre of
    mass, orientation) at :data:`POSE_CHECK_STATES` random states, or ``None``."""
    symbols = [*system.coordinates, *system.parameters]
    convert = ExpressionConverter({symbol: se.Symbol(symbol.name) for symbol in symbols})
    local = [entry for link in links for entry in (*link.origin, *link.rotation)]
    own = []
    for link in links:
        frame = bodies[link.name].pose().frame
        own += [*frame.origin, *frame.rotation]
    centres = [x for link in links for x in (link.inertial[1] if link.inertial is not None else (0, 0, 0))]
    entries = [convert(sp.sympify(entry)) for entry in (*local, *own, *centres)]
    if convert.constants:  # numbers too large for an exact fraction: their values
        large = {se.Symbol(name): se.RealDouble(value) for name, value in convert.constants.items()}
        entries = [entry.xreplace(large) for entry in entries]
    evaluate = se.Lambdify([se.Symbol(symbol.name) for symbol in symbols], entries, backend="lambda")
    rng = np.random.default_rng(19)
    for _ in range(POSE_CHECK_STATES):
        q = rng.uniform(-np.pi, np.pi, len(system.coordinates))
        parameters = rng.uniform(0.5, 1.5, len(system.parameters))
        evaluated = np.asarray(evaluate(np.concatenate([q, parameters])), dtype=float).ravel()
        centre, values = evaluated[-3 * len(links):], evaluated[:-3 * len(links)]
        frames: dict[str, tuple[np.ndarray, np.ndarray]] = {GROUND: (np.zeros(3), np.eye(3))}
        offset = 12 * len(links)
        scale = 1.0 + max(float(np.max(np.abs(values[offset:]))), float(np.max(np.abs(centre), initial=0.0)))
        for k, link in enumerate(links):
            origin, rotation = values[12 * k:12 * k + 3], values[12 * k + 3:12 * k + 12].reshape(3, 3)
            parent_origin, parent_rotation = frames[link.parent]
            world_rotation = parent_rotation @ rotation
            world_origin = parent_origin + parent_rotation @ origin
            frames[link.name] = world_origin, world_rotation
            d = 3 if system.dimension == 3 else 2
            body_position = values[offset:offset + d]
            body_rotation = values[offset + d:offset + d + d * d].reshape(d, d)
            offset += d + d * d
            position = world_origin + world_rotation @ centre[3 * k:3 * k + 3]
            if np.max(np.abs(position[:d] - body_position)) > TREE_POSE_RTOL * scale:
                return (f"the declared tree places the centre of mass of body {link.name!r} at {position[:d]} "
                        f"where the body has it at {body_position} (q = {np.round(q, 3)})")
            if isinstance(bodies[link.name], PointMass):
                continue
            if np.max(np.abs(world_rotation[:d, :d] - body_rotation)) > TREE_POSE_RTOL or (
                    d == 2 and np.max(np.abs(world_rotation[2] - [0, 0, 1])) > TREE_POSE_RTOL):
                return f"the declared tree turns body {link.name!r} otherwise than the body (q = {np.round(q, 3)})"
    return None
