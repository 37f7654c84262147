"""Recursive, structure-keeping ``M`` and ``h`` of the ``"dynamics"`` kernel for kinematic trees.

The derivation (:mod:`kronlag.symbolic.derivation`) writes every body's pose as a flat expression of
all the coordinates above it, so the kernel cannot reuse a parent's rotation, velocity or
acceleration the way a recursive algorithm does.  For a System that is a tree in joint coordinates
(:func:`recursion_of` says which qualify: read from a robot file, or with a declared tree,
:meth:`kronlag.System.add_tree_link`) this module writes the two blocks the way Pinocchio computes
them, in each body's own frame, every intermediate quantity a fresh symbol defined once (a
temporary of the kernel), so that nothing is expanded across the tree:

* ``C qd + g`` by the recursive Newton-Euler algorithm with ``qdd = 0`` and the base accelerating
  at ``-gravity`` (Luh, Walker and Paul 1980): angular velocities and accelerations and the
  accelerations of the body origins outward, forces and moments inward, each joint's generalized
  force their component along its axis;
* ``M`` by the composite-rigid-body algorithm (Walker and Orin 1982): the composite inertia of each
  subtree (mass, first moment, inertia about the body origin), the momentum of a unit speed of each
  joint carried inward to every joint above it.

``h = f_Q - (C qd + g) - d(V_loads)/dq`` with the generalized forces ``f_Q`` and the potentials of
the loads read from the derivation.  ``Phi_q`` and ``gamma`` are differentiated from ``Phi``
without expanding it (:mod:`~kronlag.numeric.codegen.constraint_terms`); the other blocks (``Phi``,
``A``, ...) are the derivation's; one ``symengine.cse`` runs over the definitions and all the
blocks.  The kernels ``g``, ``Phi_q`` and ``gamma`` compiled with the model are written the same way
(:data:`RECURSIVE_KERNELS`).

A robot System qualifies when it is exactly what the reader made (:attr:`RobotDescription.tree_bodies`,
the System's bodies those very objects), in joint coordinates, with a fixed base and revolute,
continuous or prismatic joints only; a System with a declared tree when the declaration passes
:func:`~kronlag.numeric.codegen.tree_links.declared_recursion` (every body in it, placed as its own
expressions say).  Any other System keeps the flat kernel: :func:`recursion_of` returns the reason,
and :func:`dynamics_algorithm` names the choice.
"""

from __future__ import annotations

import warnings
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import symengine as se
import sympy as sp

from ...core.kernels import Block, Kernel, rebuilt
from ...model.frames import GROUND
from ...model.symbols import free_symbols
from ...model.system import System
from ...model.trees import TreeDeclarationWarning
from ..tolerances import TREE_AXIS_RTOL
from .constraint_terms import chained_sums, constraint_blocks
from .tree_links import Recursion, RecursionLink, declared_recursion

if TYPE_CHECKING:
    from .source import KernelSource

__all__ = ["RecursionLink", "Recursion", "recursion_of", "dynamics_algorithm", "bias_forces", "mass_matrix",
           "recursive_kernel", "RECURSIVE_KERNELS", "dependency_order"]

#: The joints the recursion moves along (one coordinate each); the readers merge fixed joints.
RECURSIVE_JOINTS = ("revolute", "continuous", "prismatic")


