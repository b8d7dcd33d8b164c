"""STL surface meshes (ASCII and binary) through meshio, one frame per file."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ReadError
from pygran_core.io import Frame, PathLike, Trajectory

TRIANGLE = 5  # VTK cell type


class STLTrajectory(Trajectory):
    """Triangle meshes; ``scale`` multiplies every coordinate (e.g. ``1e-3`` for files in mm)."""

    def __init__(self, paths: Sequence[PathLike], scale: float = 1.0) -> None:
        self.paths = [Path(p) for p in paths]
        self.scale = float(scale)

    @property
    def n_frames(self) -> int:
        return len(self.paths)

    def _read_frame(self, index: int) -> Frame:
        import meshio

        path = self.paths[index]
        try:
            with np.errstate(over="ignore"):  # meshio's binary-size probe of an ASCII file
                mesh = meshio.read(path, file_format="stl")
            triangles = np.asarray(mesh.get_cells_type("triangle"), dtype=np.int64).reshape(-1, 3)
        except Exception as exc:  # noqa: BLE001 - meshio raises many kinds on bad files
            raise ReadError(
                f"{path}: frame {index}: not a readable STL file: {type(exc).__name__}: {exc}"
            ) from exc
        points = np.asarray(mesh.points, dtype=np.float64) * self.scale
        arrays = {
            "points": points,
            "cells": triangles,
            "cell_types": np.full(len(triangles), TRIANGLE, dtype=np.int64),
        }
        return Frame(arrays, attrs={"kind": "mesh", "point_data": [], "cell_data": [], "scale": self.scale})
