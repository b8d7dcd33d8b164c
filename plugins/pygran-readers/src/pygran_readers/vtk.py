"""VTK meshes and particles: legacy ``.vtk`` and XML ``.vtu``/``.vtp`` (:mod:`pygran_readers.vtkxml`).

Every file is one frame; a glob of files is a sequence of frames. A file whose cells are
all vertices (or that has none) holds particles; it becomes ``x y z`` plus one column per
point-data array (3-component arrays split into ``<name>x``, ``<name>y``, ``<name>z``, as
LIGGGHTS names them: ``v`` -> ``vx vy vz``). Any other file is a mesh (see
:class:`pygran_core.io.Frame` for the mesh arrays). ``kind="mesh"`` or
``kind="particles"`` forces one reading. :class:`PVDTrajectory` reads the files a ``.pvd``
index (:mod:`pygran_readers.series`) lists.

The legacy reader handles ``POLYDATA`` and ``UNSTRUCTURED_GRID`` in ASCII and binary,
with the classic and the VTK 5.1 (``OFFSETS``/``CONNECTIVITY``) cell layouts; numbers are
parsed a whole section at a time with numpy.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.formats.sanity import particle_problem, step_problem
from pygran_core.io import Frame, PathLike, Trajectory
from pygran_readers import vtkxml
from pygran_readers.dataset import POLY_VERTEX, VERTEX, Mesh, poly_cell_types
from pygran_readers.series import SeriesWriter, read_index

#: legacy type name -> big-endian binary dtype
DTYPES = {
    "unsigned_char": ">u1",
    "char": ">i1",
    "unsigned_short": ">u2",
    "short": ">i2",
    "unsigned_int": ">u4",
    "int": ">i4",
    "unsigned_long": ">u8",
    "long": ">i8",
    "float": ">f4",
    "double": ">f8",
    "vtktypeint64": ">i8",
    "vtktypeuint64": ">u8",
    "vtkidtype": ">i8",
    "vtktypeint32": ">i4",
}
#: polydata sections in the order their cells are numbered
POLY_SECTIONS = ("VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS")


def can_open(path: Path) -> bool:
    """True for a legacy VTK header or a VTK XML dataset (not a ``.pvd`` collection)."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(256)
    except OSError:
        return False
    xml = head.lstrip().startswith(b"<") and b"<VTKFile" in head and b'type="Collection"' not in head
    return head.startswith(b"# vtk DataFile") or xml


class _Legacy:
    """Cursor over a legacy VTK file's bytes; raises ReadError naming the line."""

    def __init__(self, path: Path, data: bytes) -> None:
        self.path, self.data, self.pos = path, data, 0
        self.binary = False

    def fail(self, message: str, pos: int | None = None) -> ReadError:
        line = self.data.count(b"\n", 0, self.pos if pos is None else pos) + 1
        return ReadError(f"{self.path}: frame 0, line {line}: {message}")

    def line(self) -> str | None:
        """The next non-blank line, or None at the end of the file."""
        while self.pos < len(self.data):
            end = self.data.find(b"\n", self.pos)
            end = len(self.data) if end < 0 else end
            text = self.data[self.pos : end].decode("latin-1").strip()
            start, self.pos = self.pos, end + 1
            if text:
                self.last = start
                return text
        return None

    def words(self, expect: int | None = None, what: str = "section") -> list[str]:
        text = self.line()
        if text is None:
            raise self.fail(f"the file ends where a {what} line was expected")
        words = text.split()
        if expect is not None and len(words) < expect:
            raise self.fail(f"bad {what} line {text[:80]!r}", self.last)
        return words

    def count(self, word: str) -> int:
        try:
            value = int(word)
        except ValueError:
            raise self.fail(f"{word[:40]!r} is not a count", self.last) from None
        if value < 0:
            raise self.fail(f"negative count {value}", self.last)
        return value

    def numbers(self, count: int, type_name: str) -> np.ndarray:
        """``count`` numbers of a legacy type, ASCII or big-endian binary."""
        dtype = DTYPES.get(type_name.lower())
        if dtype is None:
            raise self.fail(f"unsupported data type {type_name!r}", self.last)
        start = self.pos
        if self.binary:
            size = np.dtype(dtype).itemsize * count
            if self.pos + size > len(self.data):
                raise self.fail(f"the file ends inside {count} binary {type_name} values")
            values = np.frombuffer(self.data, dtype=dtype, count=count, offset=self.pos)
            self.pos += size
            values = values.astype(dtype[1:])  # native byte order
        else:
            end = self._token_end(count)
            kind = np.float64 if dtype[1] == "f" else np.int64
            try:
                values = np.fromstring(self.data[start:end], dtype=kind, sep=" ")
            except ValueError:
                values = np.empty(0)
            if len(values) != count:
                raise self.fail(
                    f"expected {count} {type_name} numbers, found a non-number or fewer values", start
                )
        return values

    def _token_end(self, count: int) -> int:
        """Byte offset just past the ``count``-th whitespace-separated token from ``pos``."""
        if count == 0:
            return self.pos
        if self.pos >= len(self.data):
            raise self.fail(f"the file ends where a block of {count} numbers was expected")
        chunk = np.frombuffer(self.data, dtype=np.uint8, offset=self.pos)
        space = chunk <= 32
        ends = np.flatnonzero(~space & np.append(space[1:], True))
        if len(ends) < count:
            raise self.fail(f"the file ends inside a block of {count} numbers")
        end = self.pos + int(ends[count - 1]) + 1
        self.pos = end
        return end


