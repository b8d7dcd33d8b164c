"""VTK XML files written as ParaView and OVITO read them: polydata (``.vtp``) and unstructured
grids (``.vtu``), one per frame, with their ``.pvd`` index.

Particles are points with one vertex each and their columns as point data: ``vx vy vz`` as
the vector ``v`` (likewise ``f``, ``omega``, ``tq``), and ``id``, ``type``, ``radius``,
``mass``, ``density`` under those names, which OVITO maps to its particle identifier,
material type, radius, mass and density. Meshes are points and cells with their point and
cell data; a ``.vtp`` holds vertices, lines, strips and polygons, a ``.vtu`` any cell type.
Arrays are inline base64 of little-endian ``Float64`` or ``Int64`` with a ``UInt64`` header,
uncompressed (OVITO reads no compressed arrays), so every value reads back exactly. The
step and time go in the CYCLE and TIME field data, after the piece: OVITO recognises a
particle file by its first element, the ``<Piece>``.
"""

from __future__ import annotations

import base64
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from pygran_core.errors import UnsupportedFeature
from pygran_core.io import Frame, PathLike
from pygran_readers.series import SeriesWriter

#: Vector columns written as one 3-component array, by their name in the file.
TRIPLES = {
    ("vx", "vy", "vz"): "v",
    ("fx", "fy", "fz"): "f",
    ("omegax", "omegay", "omegaz"): "omega",
    ("tqx", "tqy", "tqz"): "tq",
}
#: VTK cell type -> the polydata section that holds it.
SECTIONS = {1: "Verts", 2: "Verts", 3: "Lines", 4: "Lines", 5: "Polys", 7: "Polys", 9: "Polys", 6: "Strips"}
_ORDER = ("Verts", "Lines", "Strips", "Polys")
VERTEX = 1


@dataclass
class _Dataset:
    """What a frame holds, as VTK sees it: points, cells ``(C, k)`` padded with -1, their
    sizes and VTK types, point data and cell data."""

    points: np.ndarray
    cells: np.ndarray
    sizes: np.ndarray
    types: np.ndarray
    point_data: dict[str, np.ndarray]
    cell_data: dict[str, np.ndarray]


def _dataset(frame: Frame) -> _Dataset:
    """The dataset of a mesh frame (``points``, ``cells``) or a particle frame (``x y z``)."""
    arrays = dict(frame.arrays)
    if "points" in arrays:
        cells = np.asarray(arrays["cells"], np.int64)
        cells = cells.reshape(len(cells), -1) if cells.size else np.zeros((len(cells), 0), np.int64)
        sizes = (cells >= 0).sum(axis=1)
        types = np.asarray(arrays.get("cell_types", np.where(sizes == 3, 5, np.where(sizes == 4, 9, 7))))
        point_data, cell_data = (
            {name.split(":", 1)[-1]: arrays[name] for name in frame.attrs.get(key, ())}
            for key in ("point_data", "cell_data")
        )
        return _Dataset(np.asarray(arrays["points"], np.float64), cells, sizes, types, point_data, cell_data)
    missing = [axis for axis in "xyz" if axis not in arrays]
    if missing:
        raise UnsupportedFeature(f"A VTK particle file needs x, y and z; the frame lacks {missing}")
    n = len(arrays["x"])
    points = np.column_stack([arrays.pop(axis) for axis in "xyz"]).astype(np.float64).reshape(n, 3)
    data: dict[str, np.ndarray] = {}
    for name, values in arrays.items():
        triple = next((t for t in TRIPLES if name in t), None)
        if triple is not None and all(k in arrays for k in triple):
            if name == triple[0]:
                data[TRIPLES[triple]] = np.column_stack([arrays[k] for k in triple]).reshape(n, 3)
        else:
            data[name] = values
    vertices = np.arange(n, dtype=np.int64)[:, None]
    return _Dataset(points, vertices, np.ones(n, np.int64), np.full(n, VERTEX), data, {})


class VTPWriter(SeriesWriter):
    """``.vtp`` files, one per frame, and their ``.pvd`` index (see
    :class:`~pygran_readers.series.SeriesWriter`)."""

    def encode(self, frame: Frame) -> bytes:
        return "".join(vtp_text(frame)).encode("ascii")


class VTUWriter(SeriesWriter):
    """``.vtu`` files, one per frame, and their ``.pvd`` index."""

    def encode(self, frame: Frame) -> bytes:
        return "".join(vtu_text(frame)).encode("ascii")


class PVDWriter(VTPWriter):
    """A series named by its index: ``out.pvd`` indexes ``out_<step>.vtp`` beside it."""

    def __init__(self, path: PathLike, **options: Any) -> None:
        if options:
            raise UnsupportedFeature(
                f"The pvd writer takes no options (its index is {path}), got {sorted(options)}"
            )
        target = Path(path)
        super().__init__(target.with_name(f"{target.stem}_*.vtp"), target)