def recursion_of(system: System) -> tuple[Recursion | None, str]:
    """The tree the recursive kernels run on, or ``None`` with the reason the System keeps the flat
    kernel (the second item: ``"recursive"`` or the reason in words): the declared tree
    (:meth:`~kronlag.System.add_tree_link`, checked against the bodies:
    :func:`~kronlag.numeric.codegen.tree_links.declared_recursion`) or the robot reader's."""
    if getattr(system, "tree", None):  # a System pickled before declared trees has none
        return declared_recursion(system)
    robot = getattr(system, "robot", None)
    if robot is None:
        return None, "not read from a robot file"
    if not robot.tree_bodies:
        return None, "not in the joint coordinates of a tree"
    moving = [joint for joint in robot.joints if joint.coordinate is not None]
    unsupported = [f"{joint.name} ({joint.kind})" for joint in moving if joint.kind not in RECURSIVE_JOINTS]
    if unsupported:
        return None, f"joints the recursion does not take: {', '.join(unsupported)}"
    if [joint.coordinate for joint in moving] != [q.name for q in system.coordinates]:
        return None, "its coordinates are not the joints' coordinates"
    names = [body.name for body in system.bodies]
    if len(set(names)) != len(names) or len(names) != len(robot.tree_bodies) or any(
            robot.tree_bodies.get(body.name) is None or robot.tree_bodies[body.name].body is not body
            for body in system.bodies):
        return None, "its bodies are not those the reader made"
    if system.gravity is not None and (len(system.gravity) != 3 or free_symbols(system.gravity) & {
            *system.coordinates, *system.speeds}):
        return None, "gravity is not a constant 3-vector"
    index = {q.name: i for i, q in enumerate(system.coordinates)}
    links = []
    for joint in moving:
        parent = robot.body_of_link[joint.parent]
        origin, rotation = _in_body_frame(robot, joint.parent, parent)
        step = robot.local_frames[joint.child][1]
        tree_body = robot.tree_bodies.get(joint.child)
        inertial = None if tree_body is None else (tree_body.body.mass, tree_body.centre, tree_body.body.inertia)
        link = RecursionLink(joint.child, joint.kind, parent, origin + rotation * sp.Matrix(step.origin),
                        rotation * sp.Matrix(step.rotation), joint.axis, index[joint.coordinate], inertial)
        if not _moves_as_joint(link, system.coordinates[link.index]):
            return None, f"the frame of link {link.name!r} does not move as its {joint.kind} joint {joint.name!r}"
        links.append(link)
    return Recursion(tuple(links)), "recursive"


def _in_body_frame(robot, link: str, body: str) -> tuple[sp.Matrix, sp.Matrix]:
    """The frame of ``link`` in the frame of its ``body`` (constant: fixed joints between them)."""
    top = robot.root if body == GROUND else body
    origin, rotation = sp.zeros(3, 1), sp.eye(3)
    while link != top:
        link, step = robot.local_frames[link]
        origin, rotation = sp.Matrix(step.origin) + sp.Matrix(step.rotation) * origin, sp.Matrix(step.rotation) * rotation
    return origin, rotation


def _moves_as_joint(link: RecursionLink, coordinate: sp.Symbol, angle: float = 0.7) -> bool:
    """Whether the link's frame turns about its unit axis (revolute) or slides along it (prismatic) as
    its coordinate goes from 0 to ``angle``: what the recursion assumes of every joint."""
    variable = se.Symbol(coordinate.name)

    def at(matrix: sp.Matrix, value: float) -> np.ndarray:
        entries = [float(se.sympify(entry).subs({variable: value})) for entry in matrix]
        return np.array(entries).reshape(matrix.shape)

    axis = np.array(link.axis, dtype=float)
    rotation0, rotation1 = at(link.rotation, 0.0), at(link.rotation, angle)
    shift = at(link.origin, angle).ravel() - at(link.origin, 0.0).ravel()
    if link.kind == "prismatic":
        turn, slide = np.eye(3), rotation0 @ axis * angle
    else:
        cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        turn, slide = np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross, np.zeros(3)
    scale = 1.0 + float(np.max(np.abs(at(link.origin, 0.0))))
    return bool(abs(np.linalg.norm(axis) - 1) <= TREE_AXIS_RTOL
                and np.max(np.abs(rotation0.T @ rotation1 - turn)) <= TREE_AXIS_RTOL
                and np.max(np.abs(shift - slide)) <= TREE_AXIS_RTOL * scale)


def dynamics_algorithm(system: System) -> str:
    """``"recursive"`` where the ``"dynamics"`` kernel's ``M`` and ``h`` come from this module, else
    ``"flat: <reason>"`` (the derivation's matrices)."""
    recursion, reason = recursion_of(system)
    return "recursive" if recursion is not None else f"flat: {reason}"


# -- the algorithms on SymEngine 3-vectors -------------------------------------------------------------

Vector = list


class _Definitions:
    """Fresh symbols for the intermediate quantities, their definitions in order."""

    def __init__(self):
        self.pairs: list[tuple[se.Symbol, se.Basic]] = []

    def __call__(self, expr: se.Basic) -> se.Basic:
        if _trivial(expr):
            return expr
        symbol = se.Symbol(f"tree{len(self.pairs)}")
        self.pairs.append((symbol, expr))
        return symbol

    def vector(self, entries: Sequence[se.Basic]) -> Vector:
        return [self(entry) for entry in entries]


