"""YADE ``VTKRecorder`` output: ``<fileName>spheres.<iter>.vtu`` as particles, and
``<fileName>facets.<iter>.vtu`` / ``<fileName>boxes.<iter>.vtu`` as meshes.

VTKRecorder writes one XML unstructured grid per recorder kind and recorded iteration:
spheres as vertex cells whose point data holds ``radii`` (always) and, depending on its
``recorders``, ``id``, ``materialId``, ``clumpId``, ``mask``, ``color``, ``linVelVec``,
``angVelVec`` (with their lengths ``linVelLen``, ``angVelLen``) and the ``stress`` arrays,
all as float64; points are float32. Facets are triangles and boxes quads (six per box) with
cell data. The timestep is the iteration number in the file name; the files hold no time.

Sphere columns get their LIGGGHTS names (:data:`COLUMNS`): ``id``, ``type`` (the material
index plus one, as PyGran's YADE engine numbers species), ``x y z``, ``radius``,
``vx vy vz``, ``omegax omegay omegaz``; ``clumpId`` and ``mask`` become integers too. The
lengths of the velocities are dropped (a unit conversion would not follow them); any
other array keeps its YADE name, a vector split into ``<name>x <name>y <name>z``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ReadError
from pygran_core.formats.sanity import particle_problem
from pygran_core.io import Frame, PathLike, Trajectory
from pygran_readers import vtk, vtkxml
from pygran_readers.dataset import VERTEX, Mesh

#: The file names VTKRecorder gives: ``<fileName><kind>.<iteration>.vtu``.
FILE_NAME = re.compile(r"(spheres|facets|boxes)\.(\d+)\.vtu$", re.IGNORECASE)
#: YADE sphere array -> PyGran column (a 3-vector: the prefix of its x, y, z columns).
COLUMNS = {"id": "id", "materialId": "type", "radii": "radius", "linVelVec": "v", "angVelVec": "omega"}
INTEGER = frozenset({"id", "materialId", "clumpId", "mask"})
DROPPED = frozenset({"linVelLen", "angVelLen"})
_ITERATION = re.compile(r"\.(\d+)\.vtu$", re.IGNORECASE)


def can_open(path: Path) -> bool:
    """True for an XML unstructured grid with YADE's ``radii`` array or a VTKRecorder name."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except OSError:
        return False
    if b"<VTKFile" not in head or b'type="UnstructuredGrid"' not in head:
        return False
    return b'Name="radii"' in head or FILE_NAME.search(path.name) is not None


def _kind(path: Path) -> str | None:
    """``"spheres"``, ``"facets"`` or ``"boxes"`` from a VTKRecorder file name, else None."""
    found = FILE_NAME.search(path.name)
    return None if found is None else found.group(1).lower()


def _iteration(path: Path) -> int | None:
    found = _ITERATION.search(path.name)
    return None if found is None else int(found.group(1))


class YadeTrajectory(Trajectory):
    """One frame per VTKRecorder file: meshes from facets and boxes files, particles from
    the others (spheres files).

    The files must be of one kind: a glob that matches VTKRecorder's sphere and facet files
    together is a :class:`ReadError` that names the pattern of each kind.
    """

    def __init__(self, paths: Sequence[PathLike]) -> None:
        self.paths = [Path(p) for p in paths]
        first: dict[str, Path] = {}
        for path in self.paths:
            kind = _kind(path)
            if kind is not None:
                first.setdefault(kind, path)
        if len(first) > 1:
            patterns = ", ".join(
                f"{kind}: {_ITERATION.sub('.*.vtu', str(path))!r}" for kind, path in first.items()
            )
            raise ReadError(
                f"The files mix YADE VTKRecorder outputs ({', '.join(first)}); open one kind at a "
                f"time, spheres as Particles and facets or boxes as a Mesh: {patterns}"
            )

    @property
    def n_frames(self) -> int:
        return len(self.paths)

    def _read_frame(self, index: int) -> Frame:
        path = self.paths[index]
        try:
            mesh = vtkxml.read_xml(path)
            frame = (
                vtk.mesh_frame(mesh, "mesh") if _kind(path) in ("facets", "boxes") else _spheres(path, mesh)
            )
        except ReadError as exc:
            raise ReadError(str(exc).replace("frame 0", f"frame {index}", 1)) from exc
        problem = particle_problem(frame.arrays) if frame.attrs.get("kind") == "particles" else None
        if problem:
            raise ReadError(f"{path}: frame {index}: {problem}")
        frame.timestep = _iteration(path)
        return frame


def _spheres(path: Path, grid: Mesh) -> Frame:
    """The particles of one VTKRecorder spheres file."""
    points = grid.points
    n = len(points)

    def fail(message: str) -> ReadError:
        return ReadError(f"{path}: frame 0: {message}")

    types = np.asarray(grid.cell_types, dtype=np.int64)
    if len(types) != n or (types != VERTEX).any():
        found = ", ".join(str(t) for t in np.unique(types)) or "none"
        raise fail(
            f"not a YADE spheres file: expected one vertex cell (type 1) per sphere for {n} points, "
            f"found {len(types)} cells of types {found}"
        )
    data = grid.point_data
    if "radii" not in data:
        raise fail(f"not a YADE spheres file: no 'radii' point data (it has {sorted(data) or 'none'})")
    columns: dict[str, np.ndarray] = {}
    for name, values in data.items():
        if name in INTEGER:
            whole = np.round(values)
            if not np.array_equal(values, whole):
                bad = values[values != whole][0]
                raise fail(f"point data {name!r} must hold whole numbers, found {float(bad)!r}")
            values = whole.astype(np.int64)
        if name not in DROPPED:
            columns[COLUMNS.get(name, name)] = values if name in INTEGER else values.astype(np.float64)
    if "type" in columns:
        columns["type"] += 1
    arrays: dict[str, np.ndarray] = {name: columns.pop(name) for name in ("id", "type") if name in columns}
    arrays.update({axis: points[:, j].copy() for j, axis in enumerate("xyz")})
    arrays["radius"] = columns.pop("radius")
    for name in sorted(columns, key=lambda name: name not in ("v", "omega")):
        values = columns[name]
        if values.ndim == 1:
            arrays[name] = values
        elif values.shape[1:] == (3,):
            arrays.update({f"{name}{axis}": values[:, j].copy() for j, axis in enumerate("xyz")})
        else:
            flat = values.reshape(n, -1)
            arrays.update({f"{name}[{j + 1}]": flat[:, j].copy() for j in range(flat.shape[1])})
    return Frame(arrays, attrs={"kind": "particles"})
