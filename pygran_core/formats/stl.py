"""STL surface meshes (ASCII and binary), one frame per file, parsed with numpy.

A binary file is recognised by its size (84 bytes plus 50 per triangle, as its header
says), whatever its first bytes; anything else must be ASCII (``solid`` ... ``endsolid``).
Points shared by several triangles are merged (exact duplicates, in order of first
appearance). Every defect is a :class:`~pygran_core.errors.ReadError` naming the file, the
frame and, in an ASCII file, the line.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ReadError, UnsupportedFeature, WriteError
from pygran_core.formats.base import Frame, PathLike, Trajectory, TrajectoryWriter

TRIANGLE = 5  # VTK cell type
_BINARY_TRIANGLE = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


def _binary_vertices(data: bytes) -> np.ndarray | None:
    """The ``(T, 3, 3)`` vertices of a binary STL, or None when ``data`` is not one."""
    if len(data) < 84:
        return None
    count = int(np.frombuffer(data, "<u4", 1, 80)[0])
    if len(data) != 84 + _BINARY_TRIANGLE.itemsize * count:
        return None
    records = np.frombuffer(data, _BINARY_TRIANGLE, count, 84)
    return records["vertices"].astype(np.float64)


def _ascii_vertices(data: bytes, fail: Callable[[int, str], ReadError]) -> np.ndarray:
    """The ``(T, 3, 3)`` finite vertices of an ASCII STL; ``fail(line, message)`` makes the error."""
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise fail(line, f"neither a binary STL (by its size) nor ASCII text: byte {exc.start}") from None
    tokens = np.array(text.lower().split())
    if tokens.size == 0 or tokens[0] != "solid":
        raise fail(1, "not an STL file: it does not start with 'solid' and its size is not binary")
    starts = np.flatnonzero(tokens == "vertex")
    facets = int(np.count_nonzero(tokens == "facet"))
    if len(starts) != 3 * facets or (starts.size and starts[-1] + 3 >= tokens.size):
        raise fail(*_locate(text))
    try:
        values = tokens[starts[:, None] + np.arange(1, 4)].astype(np.float64)
    except ValueError:
        raise fail(*_locate(text)) from None
    if not np.isfinite(values).all():
        raise fail(*_locate(text))
    return values.reshape(-1, 3, 3)


def _locate(text: str) -> tuple[int, str]:
    """The line and the nature of the first defect of an ASCII STL (on the error path only)."""
    vertices: int | None = None  # in the open facet
    number = 0
    for number, line in enumerate(text.splitlines(), 1):
        words = line.lower().split()
        if not words:
            continue
        if words[0] == "facet":
            if vertices is not None:
                return number, f"a facet starts inside another, after {vertices} vertices"
            vertices = 0
        elif words[0] == "vertex":
            if vertices is None:
                return number, "a vertex outside a facet"
            try:
                coordinates = [float(w) for w in words[1:]]
            except ValueError:
                return number, f"a vertex coordinate is not a number: {line.strip()[:60]!r}"
            if len(coordinates) != 3 or not np.isfinite(coordinates).all():
                return number, f"a vertex needs 3 finite coordinates: {line.strip()[:60]!r}"
            vertices += 1
        elif words[0] == "endfacet":
            if vertices != 3:
                return number, f"a facet has {vertices or 0} vertices, not 3"
            vertices = None
    if vertices is not None:
        return number, "the file ends inside a facet"
    return number, "facets and vertices do not match (3 vertices per facet)"


class STLTrajectory(Trajectory):
    """Triangle meshes; ``scale`` multiplies every coordinate (e.g. ``1e-3`` for files in mm)."""

    def __init__(self, paths: Sequence[PathLike], scale: float = 1.0) -> None:
        self.paths = [Path(p) for p in paths]
        self.scale = float(scale)

    @property
    def n_frames(self) -> int:
        return len(self.paths)

    def _read_frame(self, index: int) -> Frame:
        path = self.paths[index]

        def fail(line: int | None, message: str) -> ReadError:
            return ReadError(f"{path}: frame {index}{'' if line is None else f', line {line}'}: {message}")

        try:
            data = path.read_bytes()
        except OSError as exc:
            raise fail(None, f"cannot read: {exc}") from exc
        vertices = _binary_vertices(data)
        if vertices is None:
            vertices = _ascii_vertices(data, fail)
        elif not np.isfinite(vertices).all():
            triangle = int(np.flatnonzero(~np.isfinite(vertices).all(axis=(1, 2)))[0])
            raise fail(None, f"binary triangle {triangle} has a coordinate that is not finite")
        if len(vertices) == 0:
            raise fail(None, "the file holds no triangle")
        flat = vertices.reshape(-1, 3)
        unique, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)  # merged points in order of first appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        arrays = {
            "points": unique[order] * self.scale,
            "cells": rank[inverse.reshape(-1)].reshape(-1, 3).astype(np.int64),
            "cell_types": np.full(len(vertices), TRIANGLE, dtype=np.int64),
        }
        return Frame(arrays, attrs={"kind": "mesh", "point_data": [], "cell_data": [], "scale": self.scale})


#: VTK cell types an STL file can hold, split into triangles: triangle, polygon, quad.
SURFACE_CELLS = frozenset({TRIANGLE, 7, 9})


class STLWriter(TrajectoryWriter):
    """Mesh frames as ASCII STL, every coordinate written so that it reads back exactly.

    Polygons and quads become fans of triangles; a frame with other cells (vertices, lines,
    volumes) or particles is refused. An STL file holds one mesh: a ``*`` in the name writes
    a file per frame with its step in its place, else a second frame is refused.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)
        self.count = 0

    def write_frame(self, frame: Frame) -> None:
        if frame.attrs.get("kind") != "mesh" or "cells" not in frame.arrays:
            kind = frame.attrs.get("kind") or "particle"
            raise UnsupportedFeature(f"{self.path}: STL holds surface meshes, not {kind} frames")
        if self.count and "*" not in self.path.name:
            raise UnsupportedFeature(
                f"{self.path}: an STL file holds one mesh; put '*' in the name for a file per frame"
            )
        step = frame.timestep if frame.timestep is not None else self.count
        target = self.path.with_name(self.path.name.replace("*", str(step)))
        try:
            target.write_text(stl_text(surface_triangles(frame.arrays, target)), encoding="ascii")
        except OSError as exc:
            raise WriteError(
                f"{target}: frame {self.count} could not be written: {exc.strerror or exc}"
            ) from None
        self.count += 1