def _trivial(expr: se.Basic) -> bool:
    """A number, a symbol or a number times a symbol: not worth a temporary."""
    if not expr.args or expr.is_Number:
        return True
    return isinstance(expr, se.Mul) and len(expr.args) == 2 and any(arg.is_Number for arg in expr.args) \
        and all(not arg.args for arg in expr.args)


def _cross(a: Vector, b: Vector) -> Vector:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a: Vector, b: Vector) -> se.Basic:
    return se.Add(*(x * y for x, y in zip(a, b)))


def _add(*vectors: Vector) -> Vector:
    return [se.Add(*entries) for entries in zip(*vectors)]


def _scaled(factor: se.Basic, a: Vector) -> Vector:
    return [factor * x for x in a]


def _apply(matrix: list[list[se.Basic]], a: Vector) -> Vector:
    return [se.Add(*(row[k] * a[k] for k in range(3))) for row in matrix]


def _transposed(matrix: list[list[se.Basic]]) -> list[list[se.Basic]]:
    return [[matrix[k][i] for k in range(3)] for i in range(3)]


@dataclass
class _Frame:
    """A link's frame in its parent's as SymEngine entries (composite entries defined once)."""

    rotation: list[list[se.Basic]]  # E: child components -> parent components
    origin: Vector
    axis: Vector
    revolute: bool
    speed: se.Basic
    parent: int | None  # index of the parent link, None: the ground


def _frames(recursion: Recursion, convert: Callable[[sp.Expr], se.Basic], qd: Sequence[se.Basic],
            define: _Definitions) -> list[_Frame]:
    """Each link's frame in its parent's, its axis, speed and parent's position in the list."""
    position = {link.name: k for k, link in enumerate(recursion.links)}
    frames = []
    for link in recursion.links:
        rotation = [[define(convert(link.rotation[i, j])) for j in range(3)] for i in range(3)]
        frames.append(_Frame(rotation, define.vector([convert(x) for x in link.origin]),
                             [_number(x) for x in link.axis], link.kind != "prismatic", qd[link.index],
                             position.get(link.parent)))
    return frames


def bias_forces(recursion: Recursion, frames: list[_Frame], gravity: Vector, define: _Definitions,
                convert: Callable[[sp.Expr], se.Basic], accelerations: Sequence[se.Basic] | None = None
                ) -> list[se.Basic]:
    """``C qd + g`` by the recursive Newton-Euler algorithm (``qdd = 0``, base acceleration ``-gravity``),
    one entry per link (its coordinate's); with the joints' ``accelerations`` (one per link, in the
    links' order) ``M qdd + C qd + g``, the inverse dynamics."""
    zero = se.Integer(0)
    n = len(frames)
    omega: list[Vector] = [[]] * n
    alpha: list[Vector] = [[]] * n
    accel: list[Vector] = [[]] * n
    force: list[Vector] = [[zero] * 3 for _ in range(n)]
    moment: list[Vector] = [[zero] * 3 for _ in range(n)]
    for k, (link, frame) in enumerate(zip(recursion.links, frames)):
        if frame.parent is None:
            w_p, dw_p, a_p = [zero] * 3, [zero] * 3, [-x for x in gravity]
        else:
            w_p, dw_p, a_p = omega[frame.parent], alpha[frame.parent], accel[frame.parent]
        back = _transposed(frame.rotation)
        r = frame.origin
        carried = define.vector(_apply(back, w_p))  # the parent's angular velocity in this frame
        origin_acceleration = _add(a_p, _cross(dw_p, r), _cross(w_p, define.vector(_cross(w_p, r))))
        accel_k = _apply(back, origin_acceleration)
        joint_rate = _scaled(frame.speed, frame.axis)
        joint_acceleration = _scaled(accelerations[k], frame.axis) if accelerations is not None else [zero] * 3
        if frame.revolute:
            omega[k] = define.vector(_add(carried, joint_rate))
            alpha[k] = define.vector(_add(_apply(back, dw_p), _cross(carried, joint_rate), joint_acceleration))
        else:
            omega[k] = carried
            alpha[k] = define.vector(_apply(back, dw_p))
            accel_k = _add(accel_k, _scaled(se.Integer(2), _cross(omega[k], joint_rate)), joint_acceleration)
        accel[k] = define.vector(accel_k)
        if link.inertial is None:
            continue
        mass, centre, inertia = link.inertial
        m = convert(mass)
        c = [_entry(x, convert) for x in centre]
        tensor = [[convert(inertia[i, j]) for j in range(3)] for i in range(3)]
        w, dw = omega[k], alpha[k]
        centre_acceleration = _add(accel[k], _cross(dw, c), _cross(w, define.vector(_cross(w, c))))
        force[k] = define.vector(_scaled(m, centre_acceleration))
        spin = define.vector(_apply(tensor, w))
        moment[k] = _add(_apply(tensor, dw), _cross(w, spin), _cross(c, force[k]))
    result: list[se.Basic] = [zero] * n
    for k in reversed(range(n)):
        frame = frames[k]
        force[k], moment[k] = define.vector(force[k]), define.vector(moment[k])
        result[k] = _dot(frame.axis, moment[k] if frame.revolute else force[k])
        if frame.parent is not None:
            carried = define.vector(_apply(frame.rotation, force[k]))
            p = frame.parent
            force[p] = _add(force[p], carried)
            moment[p] = _add(moment[p], _apply(frame.rotation, moment[k]), _cross(frame.origin, carried))
    return result


