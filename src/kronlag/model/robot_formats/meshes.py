"""Mesh files named by robot descriptions: where they are (:func:`resolve_mesh`) and the box they fill
(:func:`mesh_bounds`), for the animation's drawing of a link.

A mesh ``filename`` is searched for, in this order (:func:`search_roots`):

1. an absolute path or ``file://`` URL as written;
2. a relative path against the robot file's directory;
3. ``package://PACKAGE/rest`` (and SDF's ``model://MODEL/rest`` alike): for each search root ``S`` -
   the ``package_paths=`` given to the loader, then the entries of ``ROS_PACKAGE_PATH``, then the
   robot file's directory and each of its parents - ``S/PACKAGE/rest``, or ``S/rest`` where ``S``
   itself is named ``PACKAGE``.

Meshes are data, read for their vertices only: binary and ASCII STL, Wavefront OBJ (``v`` lines)
and COLLADA (``.dae``: the ``POSITION`` arrays of the geometries the visual scene instances, placed
by their nodes' ``matrix``/``translate``/``scale``, in the file's ``<unit meter>``, ``Y_UP`` turned
to z up), through the same hardened XML parser and size limit as the robot files.  A mesh that is
missing or unreadable is a :class:`RobotFileWarning` and is drawn as a named placeholder.
"""

from __future__ import annotations

import os
import struct
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from urllib.parse import unquote, urlparse
from xml.etree.ElementTree import Element

import numpy as np

from ...core.errors import ModelFileError
from ...core.limits import MAX_MODEL_FILE_BYTES
from .description import RobotFileWarning, Visual

__all__ = ["MESH_SUFFIXES", "mesh_bounds", "resolve_mesh", "search_roots", "with_mesh_bounds"]

#: The mesh formats whose vertices are read (others are drawn as a placeholder).
MESH_SUFFIXES = (".stl", ".obj", ".dae")


def search_roots(source: str | Path, package_paths: Sequence[str | Path] = ()) -> list[Path]:
    """The folders ``package://`` names are looked up in, in order: ``package_paths``,
    ``ROS_PACKAGE_PATH``, then the robot file's directory and its parents."""
    environment = [Path(entry) for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if entry]
    here = Path(source).resolve().parent
    return [Path(path) for path in package_paths] + environment + [here, *here.parents]


def resolve_mesh(filename: str, source: str | Path, package_paths: Sequence[str | Path] = ()) -> Path | None:
    """The file a mesh ``filename`` of the robot file ``source`` names (see the module docstring),
    ``None`` if it is not found."""
    url = urlparse(filename)
    if url.scheme in ("package", "model"):
        package, rest = url.netloc, unquote(url.path).lstrip("/")
        for root in search_roots(source, package_paths):
            for candidate in (root / package / rest, root / rest if root.name == package else None):
                if candidate is not None and candidate.is_file():
                    return candidate
        return None
    path = Path(unquote(url.path) if url.scheme == "file" else filename)
    candidate = path if path.is_absolute() else Path(source).resolve().parent / path
    return candidate if candidate.is_file() else None


def _stl_vertices(data: bytes) -> np.ndarray:
    """The vertices of an STL file, binary (80-byte header, count, 50-byte triangles) or ASCII."""
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * count == len(data):
            records = np.frombuffer(data, dtype=np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)),
                                                          ("attribute", "<u2")]), count=count, offset=84)
            return records["vertices"].reshape(-1, 3).astype(float)
    rows = [line.split()[1:4] for line in data.decode("ascii", "replace").splitlines()
            if line.strip().startswith("vertex")]
    return np.array(rows, dtype=float).reshape(-1, 3)


def _obj_vertices(data: bytes) -> np.ndarray:
    rows = [line.split()[1:4] for line in data.decode("utf-8", "replace").splitlines() if line.startswith("v ")]
    return np.array(rows, dtype=float).reshape(-1, 3)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _node_transform(node: Element) -> np.ndarray:
    """A COLLADA node's own transform (its ``matrix``, ``translate``, ``rotate`` and ``scale`` in order)."""
    result = np.eye(4)
    for child in node:
        tag, values = _local(child.tag), np.array((child.text or "").split(), dtype=float)
        step = np.eye(4)
        if tag == "matrix":
            step = values.reshape(4, 4)
        elif tag == "translate":
            step[:3, 3] = values
        elif tag == "scale":
            step[:3, :3] = np.diag(values)
        elif tag == "rotate":
            axis, angle = values[:3] / np.linalg.norm(values[:3]), np.radians(values[3])
            k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            step[:3, :3] = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
        result = result @ step
    return result


