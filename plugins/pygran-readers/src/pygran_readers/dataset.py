"""What a VTK file holds, as both parsers (legacy :mod:`pygran_readers.vtk`, XML
:mod:`pygran_readers.vtkxml`) build it, and the VTK cell types of polydata sections."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

VERTEX, POLY_VERTEX = 1, 2
_POLY_TYPE = {"VERTICES": (1, 2), "LINES": (3, 4), "TRIANGLE_STRIPS": (6, 6)}
_POLYGON_TYPE = {3: 5, 4: 9}  # triangle, quad; other sizes are polygons (7)


@dataclass
class Mesh:
    """What a VTK file holds, before it becomes a Frame."""

    points: np.ndarray
    cells: list[np.ndarray] = field(default_factory=list)  # one int array per cell
    cell_types: list[int] = field(default_factory=list)
    point_data: dict[str, np.ndarray] = field(default_factory=dict)
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)
    field_data: dict[str, np.ndarray] = field(default_factory=dict)  # dataset-level, e.g. TIME, CYCLE

    @property
    def timing(self) -> dict[str, Any]:
        """``timestep``/``time`` for a Frame, from the CYCLE and TIME field data when present."""
        found: dict[str, Any] = {}
        if "CYCLE" in self.field_data and np.size(self.field_data["CYCLE"]) == 1:
            found["timestep"] = int(np.ravel(self.field_data["CYCLE"])[0])
        if "TIME" in self.field_data and np.size(self.field_data["TIME"]) == 1:
            found["time"] = float(np.ravel(self.field_data["TIME"])[0])
        return found


def poly_cell_types(section: str, cells: list[np.ndarray]) -> list[int]:
    """VTK cell types of the cells of a polydata section (``VERTICES``, ``LINES``,
    ``POLYGONS``, ``TRIANGLE_STRIPS``; none for ``CELLS``, whose types are listed)."""
    if section == "POLYGONS":
        return [_POLYGON_TYPE.get(len(c), 7) for c in cells]
    if section not in _POLY_TYPE:
        return []
    one, many = _POLY_TYPE[section]
    return [one if len(c) == 1 or section == "LINES" and len(c) == 2 else many for c in cells]