def mass_matrix(recursion: Recursion, frames: list[_Frame], define: _Definitions,
                convert: Callable[[sp.Expr], se.Basic]) -> list[list[se.Basic]]:
    """``M`` by the composite-rigid-body algorithm, rows and columns in the links' order."""
    zero = se.Integer(0)
    n = len(frames)
    # composite inertia of each subtree in its root body's frame: mass, first moment, inertia about the origin
    mass: list[se.Basic] = [zero] * n
    first: list[Vector] = [[zero] * 3 for _ in range(n)]
    about_origin: list[list[list[se.Basic]]] = [[[zero] * 3 for _ in range(3)] for _ in range(n)]
    for k, link in enumerate(recursion.links):
        if link.inertial is None:
            continue
        m_sym, centre, inertia = link.inertial
        m = convert(m_sym)
        c = [_entry(x, convert) for x in centre]
        mass[k], first[k] = m, _scaled(m, c)
        squared = _dot(c, c)
        about_origin[k] = [[convert(inertia[i, j]) + m * ((squared if i == j else zero) - c[i] * c[j])
                            for j in range(3)] for i in range(3)]
    for k in reversed(range(n)):
        frame = frames[k]
        mass[k] = define(mass[k])
        first[k] = define.vector(first[k])
        about_origin[k] = [[define(about_origin[k][i][j]) if j >= i else None for j in range(3)] for i in range(3)]
        for i in range(3):
            for j in range(i):
                about_origin[k][i][j] = about_origin[k][j][i]
        p = frame.parent
        if p is None:
            continue
        e, r = frame.rotation, frame.origin
        moved = define.vector(_apply(e, first[k]))  # E h
        half = [[define(_dot(about_origin[k][i], e[j])) for j in range(3)] for i in range(3)]  # I E^T
        rr = _dot(r, r)
        rh = _dot(r, moved)
        mass[p] = mass[p] + mass[k]
        first[p] = _add(first[p], _scaled(mass[k], r), moved)
        for i in range(3):
            for j in range(i, 3):
                rotated = se.Add(*(e[i][a] * half[a][j] for a in range(3)))
                shift = mass[k] * ((rr if i == j else zero) - r[i] * r[j]) + (2 * rh if i == j else zero) \
                    - r[i] * moved[j] - moved[i] * r[j]
                about_origin[p][i][j] = about_origin[p][i][j] + rotated + shift
                about_origin[p][j][i] = about_origin[p][i][j]
    # M's entries by whichever of two ways writes fewer operations for this tree: world-frame momenta
    # (few products an entry, after a world frame a link: long planar chains) or momenta carried up
    # link by link (no world frames: short spatial arms, whose joint rotations are mostly zeros and ones)
    start = len(define.pairs)
    candidates = []
    for way in (_entries_from_world_momenta, _entries_carried_up):
        del define.pairs[start:]
        result = way(frames, first, about_origin, mass, define)
        added = define.pairs[start:]
        cost = (sum(se.count_ops(expr) for _, expr in added)
                + sum(se.count_ops(entry) for row in result for entry in row))
        candidates.append((cost, added, result))
    _, added, result = min(candidates, key=lambda candidate: candidate[0])  # the first on a tie
    define.pairs[start:] = added
    return result