def _dae_vertices(path: Path) -> np.ndarray:
    """The vertices of the geometries a COLLADA file's visual scenes instance, in metres, z up."""
    from .safe_xml import read_xml

    root = read_xml(path).root
    elements = {element.get("id"): element for element in root.iter() if element.get("id")}

    def positions(geometry: Element) -> np.ndarray:
        blocks = []
        for vertices in (e for e in geometry.iter() if _local(e.tag) == "vertices"):
            for put in (e for e in vertices if _local(e.tag) == "input" and e.get("semantic") == "POSITION"):
                source = elements.get((put.get("source") or "").lstrip("#"))
                array = None if source is None else next((e for e in source.iter() if _local(e.tag) == "float_array"),
                                                         None)
                if array is not None:
                    blocks.append(np.array((array.text or "").split(), dtype=float).reshape(-1, 3))
        return np.concatenate(blocks) if blocks else np.zeros((0, 3))

    found: list[np.ndarray] = []

    def visit(node: Element, outer: np.ndarray) -> None:
        placed = outer @ _node_transform(node)
        for child in node:
            tag = _local(child.tag)
            if tag == "node":
                visit(child, placed)
            elif tag == "instance_geometry":
                geometry = elements.get((child.get("url") or "").lstrip("#"))
                if geometry is not None:
                    points = positions(geometry)
                    found.append(points @ placed[:3, :3].T + placed[:3, 3])

    for scene in (e for e in root.iter() if _local(e.tag) == "visual_scene"):
        for node in (e for e in scene if _local(e.tag) == "node"):
            visit(node, np.eye(4))
    vertices = np.concatenate(found) if found else np.zeros((0, 3))
    unit = next((e for e in root.iter() if _local(e.tag) == "unit"), None)
    vertices = vertices * float(unit.get("meter", "1")) if unit is not None else vertices
    up = next((e for e in root.iter() if _local(e.tag) == "up_axis"), None)
    axis = (up.text or "Z_UP").strip() if up is not None else "Z_UP"
    if axis == "Y_UP":  # y up -> z up: a quarter turn about x
        vertices = vertices[:, [0, 2, 1]] * [1, -1, 1]
    elif axis == "X_UP":  # x up -> z up: a quarter turn about y
        vertices = vertices[:, [2, 1, 0]] * [-1, 1, 1]
    return vertices


def mesh_bounds(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and highest corner of the box around a mesh file's vertices (in its own frame).

    Raises
    ------
    ModelFileError
        The file is unreadable, too large, of an unknown format or holds no vertex.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ModelFileError(f"{path}: mesh format {suffix!r} is not read (only {', '.join(MESH_SUFFIXES)})")
    if path.stat().st_size > MAX_MODEL_FILE_BYTES:
        raise ModelFileError(f"{path}: the mesh is larger than {MAX_MODEL_FILE_BYTES} bytes")
    try:
        if suffix == ".dae":
            vertices = _dae_vertices(path)
        else:
            data = path.read_bytes()
            vertices = _stl_vertices(data) if suffix == ".stl" else _obj_vertices(data)
    except (OSError, ValueError) as error:
        raise ModelFileError(f"{path}: cannot read the mesh's vertices: {error}") from None
    vertices = vertices[np.isfinite(vertices).all(axis=1)]
    if not len(vertices):
        raise ModelFileError(f"{path}: the mesh has no vertices")
    return vertices.min(axis=0), vertices.max(axis=0)


def with_mesh_bounds(visuals: Iterable[Visual], source: str, package_paths: Sequence[str | Path] = ()) -> list[Visual]:
    """``visuals`` with every mesh found and read replaced by a ``box`` of its bounds (scaled, placed
    at the box's centre; ``filename`` kept); a mesh that is missing or unreadable stays a named
    placeholder and is a :class:`RobotFileWarning` (one for all of them)."""
    result, missing = [], []
    for visual in visuals:
        if visual.shape != "mesh" or visual.filename is None:
            result.append(visual)
            continue
        path = resolve_mesh(visual.filename, source, package_paths)
        try:
            if path is None:
                raise ModelFileError("not found")
            low, high = mesh_bounds(path)
        except ModelFileError as error:
            missing.append(f"{visual.filename} ({str(error).rsplit(': ', 1)[-1]})")
            result.append(visual)
            continue
        scale = np.array(visual.size if len(visual.size) == 3 else (1.0, 1.0, 1.0))
        corners = np.sort(np.stack([low * scale, high * scale]), axis=0)
        pose = visual.pose.copy()
        pose[:3, 3] = visual.pose[:3, :3] @ corners.mean(axis=0) + visual.pose[:3, 3]
        result.append(Visual(visual.link, visual.body, "box", tuple(map(float, corners[1] - corners[0])), pose,
                             visual.filename))
    if missing:
        warnings.warn(f"{source}: meshes drawn as placeholders: {', '.join(missing)}; searched the file's "
                      "directory and its parents, ROS_PACKAGE_PATH and package_paths=", RobotFileWarning,
                      stacklevel=4)
    return result