def _encoded(values: np.ndarray) -> str:
    """Inline binary: base64 of a UInt64 byte count followed by the little-endian values."""
    raw = np.ascontiguousarray(values).tobytes()
    return base64.b64encode(np.uint64(len(raw)).astype("<u8").tobytes() + raw).decode("ascii")


def _array(name: str, values: np.ndarray, tuples: bool = False) -> str:
    """A DataArray of ``values`` (``tuples``: state NumberOfTuples, as field data must)."""
    values = np.asarray(values)
    if values.dtype == np.uint8:  # cell types, as VTK stores them
        kind, data = "UInt8", values
    elif values.dtype.kind in "iub":
        kind, data = "Int64", values.astype("<i8")
    elif values.dtype.kind == "f":
        kind, data = "Float64", values.astype("<f8")
    else:
        raise UnsupportedFeature(f"VTK XML arrays hold numbers; {name!r} holds {values.dtype}")
    components = 1 if data.ndim == 1 else int(np.prod(data.shape[1:]))
    count = f' NumberOfTuples="{len(data)}"' if tuples else ""
    return (
        f'<DataArray type="{kind}" Name={quoteattr(name)}{count} NumberOfComponents="{components}" '
        f'format="binary">{_encoded(data)}</DataArray>\n'
    )


def _field(frame: Frame) -> str:
    arrays = []
    if frame.timestep is not None:
        arrays.append(_array("CYCLE", np.array([int(frame.timestep)]), tuples=True))
    if frame.time is not None:
        arrays.append(_array("TIME", np.array([float(frame.time)]), tuples=True))
    return "<FieldData>\n" + "".join(arrays) + "</FieldData>\n" if arrays else ""


def _head(kind: str) -> str:
    return (
        '<?xml version="1.0"?>\n'
        f'<VTKFile type="{kind}" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n<{kind}>\n'
    )


def _points(points: np.ndarray) -> str:
    return "<Points>\n" + _array("Points", points.reshape(-1, 3)) + "</Points>\n"


def _data(tag: str, data: dict[str, np.ndarray]) -> str:
    return f"<{tag}>\n" + "".join(_array(n, v) for n, v in data.items()) + f"</{tag}>\n" if data else ""


def _connectivity(data: _Dataset, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The connectivity and offsets of the cells ``rows`` (a mask)."""
    cells = data.cells[rows]
    return cells[cells >= 0], np.cumsum(data.sizes[rows])


def vtp_text(frame: Frame) -> Iterator[str]:
    """The text of one ``.vtp`` file holding ``frame`` (particles or a mesh)."""
    data = _dataset(frame)
    unknown = sorted(set(data.types.tolist()) - set(SECTIONS))
    if unknown:
        raise UnsupportedFeature(
            f"A .vtp file holds vertices, lines, strips and polygons, not VTK cell types {unknown}: "
            "write the mesh as .vtu or legacy .vtk"
        )
    section_of = np.array([_ORDER.index(SECTIONS[int(t)]) for t in data.types], np.int64)
    if np.any(np.diff(section_of) < 0):
        raise UnsupportedFeature(
            "A .vtp file lists its cells by kind (vertices, lines, strips, polygons); this mesh mixes "
            "them in another order: write it as .vtu or legacy .vtk"
        )
    yield _head("PolyData")
    counts = " ".join(f'NumberOf{s}="{np.count_nonzero(section_of == k)}"' for k, s in enumerate(_ORDER))
    yield f'<Piece NumberOfPoints="{len(data.points)}" {counts}>\n'
    yield _points(data.points)
    for k, section in enumerate(_ORDER):
        rows = section_of == k
        if rows.any():
            connectivity, offsets = _connectivity(data, rows)
            yield f"<{section}>\n" + _array("connectivity", connectivity) + _array("offsets", offsets)
            yield f"</{section}>\n"
    yield _data("PointData", data.point_data) + _data("CellData", data.cell_data) + "</Piece>\n"
    yield _field(frame) + "</PolyData>\n</VTKFile>\n"


def vtu_text(frame: Frame) -> Iterator[str]:
    """The text of one ``.vtu`` file holding ``frame`` (particles or a mesh)."""
    data = _dataset(frame)
    yield _head("UnstructuredGrid")
    yield f'<Piece NumberOfPoints="{len(data.points)}" NumberOfCells="{len(data.cells)}">\n'
    yield _points(data.points)
    connectivity, offsets = _connectivity(data, np.ones(len(data.cells), bool))
    yield "<Cells>\n" + _array("connectivity", connectivity) + _array("offsets", offsets)
    yield _array("types", data.types.astype(np.uint8)) + "</Cells>\n"
    yield _data("PointData", data.point_data) + _data("CellData", data.cell_data) + "</Piece>\n"
    yield _field(frame) + "</UnstructuredGrid>\n</VTKFile>\n"