def _entries_from_world_momenta(frames, first, about_origin, mass, define: _Definitions) -> list[list[se.Basic]]:
    """M[k][j] for j = k and its ancestors from the world momentum of a unit speed of joint k (linear L,
    angular A about the world origin) projected on joint j's axis line: s . A + (o x s) . L, or s . L
    for a slide."""
    zero = se.Integer(0)
    n = len(frames)
    # each link's frame in the world (rotation, origin), its joint axis s and the axis' moment o x s there
    world: list[tuple[list[list[se.Basic]], Vector, Vector, Vector]] = []
    for frame in frames:
        if frame.parent is None:
            rotation, origin = frame.rotation, frame.origin
        else:
            parent_rotation, parent_origin = world[frame.parent][:2]
            rotation = [[define(se.Add(*(parent_rotation[i][a] * frame.rotation[a][j] for a in range(3))))
                         for j in range(3)] for i in range(3)]
            origin = define.vector(_add(parent_origin, _apply(parent_rotation, frame.origin)))
        axis = define.vector(_apply(rotation, frame.axis))
        world.append((rotation, origin, axis, define.vector(_cross(origin, axis))))
    result = [[zero] * n for _ in range(n)]
    for k, frame in enumerate(frames):
        s = frame.axis
        if frame.revolute:  # momentum of a unit turn about the axis through the origin
            linear = _cross(s, first[k])
            angular = _apply(about_origin[k], s)
        else:  # of a unit slide along the axis
            linear = _scaled(mass[k], s)
            angular = _cross(first[k], s)
        rotation, origin = world[k][:2]
        momentum = define.vector(_apply(rotation, define.vector(linear)))
        moment = define.vector(_add(_apply(rotation, define.vector(angular)), _cross(origin, momentum)))
        ancestor: int | None = k
        while ancestor is not None:
            _, _, axis, axis_moment = world[ancestor]
            value = (_dot(axis, moment) + _dot(axis_moment, momentum) if frames[ancestor].revolute
                     else _dot(axis, momentum))
            result[k][ancestor] = result[ancestor][k] = define(value)
            ancestor = frames[ancestor].parent
    return result


def _entries_carried_up(frames, first, about_origin, mass, define: _Definitions) -> list[list[se.Basic]]:
    """M[k][j] for j = k and its ancestors from the momentum of a unit speed of joint k, carried up to
    each ancestor's frame in turn and projected on its axis."""
    zero = se.Integer(0)
    n = len(frames)
    result = [[zero] * n for _ in range(n)]
    for k, frame in enumerate(frames):
        s = frame.axis
        if frame.revolute:  # momentum of a unit turn about the axis through the origin
            linear = define.vector(_cross(s, first[k]))
            angular = define.vector(_apply(about_origin[k], s))
        else:  # of a unit slide along the axis
            linear = define.vector(_scaled(mass[k], s))
            angular = define.vector(_cross(first[k], s))
        j = k
        while True:
            joint = frames[j]
            result[k][j] = result[j][k] = define(_dot(joint.axis, angular if joint.revolute else linear))
            if joint.parent is None:
                break
            linear_up = define.vector(_apply(joint.rotation, linear))
            angular = define.vector(_add(_apply(joint.rotation, angular), _cross(joint.origin, linear_up)))
            linear, j = linear_up, joint.parent
    return result


