"""Mesh: a SubSystem of surface cells (wall triangles or polygons) sharing a set of points.

The elements are the cells: ``cells`` (n_cells, k) holds each cell's point indices (rows of
cells with fewer than k points are padded with -1, as the VTK reader gives them) and every
cell-data array (e.g. LIGGGHTS ``meshid``, ``v``, the reader's ``cell_types``) has one row
per cell, so slicing, iteration and ``len`` act on cells. ``points`` (n_points, 3) and the
point-data arrays are metadata shared by every slice (cell indices stay valid);
:meth:`translate` and :meth:`scale` move the points by default.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from pygran_core.analysis.subsystem import DIMENSIONS, SubSystem, _frozen
from pygran_core.errors import ConfigError


class Mesh(SubSystem):
    """``Mesh(points=(n, 3), cells=(m, k), point_data={name: (n, ...)}, **cell_data)``."""

    coordinate_keys = ("points",)
    dimensions: Mapping[str, str] = {**DIMENSIONS, "points": "length", "v": "velocity"}

    def __init__(
        self,
        points: Any = None,
        cells: Any = None,
        point_data: Mapping[str, Any] | None = None,
        **data: Any,
    ) -> None:
        if points is None and self._copy_source(dict(data)) is None:
            raise ConfigError("Mesh needs points=(n, 3) and cells=(m, k), or a Mesh to copy (Mesh=other)")
        if cells is not None:
            data["cells"] = np.asarray(cells, dtype=np.intp).reshape(len(cells), -1)
        super().__init__(**data)
        if points is None:
            return
        arrays = {"points": np.asarray(points, dtype=float).reshape(-1, 3), **(point_data or {})}
        n_points = len(arrays["points"])
        wrong = {k: len(v) for k, v in arrays.items() if len(v) != n_points}
        if wrong:
            raise ConfigError(f"Mesh point data must have one row per point ({n_points}): {wrong}")
        clash = sorted(set(arrays) & set(self._fields))
        if clash:
            raise ConfigError(f"Mesh point data and cell data share the names {clash}")
        cells = self._fields.get("cells")
        if cells is not None and len(cells) and not -1 <= cells.min() <= cells.max() < n_points:
            raise ConfigError(
                f"Mesh cells refer to points {self.cells.min()}..{self.cells.max()}; there are {n_points}"
            )
        self._meta.update({k: _frozen(v) for k, v in arrays.items()}, point_keys=tuple(arrays))

    def nCells(self) -> int:
        """Number of cells."""
        return len(self)

    def nPoints(self) -> int:
        """Number of points (shared by every slice of this mesh)."""
        return len(self.points)

    @property
    def point_data(self) -> dict[str, np.ndarray]:
        """Point arrays by name, ``points`` included."""
        return {key: self._meta[key] for key in self._meta.get("point_keys", ())}

    @property
    def cell_data(self) -> dict[str, np.ndarray]:
        """Per-cell arrays by name, ``cells`` excluded."""
        return {key: value for key, value in self._fields.items() if key != "cells"}

    def _vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """(n_cells, k, 3) vertex coordinates, padding replaced by each cell's first vertex, and
        the (n_cells, k) mask of real vertices."""
        cells = np.asarray(self.cells).reshape(len(self), -1)
        real = cells >= 0
        return self.points[np.where(real, cells, cells[:, :1])], real

    def computeAreas(self) -> np.ndarray:
        """Area of each (planar) polygonal cell, from its vector area ``|sum p_j x p_j+1| / 2``."""
        vertices, _ = self._vertices()
        vector_area = np.cross(vertices, np.roll(vertices, -1, axis=1)).sum(axis=1) / 2
        return np.linalg.norm(vector_area, axis=1)

    def computeCentres(self) -> np.ndarray:
        """Centre of each cell: the mean of its vertices, (n_cells, 3)."""
        vertices, real = self._vertices()
        return (vertices * real[..., None]).sum(axis=1) / real.sum(axis=1, keepdims=True)

    @classmethod
    def _frame_kwargs(cls, frame: Any) -> dict[str, Any]:
        """A mesh Frame (``points``, ``cells``, point and cell data named in its attrs) as keywords."""
        arrays = dict(frame.arrays)
        if "points" not in arrays or "cells" not in arrays:
            raise ConfigError(f"Not a mesh frame (no points/cells): its arrays are {sorted(arrays)}")
        point_data = {key: arrays.pop(key) for key in frame.attrs.get("point_data", ())}
        meta = {"timestep": frame.timestep, "time": frame.time, "box": frame.box}
        return {
            **arrays,
            "point_data": point_data,
            **{k: v for k, v in meta.items() if v is not None},
            "units": frame.attrs.get("units", "si"),
        }

    def _to_frame(self) -> Any:
        frame = super()._to_frame()
        point_data = {k: v for k, v in self.point_data.items() if k != "points"}
        frame.arrays = {"points": self.points, **frame.arrays, **point_data}
        frame.attrs.update(kind="mesh", point_data=list(point_data), cell_data=list(self.cell_data))
        return frame

    def __add__(self, other: SubSystem) -> Mesh:
        """Both meshes as one: points appended, the other's cells renumbered; common data kept."""
        if not isinstance(other, Mesh):
            return NotImplemented
        self._check_same_units(other)
        offset = self.nPoints()
        mine, theirs = self.point_data, other.point_data
        points = {k: np.concatenate((v, theirs[k])) for k, v in mine.items() if k in theirs}
        cells = {k: np.concatenate((v, other._fields[k])) for k, v in self.cell_data.items() if k in other}
        cells["cells"] = np.concatenate((self.cells, other.cells + offset))
        new = type(self)._from_parts({k: _frozen(v) for k, v in cells.items()}, self._meta)
        new._meta.update({k: _frozen(v) for k, v in points.items()}, point_keys=tuple(points))
        return new

    def __iadd__(self, other: SubSystem) -> Mesh:
        return self + other

    def __mul__(self, other: SubSystem) -> Mesh:
        raise TypeError("The '*' product is defined for Particles, not for Mesh")