def surface_triangles(arrays: dict[str, np.ndarray], where: PathLike) -> np.ndarray:
    """The ``(T, 3, 3)`` triangles of a mesh frame's surface cells, polygons split as fans."""
    points = np.asarray(arrays["points"], np.float64)
    cells = np.asarray(arrays["cells"], np.int64).reshape(len(arrays["cells"]), -1)
    sizes = (cells >= 0).sum(axis=1)
    types = np.asarray(arrays.get("cell_types", np.where(sizes == 3, TRIANGLE, 7)), np.int64)
    other = sorted(set(types.tolist()) - SURFACE_CELLS)
    if other or (sizes < 3).any():
        raise UnsupportedFeature(
            f"{where}: STL holds triangles; this mesh has cells of VTK type {other or [1, 3]} "
            "(vertices, lines or volumes): write it as .vtk or .vtu"
        )
    corners, owners = [np.empty((0, 3), np.int64)], [np.empty(0, np.int64)]
    for n in np.unique(sizes):
        rows = np.flatnonzero(sizes == n)
        fan = np.array([[0, k, k + 1] for k in range(1, n - 1)])
        corners.append(cells[rows][:, fan].reshape(-1, 3))
        owners.append(np.repeat(rows, n - 2))
    in_cell_order = np.argsort(np.concatenate(owners), kind="stable")
    return points[np.concatenate(corners)[in_cell_order]]


def stl_text(triangles: np.ndarray) -> str:
    """ASCII STL of ``triangles`` with unit normals (zero for a triangle without area)."""
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    lines = ["solid pygran"]
    for normal, corners in zip(normals, triangles):
        lines.append("facet normal " + " ".join(map(repr, normal.tolist())))
        lines.append("outer loop")
        lines.extend("vertex " + " ".join(map(repr, corner.tolist())) for corner in corners)
        lines.extend(("endloop", "endfacet"))
    lines.append("endsolid pygran")
    return "\n".join(lines) + "\n"