class _InputConverter:
    """SymPy -> SymEngine with the kernel's input names (``q[i]``, ``qd[i]``, ``p[i]``, ``t``) and the
    numbers as doubles, so that constant arithmetic (a mass times a centre, a parallel-axis shift)
    folds as the recursion builds its terms; :meth:`exact` then gives every double the kernel's exact
    form (:class:`~kronlag.core.kernels.ExpressionConverter`: a fraction or a named literal)."""

    def __init__(self, source: KernelSource):
        eq = source.equations
        inputs = [*zip(eq.coordinates, source.q), *zip(eq.speeds, source.qd),
                  *((symbol, se.Symbol(f"p[{i}]")) for i, symbol in enumerate(eq.parameters)),
                  (eq.time, se.Symbol("t"))]
        self.renames = {se.Symbol(symbol.name): target for symbol, target in inputs}
        self.source = source
        self.memo: dict[se.Basic, se.Basic] = {}

    def __call__(self, expr: sp.Expr) -> se.Basic:
        converted = se.sympify(expr)
        return converted.xreplace(self.renames) if converted.free_symbols else converted

    def exact(self, expr: se.Basic) -> se.Basic:
        """``expr`` with its doubles in the kernel's exact form."""
        result = self.memo.get(expr)
        if result is None:
            if isinstance(expr, se.RealDouble):
                result = self.source.convert(sp.Float(float(expr)))
            elif not expr.args:
                result = expr
            else:
                result = rebuilt(expr, [self.exact(arg) for arg in expr.args])
            self.memo[expr] = result
        return result


def _entry(value, convert: Callable[[sp.Expr], se.Basic]) -> se.Basic:
    """A number of a robot file (:func:`_number`) or an expression of a declared tree."""
    return _number(value) if isinstance(value, int | float) else convert(value)


def _number(value: float) -> se.Basic:
    """A number of the file: an integer exactly, else a double."""
    return se.Integer(int(value)) if float(value).is_integer() else se.RealDouble(float(value))


# -- the kernel ------------------------------------------------------------------------------------


#: The kernels written here for a qualifying System (:func:`recursive_kernel`): the forward dynamics,
#: and the compiled-with-the-model kernels whose flat forms grow fastest (``g``: n^2 terms in relative
#: angles; ``Phi_q``, ``gamma``: :mod:`~kronlag.numeric.codegen.constraint_terms`).
RECURSIVE_KERNELS = ("dynamics", "g", "Phi_q", "gamma")

#: The recursion of each KernelSource's System, found once (the declared tree's check evaluates poses).
_RECURSIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _recursion(source: KernelSource) -> tuple[Recursion | None, str]:
    found = _RECURSIONS.get(source)
    if found is None:
        found = _RECURSIONS[source] = recursion_of(source.equations.system)
    return found


def recursive_kernel(source: KernelSource, name: str, blocks: Sequence[Block]) -> Kernel | None:
    """Kernel ``name`` of :data:`RECURSIVE_KERNELS` of ``source`` (a
    :class:`~kronlag.numeric.codegen.KernelSource`) written structure-keeping, or ``None`` when its
    System does not qualify (:func:`recursion_of`; a declared tree that fails its check warns once,
    with the ``"dynamics"`` kernel).  ``blocks`` are the kernel's blocks (``M`` and ``h`` first for
    ``"dynamics"``)."""
    system = source.equations.system
    recursion, reason = _recursion(source)
    if recursion is None:
        if getattr(system, "tree", None) and name == "dynamics":
            warnings.warn(f"system {system.name!r}: the declared kinematic tree is not used ({reason}); "
                          "M and h come from the flat derivation", TreeDeclarationWarning, stacklevel=3)
        return None
    if name in ("Phi_q", "gamma"):
        constraint_sums, named = chained_sums([entry for row in constraint_blocks(source)[name] for entry in row])
        temporaries, reduced = _eliminated(constraint_sums, named)
        return Kernel(name, tuple(blocks), temporaries, reduced, dict(source.convert.constants))
    m = source.m
    zero = se.Integer(0)
    convert = _InputConverter(source)
    define = _Definitions()
    frames = _frames(recursion, convert, source.qd if name == "dynamics" else [zero] * m, define)
    order = [link.index for link in recursion.links]
    bias = [zero] * m  # C qd + g, or g alone at qd = 0
    for a, entry in zip(order, bias_forces(recursion, frames, gravity_vector(system, convert), define, convert)):
        bias[a] = convert.exact(entry)
    load_gradient = load_potential_gradient(source)
    sums: list[tuple[se.Symbol, se.Basic]] = []
    if name == "g":
        entries = [value + slope for value, slope in zip(bias, load_gradient)]
    else:
        assert [block.name for block in blocks[:2]] == ["M", "h"], "the dynamics kernel starts with M and h"
        mass = [[zero] * m for _ in range(m)]
        for a, row in zip(order, mass_matrix(recursion, frames, define, convert)):
            for b, value in zip(order, row):
                mass[a][b] = convert.exact(value)
        forces = source.matrix("f_Q")
        h = [[forces[i][0] - bias[i] - load_gradient[i]] for i in range(m)]
        constraints = constraint_blocks(source)
        others = [constraints.get(block.name) or source.matrix(block.name) for block in blocks[2:]]
        sums, constraint_entries = chained_sums([entry for rows in others for row in rows for entry in row])
        entries = [entry for rows in (mass, h) for row in rows for entry in row] + constraint_entries
    definitions = [(symbol, convert.exact(expr)) for symbol, expr in define.pairs] + sums
    temporaries, outputs = _eliminated(definitions, entries)
    return Kernel(name, tuple(blocks), temporaries, outputs, dict(source.convert.constants))