def read_legacy(path: Path) -> Mesh:
    """Parse a legacy VTK file (POLYDATA or UNSTRUCTURED_GRID, ASCII or BINARY)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ReadError(f"{path}: cannot read the file: {exc}") from exc
    cur = _Legacy(path, data)
    if not (cur.line() or "").startswith("# vtk DataFile"):
        raise cur.fail("not a legacy VTK file (no '# vtk DataFile' header)")
    if cur.line() is None:
        raise cur.fail("the file ends after its first line")
    mode = (cur.line() or "").upper()
    if mode not in ("ASCII", "BINARY"):
        raise cur.fail(f"expected ASCII or BINARY, found {mode[:40]!r}", cur.last)
    cur.binary = mode == "BINARY"
    words = cur.words(2, "DATASET")
    if words[0].upper() != "DATASET" or words[1].upper() not in ("POLYDATA", "UNSTRUCTURED_GRID"):
        raise cur.fail(
            f"only DATASET POLYDATA and UNSTRUCTURED_GRID are read, found {' '.join(words)!r}", cur.last
        )
    points = None
    sections: list[tuple[str, list[np.ndarray]]] = []
    cell_types: np.ndarray | None = None
    target: dict[str, np.ndarray] | None = None
    sizes = {"POINT_DATA": 0, "CELL_DATA": 0}
    point_data: dict[str, np.ndarray] = {}
    cell_data: dict[str, np.ndarray] = {}
    field_data: dict[str, np.ndarray] = {}
    target_size = 0
    while (text := cur.line()) is not None:
        words = text.split()
        key = words[0].upper()
        if key == "POINTS":
            if len(words) < 3:
                raise cur.fail(f"bad POINTS line {text[:80]!r}", cur.last)
            n = cur.count(words[1])
            points = cur.numbers(3 * n, words[2]).astype(np.float64).reshape(n, 3)
        elif key in POLY_SECTIONS or key == "CELLS":
            if len(words) < 3:
                raise cur.fail(f"bad {key} line {text[:80]!r}", cur.last)
            sections.append((key, _read_cells(cur, cur.count(words[1]), cur.count(words[2]))))
        elif key == "CELL_TYPES":
            if len(words) < 2:
                raise cur.fail(f"bad CELL_TYPES line {text[:80]!r}", cur.last)
            cell_types = cur.numbers(cur.count(words[1]), "int")
        elif key in sizes:
            if len(words) < 2:
                raise cur.fail(f"bad {key} line {text[:80]!r}", cur.last)
            sizes[key] = cur.count(words[1])
            target = point_data if key == "POINT_DATA" else cell_data
            target_size = sizes[key]
        elif key == "METADATA":
            while (skip := cur.line()) is not None and skip.upper().startswith(
                ("INFORMATION", "NAME", "DATA", "COMPONENT")
            ):
                pass
            if skip is not None:
                cur.pos = cur.last  # not metadata: read it as a section
        elif key == "FIELD" and target is None:  # dataset-level field data (e.g. TIME)
            _read_attribute(cur, words, field_data, None)
        elif target is not None and key in (
            "SCALARS",
            "VECTORS",
            "NORMALS",
            "TENSORS",
            "TEXTURE_COORDINATES",
            "FIELD",
            "LOOKUP_TABLE",
        ):
            _read_attribute(cur, words, target, target_size)
        else:
            raise cur.fail(f"unknown or misplaced section {text[:60]!r}", cur.last)
    if points is None:
        raise cur.fail("the file has no POINTS section")
    mesh = _assemble(cur, points, sections, cell_types, point_data, cell_data)
    mesh.field_data = field_data
    return mesh


def _read_cells(cur: _Legacy, n: int, size: int) -> list[np.ndarray]:
    """Cells of a VERTICES/LINES/POLYGONS/CELLS section, classic or VTK 5.1 layout."""
    save = cur.pos
    peek = cur.line()
    if peek is not None and peek.upper().startswith("OFFSETS"):
        words = peek.split()
        offsets = cur.numbers(n, words[1] if len(words) > 1 else "vtktypeint64")
        words = cur.words(2, "CONNECTIVITY")
        if words[0].upper() != "CONNECTIVITY":
            raise cur.fail(f"expected CONNECTIVITY, found {words[0][:40]!r}", cur.last)
        connectivity = cur.numbers(size, words[1])
        if n == 0:
            return []
        if offsets[0] != 0 or np.any(np.diff(offsets) < 0) or offsets[-1] != size:
            raise cur.fail("cell OFFSETS are not increasing from 0 to the connectivity size")
        return np.split(connectivity.astype(np.int64), offsets[1:-1])
    cur.pos = save
    flat = cur.numbers(size, "int").astype(np.int64)
    cells, at = [], 0
    # Cell sizes are only known one cell at a time in the classic layout; when every cell
    # has the same size (the usual case) the whole block is reshaped at once.
    if n and size % n == 0 and flat[0] + 1 == size // n and np.all(flat[:: size // n] == flat[0]):
        table = flat.reshape(n, size // n)[:, 1:]
        return list(table)
    for _ in range(n):
        if at >= size or flat[at] < 0 or at + 1 + flat[at] > size:
            raise cur.fail("the cell list is shorter than its header says or has a bad cell size")
        cells.append(flat[at + 1 : at + 1 + flat[at]])
        at += 1 + int(flat[at])
    if at != size:
        raise cur.fail(f"the cell list has {size - at} values more than its {n} cells use")
    return cells


def _read_attribute(cur: _Legacy, words: list[str], target: dict[str, np.ndarray], n: int | None) -> None:
    """One data array into ``target``; ``n`` is the tuple count (None: any, for field data)."""
    key = words[0].upper()
    if key == "FIELD":
        if len(words) < 3:
            raise cur.fail(f"bad FIELD line {' '.join(words)[:80]!r}", cur.last)
        for _ in range(cur.count(words[2])):
            name, ncomp, ntuples, type_name = (cur.words(4, "field array") + [""])[:4]
            if name.upper() == "NULL_ARRAY":
                continue
            k, m = cur.count(ncomp), cur.count(ntuples)
            values = cur.numbers(k * m, type_name)
            target[name] = values.reshape(m, k) if k > 1 else values
            if n is not None and m != n:
                raise cur.fail(f"field array {name!r} has {m} tuples, the data section {n}", cur.last)
        return
    if key == "LOOKUP_TABLE":  # a colour table: skip its 4 values per entry
        if len(words) < 3:
            raise cur.fail("bad LOOKUP_TABLE line", cur.last)
        cur.numbers(4 * cur.count(words[2]), "unsigned_char" if cur.binary else "float")
        return
    if len(words) < 3:
        raise cur.fail(f"bad {key} line {' '.join(words)[:80]!r}", cur.last)
    name = words[1]
    if key == "SCALARS":
        type_name, k = words[2], cur.count(words[3]) if len(words) > 3 else 1
        save = cur.pos
        table = cur.line()
        if table is None or not table.upper().startswith("LOOKUP_TABLE"):
            cur.pos = save
    elif key == "TEXTURE_COORDINATES":
        if len(words) < 4:
            raise cur.fail("bad TEXTURE_COORDINATES line", cur.last)
        k, type_name = cur.count(words[2]), words[3]
    else:
        k, type_name = (9 if key == "TENSORS" else 3), words[2]
    assert n is not None
    values = cur.numbers(k * n, type_name)
    target[name] = (
        values.reshape(n, 3, 3) if key == "TENSORS" else (values.reshape(n, k) if k > 1 else values)
    )


def _assemble(
    cur: _Legacy,
    points: np.ndarray,
    sections: list[tuple[str, list[np.ndarray]]],
    cell_types: np.ndarray | None,
    point_data: dict[str, np.ndarray],
    cell_data: dict[str, np.ndarray],
) -> Mesh:
    cells: list[np.ndarray] = []
    types: list[int] = []
    for key, section in sorted(
        sections, key=lambda s: POLY_SECTIONS.index(s[0]) if s[0] in POLY_SECTIONS else 0
    ):
        cells.extend(section)
        types.extend(poly_cell_types(key, section))
    if any(key == "CELLS" for key, _ in sections):
        if cell_types is None or len(cell_types) != len(cells):
            raise cur.fail(f"CELL_TYPES must give one type for each of the {len(cells)} cells")
        types = [int(t) for t in cell_types]
    for c in cells:
        if len(c) and (c.min() < 0 or c.max() >= len(points)):
            bad, last = int(c.min()) if c.min() < 0 else int(c.max()), len(points) - 1
            raise cur.fail(f"a cell refers to point {bad}, but the points are numbered 0 to {last}")
    for name, values in point_data.items():
        if len(values) != len(points):
            raise cur.fail(f"point data {name!r} has {len(values)} values for {len(points)} points")
    for name, values in cell_data.items():
        if len(values) != len(cells):
            raise cur.fail(f"cell data {name!r} has {len(values)} values for {len(cells)} cells")
    return Mesh(points, cells, types, point_data, cell_data)


def _reader_for(path: Path) -> Callable[[Path], Mesh]:
    """The parser of a file: by its suffix, else by its first bytes."""
    suffix = path.suffix.lower()
    if suffix in (".vtu", ".vtp"):
        return vtkxml.read_xml
    if suffix == ".vtk":
        return read_legacy
    try:
        with open(path, "rb") as handle:
            head = handle.read(512)
    except OSError as exc:
        raise ReadError(f"{path}: frame 0: cannot read the file: {exc}") from exc
    return read_legacy if head.startswith(b"# vtk DataFile") else vtkxml.read_xml


def read_any(path: Path) -> Mesh:
    """Parse a VTK file, legacy or XML (by its suffix, else by its first bytes)."""
    return _reader_for(path)(path)


def mesh_frame(mesh: Mesh, kind: str | None) -> Frame:
    """A Frame from a mesh: particles when every cell is a vertex (or ``kind`` says so)."""
    vertices_only = all(t in (VERTEX, POLY_VERTEX) for t in mesh.cell_types)
    if kind == "particles" or (kind is None and vertices_only):
        arrays = {"x": mesh.points[:, 0].copy(), "y": mesh.points[:, 1].copy(), "z": mesh.points[:, 2].copy()}
        for name, values in mesh.point_data.items():
            if values.ndim == 1:
                arrays[name] = values
            elif values.shape[1:] == (3,):
                arrays.update({f"{name}{axis}": values[:, j].copy() for j, axis in enumerate("xyz")})
            else:
                flat = values.reshape(len(values), -1)
                arrays.update({f"{name}[{j + 1}]": flat[:, j].copy() for j in range(flat.shape[1])})
        return Frame(arrays, attrs={"kind": "particles"}, **mesh.timing)
    width = max((len(c) for c in mesh.cells), default=0)
    cells = np.full((len(mesh.cells), width), -1, dtype=np.int64)
    for row, cell in enumerate(mesh.cells):
        cells[row, : len(cell)] = cell
    arrays = {
        "points": mesh.points,
        "cells": cells,
        "cell_types": np.asarray(mesh.cell_types, dtype=np.int64),
    }
    clash = set(mesh.point_data) & set(mesh.cell_data) | set(arrays) & (
        set(mesh.point_data) | set(mesh.cell_data)
    )
    point_keys = {n: f"point:{n}" if n in clash else n for n in mesh.point_data}
    cell_keys = {n: f"cell:{n}" if n in clash else n for n in mesh.cell_data}
    arrays.update({point_keys[n]: v for n, v in mesh.point_data.items()})
    arrays.update({cell_keys[n]: v for n, v in mesh.cell_data.items()})
    return Frame(
        arrays,
        attrs={
            "kind": "mesh",
            "point_data": list(point_keys.values()),
            "cell_data": list(cell_keys.values()),
        },
        **mesh.timing,
    )


class VTKTrajectory(Trajectory):
    """One frame per VTK file, read when asked for; particles with repeated ids or a radius,
    mass or density that is not positive are a ``ReadError`` naming the file."""

    def __init__(self, paths: Sequence[PathLike], kind: str | None = None) -> None:
        if kind not in (None, "mesh", "particles"):
            raise ReadError(f"kind must be 'mesh', 'particles' or None, got {kind!r}")
        self.paths = [Path(p) for p in paths]
        self.kind = kind

    @property
    def n_frames(self) -> int:
        return len(self.paths)

    def _read_frame(self, index: int) -> Frame:
        path = self.paths[index]
        try:
            mesh = _reader_for(path)(path)
        except ReadError as exc:
            raise ReadError(str(exc).replace("frame 0", f"frame {index}", 1)) from exc
        frame = mesh_frame(mesh, self.kind)
        problem = particle_problem(frame.arrays) if frame.attrs["kind"] == "particles" else None
        if problem:
            raise ReadError(f"{path}: frame {index}: {problem}")
        return frame


class PVDTrajectory(Trajectory):
    """The frames a ``.pvd`` index lists: each ``DataSet``'s file read as VTK (legacy or XML),
    with the index's ``timestep`` as the frame's time and its ``cycle`` (else the file's) as
    its step. A file listed for several frames is parsed once."""

    def __init__(self, paths: Sequence[PathLike], kind: str | None = None) -> None:
        if kind not in (None, "mesh", "particles"):
            raise ReadError(f"kind must be 'mesh', 'particles' or None, got {kind!r}")
        self.kind = kind
        self.entries: list[tuple[Path, float, int | None, Path]] = []
        for index in paths:
            index = Path(index)
            for entry in read_index(index):
                where = f"{index}: line {entry['line']}"
                if entry.get("part", "0") != "0":
                    raise UnsupportedFeature(
                        f"{where}: datasets of several parts are not read; open each file"
                    )
                if "file" not in entry:
                    raise ReadError(f"{where}: a DataSet names no file")
                try:
                    time = float(entry.get("timestep", "nan"))
                    cycle = int(entry["cycle"]) if "cycle" in entry else None
                except ValueError:
                    raise ReadError(f"{where}: timestep or cycle is not a number") from None
                if not math.isfinite(time):
                    raise ReadError(f"{where}: a DataSet has no finite timestep")
                previous = self.entries[-1][2] if self.entries else None
                problem = None if cycle is None else step_problem(previous, cycle)
                if problem:
                    raise ReadError(f"{where}: {problem}")
                self.entries.append((index.parent / entry["file"], time, cycle, index))
        self._cached: tuple[Path, Mesh] | None = None

    @property
    def n_frames(self) -> int:
        return len(self.entries)

    def _read_frame(self, index: int) -> Frame:
        path, time, cycle, source = self.entries[index]
        if self._cached is None or self._cached[0] != path:
            if not path.is_file():
                raise ReadError(f"{source}: frame {index} is {path}, which does not exist")
            try:
                self._cached = (path, read_any(path))
            except ReadError as exc:
                raise ReadError(str(exc).replace("frame 0", f"frame {index}", 1)) from exc
        frame = mesh_frame(self._cached[1], self.kind)
        problem = particle_problem(frame.arrays) if frame.attrs.get("kind") == "particles" else None
        if problem:
            raise ReadError(f"{source}: frame {index} ({path.name}): {problem}")
        frame.arrays = {name: values.copy() for name, values in frame.arrays.items()}  # the cache stays
        frame.time = time
        if cycle is not None:
            frame.timestep = cycle
        return frame


# -- writing -------------------------------------------------------------------------------

_POLYGON_CELLS = frozenset({5, 7, 9})  # triangle, polygon, quad
_TRIPLES = {
    ("vx", "vy", "vz"): "v",
    ("fx", "fy", "fz"): "f",
    ("omegax", "omegay", "omegaz"): "omega",
    ("tqx", "tqy", "tqz"): "tq",
}


class VTKWriter(SeriesWriter):
    """Legacy VTK files, one per frame (ASCII by default, or big-endian ``binary=True``),
    and their ``.pvd`` index (see :class:`~pygran_readers.series.SeriesWriter`: a ``*`` in
    the name is the step, unchanged frames are not written again).

    Meshes are written as POLYDATA polygons (UNSTRUCTURED_GRID when some cells are not
    polygons), particles as POLYDATA vertices with their columns as point data (``vx vy vz``
    as the vector ``v``). The frame's step and time go in the CYCLE and TIME field data, after
    the geometry, where OVITO's reader accepts them.
    """

    def __init__(self, path: PathLike, binary: bool = False, index: PathLike | None = None) -> None:
        super().__init__(path, index)
        self.binary = bool(binary)

    def encode(self, frame: Frame) -> bytes:
        return b"".join(_legacy_chunks(frame, self.binary))


def _legacy_chunks(frame: Frame, binary: bool) -> Iterator[bytes]:
    yield b"# vtk DataFile Version 3.0\nPyGran frame\n" + (b"BINARY\n" if binary else b"ASCII\n")
    if "points" in frame.arrays:
        yield from _mesh_chunks(frame, binary)
    else:
        yield from _particle_chunks(frame, binary)


def _numbers(values: np.ndarray, binary: bool, per_line: int, integer: str = ">i8") -> bytes:
    """Numbers as ASCII lines of ``per_line`` values, or big-endian binary (``integer`` for ints)."""
    values = np.asarray(values)
    if binary:
        dtype = integer if values.dtype.kind in "iub" else ">f8"
        return values.astype(dtype).tobytes() + b"\n"
    if values.size == 0:
        return b""
    flat = values.reshape(-1, per_line) if values.size % per_line == 0 else values.reshape(-1, 1)
    form = "%d" if values.dtype.kind in "iub" else "%r"
    row = " ".join([form] * flat.shape[1]) + "\n"
    cast = flat.astype(np.int64 if values.dtype.kind in "iub" else np.float64).tolist()
    return ((row * len(flat)) % tuple(v for record in cast for v in record)).encode("ascii")


def _array_chunks(name: str, values: np.ndarray, binary: bool) -> Iterator[bytes]:
    values = np.asarray(values)
    components = 1 if values.ndim == 1 else int(np.prod(values.shape[1:]))
    kind = "long" if values.dtype.kind in "iub" else "double"
    if " " in name:
        raise UnsupportedFeature(f"VTK array names cannot contain spaces: {name!r}")
    yield f"{name} {components} {len(values)} {kind}\n".encode("ascii")
    yield _numbers(values.reshape(len(values), components), binary, components)


def _field(arrays: dict[str, np.ndarray], binary: bool) -> Iterator[bytes]:
    yield f"FIELD FieldData {len(arrays)}\n".encode("ascii")
    for name, values in arrays.items():
        yield from _array_chunks(name, values, binary)


def _timing(frame: Frame) -> dict[str, np.ndarray]:
    found = {}
    if frame.timestep is not None:
        found["CYCLE"] = np.array([int(frame.timestep)], np.int64)
    if frame.time is not None:
        found["TIME"] = np.array([float(frame.time)])
    return found


def _points_chunks(points: np.ndarray, binary: bool) -> Iterator[bytes]:
    yield f"POINTS {len(points)} double\n".encode("ascii")
    yield _numbers(np.asarray(points, np.float64), binary, 3)


def _mesh_chunks(frame: Frame, binary: bool) -> Iterator[bytes]:
    arrays = frame.arrays
    cells = np.asarray(arrays["cells"], np.int64).reshape(len(arrays["cells"]), -1)
    sizes = (cells >= 0).sum(axis=1)
    types = np.asarray(arrays.get("cell_types", np.where(sizes == 3, 5, np.where(sizes == 4, 9, 7))))
    keep = np.column_stack([np.ones(len(cells), bool), cells >= 0])
    connectivity = np.column_stack([sizes, cells])[keep]  # row by row: size, then the cell's points
    polydata = set(types.tolist()) <= _POLYGON_CELLS
    yield b"DATASET POLYDATA\n" if polydata else b"DATASET UNSTRUCTURED_GRID\n"
    yield from _points_chunks(arrays["points"], binary)
    section = "POLYGONS" if polydata else "CELLS"
    yield f"{section} {len(cells)} {len(connectivity)}\n".encode("ascii")
    if binary:
        yield _numbers(connectivity, binary, 1, integer=">i4")
    else:  # a cell per line, as OVITO's reader needs
        rows = zip(sizes.tolist(), cells.tolist())
        yield "".join(f"{n} {' '.join(map(str, row[:n]))}\n" for n, row in rows).encode("ascii")
    if not polydata:
        yield f"CELL_TYPES {len(cells)}\n".encode("ascii")
        yield _numbers(types.astype(np.int64), binary, 1, integer=">i4")
    timing = _timing(frame)
    if timing:
        yield from _field(timing, binary)
    for section, names, size in (
        ("CELL_DATA", frame.attrs.get("cell_data", ()), len(cells)),
        ("POINT_DATA", frame.attrs.get("point_data", ()), len(arrays["points"])),
    ):
        data = {name.split(":", 1)[-1]: arrays[name] for name in names}
        if data:
            yield f"{section} {size}\n".encode("ascii")
            yield from _field(data, binary)


def _particle_chunks(frame: Frame, binary: bool) -> Iterator[bytes]:
    arrays = dict(frame.arrays)
    missing = [axis for axis in "xyz" if axis not in arrays]
    if missing:
        raise UnsupportedFeature(f"A VTK particle file needs x, y and z; the frame lacks {missing}")
    points = np.column_stack([arrays.pop(axis) for axis in "xyz"]).astype(np.float64).reshape(-1, 3)
    data: dict[str, np.ndarray] = {}
    for name, values in arrays.items():
        triple = next((t for t in _TRIPLES if name in t), None)
        if triple is not None and all(k in arrays for k in triple):
            if name == triple[0]:
                data[_TRIPLES[triple]] = np.column_stack([arrays[k] for k in triple])
        else:
            data[name] = values
    n = len(points)
    yield b"DATASET POLYDATA\n"
    yield from _points_chunks(points, binary)
    yield f"VERTICES {n} {2 * n}\n".encode("ascii")
    yield _numbers(np.column_stack([np.ones(n, np.int64), np.arange(n)]), binary, 2, integer=">i4")
    timing = _timing(frame)
    if timing:
        yield from _field(timing, binary)
    if data:
        yield f"POINT_DATA {n}\n".encode("ascii")
        yield from _field(data, binary)
