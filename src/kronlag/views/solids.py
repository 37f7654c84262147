"""The visual geometry of a robot file, as the animation draws it.

A System read from a URDF, MJCF or SDF file (``system.robot``) lists visuals: boxes, cylinders,
spheres, capsules, and meshes drawn by their bounding boxes (:mod:`kronlag.model.robot_formats.meshes`;
a mesh that was not found is a named placeholder and is not drawn).  :func:`solid_points` samples
each visual's surface in its body's frame; the animation moves the samples with the body's frame
(:func:`body_frames` gives its expressions) and fills the convex hull of their projection
(:func:`hull`): the silhouette of a convex solid, drawn far to near.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

if TYPE_CHECKING:
    from ..model.robot_formats.description import Visual
    from ..model.system import System

__all__ = ["body_frames", "hull", "place", "solid_points"]

#: Points around a circle of a cylinder's or capsule's cross-section (and per ring of a sphere).
_AROUND = 16


def _ring(radius: float, height: float) -> np.ndarray:
    angles = np.linspace(0, 2 * np.pi, _AROUND, endpoint=False)
    return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(_AROUND, height)])


def _ball(radius: float) -> np.ndarray:
    rings = [_ring(radius * np.cos(latitude), radius * np.sin(latitude))
             for latitude in np.linspace(-np.pi / 2, np.pi / 2, 7)[1:-1]]
    return np.concatenate([*rings, [[0, 0, radius], [0, 0, -radius]]])


def solid_points(visual: Visual) -> np.ndarray | None:
    """Points of a visual's surface in its body's frame, shape (n, 3); ``None`` for a placeholder."""
    size = visual.size
    if visual.shape == "box":
        local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * np.array(size[:3]) / 2
    elif visual.shape == "sphere":
        local = _ball(size[0])
    elif visual.shape == "cylinder":
        local = np.concatenate([_ring(size[0], -size[1] / 2), _ring(size[0], size[1] / 2)])
    elif visual.shape == "capsule":
        local = np.concatenate([_ball(size[0]) + [0, 0, -size[1] / 2], _ball(size[0]) + [0, 0, size[1] / 2]])
    else:
        return None
    return local @ visual.pose[:3, :3].T + visual.pose[:3, 3]


def body_frames(system: System) -> dict[str, list[sp.Expr]]:
    """The origin and rotation (12 expressions, the rotation by rows) of every body that carries a
    visual (``"ground"``: the world's), from ``system.robot.frames``."""
    robot = system.robot
    if robot is None:
        return {}
    frames = {}
    for visual in robot.visuals:
        if visual.body in frames or solid_points(visual) is None:
            continue
        frame = robot.frames.get(visual.body)
        origin, rotation = (sp.zeros(3, 1), sp.eye(3)) if frame is None else (frame.origin, frame.rotation)
        frames[visual.body] = [*sp.Matrix(origin), *sp.Matrix(rotation)]
    return frames


def place(system: System, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The visuals' points in the world at T times: ``values`` are the 12 frame entries of each body
    (:func:`body_frames`) at those times, (T, 12); the result maps ``"<link> <shape>"`` (numbered
    if a link has several) to (T, n, 3)."""
    assert system.robot is not None
    placed: dict[str, np.ndarray] = {}
    for visual in system.robot.visuals:
        local = solid_points(visual)
        if local is None:
            continue
        frame = values[visual.body]
        origin, rotation = frame[:, :3], frame[:, 3:].reshape(-1, 3, 3)
        label = f"{visual.link} {visual.shape}"
        label = next(f"{label} {k}" for k in range(1, len(placed) + 2) if f"{label} {k}" not in placed) \
            if label in placed else label
        placed[label] = np.einsum("tij,nj->tni", rotation, local) + origin[:, None, :]
    return placed


def _turn(a, b, c) -> float:
    """The z component of ``(b - a) x (c - a)``: positive for a left turn."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def hull(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2-D points (n, 2), counter-clockwise (Andrew's monotone chain)."""
    order = sorted(set(map(tuple, np.asarray(points, dtype=float))))
    if len(order) <= 2:
        return np.array(order)

    def half(sequence):
        chain: list = []
        for point in sequence:
            while len(chain) >= 2 and _turn(chain[-2], chain[-1], point) <= 0:
                chain.pop()
            chain.append(point)
        return chain

    lower, upper = half(order), half(reversed(order))
    return np.array(lower[:-1] + upper[:-1])