def gravity_vector(system: System, convert: Callable[[sp.Expr], se.Basic]) -> Vector:
    """The System's gravity as a 3-vector of the kernel (a planar tree's in its plane)."""
    zero = se.Integer(0)
    gravity = [convert(x) for x in system.gravity] if system.gravity is not None else []
    return gravity + [zero] * (3 - len(gravity))


def load_potential_gradient(source: KernelSource) -> list[se.Basic]:
    """``d(V_loads)/dq``: the gradient of the loads' potentials (springs, potentials), which the
    recursion leaves out."""
    potential = sp.Add(*(load.potential() for load in source.equations.system.loads))
    loads = source.convert(potential) if potential != 0 else se.Integer(0)
    return [se.diff(loads, q) for q in source.q]


def _eliminated(definitions: list[tuple[se.Symbol, se.Basic]], outputs: list[se.Basic]
                ) -> tuple[tuple[tuple[se.Symbol, se.Basic], ...], tuple[se.Basic, ...]]:
    """One ``symengine.cse`` over the ``definitions`` and the ``outputs``; the definitions and the
    common subexpressions in an order where each follows what it uses, renamed ``x0, x1, ...`` (the
    printers' temporaries)."""
    replacements, reduced = se.cse([expr for _, expr in definitions] + outputs)
    values = {symbol: expr for symbol, expr in replacements}
    values.update({symbol: expr for (symbol, _), expr in zip(definitions, reduced)})
    final = reduced[len(definitions):]
    used_by_outputs = [used for expr in final for used in expr.free_symbols if used in values]
    order = dependency_order(values, [symbol for symbol, _ in definitions] + used_by_outputs)
    # a temporary that is a symbol or a number times one is written where it is used
    kept: list[se.Symbol] = []
    names: dict[se.Symbol, se.Basic] = {}
    for symbol in order:
        value = _renamed(values[symbol], names)
        if _trivial(value):
            names[symbol] = value
        else:
            values[symbol] = value
            names[symbol] = se.Symbol(f"x{len(kept)}")
            kept.append(symbol)
    temporaries = tuple((names[symbol], values[symbol]) for symbol in kept)
    return temporaries, tuple(_renamed(expr, names) for expr in final)


def dependency_order(values: dict[se.Symbol, se.Basic], roots: Sequence[se.Symbol]) -> list[se.Symbol]:
    """The symbols of ``values`` that ``roots`` use (themselves included), each after the ones its
    value uses (depth first, without recursion: the chains of a long tree are deep)."""
    order: list[se.Symbol] = []
    done: set[se.Symbol] = set()
    for root in roots:
        stack = [(root, False)]
        while stack:
            symbol, ready = stack.pop()
            if symbol in done:
                continue
            if ready:
                done.add(symbol)
                order.append(symbol)
                continue
            stack.append((symbol, True))
            stack.extend((used, False) for used in values[symbol].free_symbols if used in values and used not in done)
    return order


def _renamed(expr: se.Basic, names: dict[se.Symbol, se.Basic]) -> se.Basic:
    """``expr`` with its symbols that ``names`` maps replaced (the map of its own symbols only: SymEngine
    copies the whole map on every call)."""
    own = {symbol: names[symbol] for symbol in expr.free_symbols if symbol in names}
    return expr.xreplace(own) if own else expr
