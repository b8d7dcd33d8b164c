"""STL surface meshes (ASCII and binary), one frame per file, parsed with numpy.

A binary file is recognised by its size (84 bytes plus 50 per triangle, as its header
says), whatever its first bytes; anything else must be ASCII (``solid`` ... ``endsolid``).
Points shared by several triangles are merged (exact duplicates, in order of first
appearance). Every defect is a :class:`~pygran_core.errors.ReadError` naming the file.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ReadError
from pygran_core.io import Frame, PathLike, Trajectory

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


def _ascii_vertices(data: bytes, path: Path) -> np.ndarray:
    """The ``(T, 3, 3)`` vertices of an ASCII STL."""
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        raise ReadError(f"{path}: neither a binary STL (size) nor ASCII text: byte {exc.start}") from exc
    tokens = np.array(text.lower().split())
    if tokens.size == 0 or tokens[0] != "solid":
        raise ReadError(f"{path}: not an STL file: it does not start with 'solid' and its size is not binary")
    starts = np.flatnonzero(tokens == "vertex")
    facets = int(np.count_nonzero(tokens == "facet"))
    if len(starts) != 3 * facets or (starts.size and starts[-1] + 3 >= tokens.size):
        raise ReadError(f"{path}: {facets} facets but {len(starts)} vertices (3 per facet expected)")
    try:
        values = tokens[starts[:, None] + np.arange(1, 4)].astype(np.float64)
    except ValueError as exc:
        raise ReadError(f"{path}: a vertex has a coordinate that is not a number: {exc}") from exc
    return values.reshape(-1, 3, 3)


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
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ReadError(f"{path}: frame {index}: cannot read: {exc}") from exc
        vertices = _binary_vertices(data)
        if vertices is None:
            vertices = _ascii_vertices(data, path)
        if len(vertices) == 0:
            raise ReadError(f"{path}: frame {index}: the file holds no triangle")
        if not np.isfinite(vertices).all():
            raise ReadError(f"{path}: frame {index}: a vertex coordinate is not finite")
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
