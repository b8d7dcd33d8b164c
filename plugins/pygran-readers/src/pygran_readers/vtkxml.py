"""VTK XML files (``.vtu`` unstructured grids, ``.vtp`` polydata), parsed without the vtk package.

The XML is parsed with expat (no DTD, so no entities); the data arrays may be inline ASCII,
inline base64 binary, or appended (base64 or raw), uncompressed or compressed by
``vtkZLibDataCompressor`` or ``vtkLZMADataCompressor``, with ``UInt32`` or ``UInt64``
headers in either byte order. Every count the file states (``NumberOfPoints``,
``NumberOfCells``, ``NumberOfComponents``, a binary header's sizes, cell offsets and point
indices) is checked against the data actually present before anything is allocated or
decompressed, so a damaged file is a :class:`~pygran_core.errors.ReadError` naming the file
and the line of the element at fault, never a crash, a hang or a huge allocation.
"""

from __future__ import annotations

import binascii
import lzma
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.parsers import expat

import numpy as np

from pygran_core.errors import ReadError
from pygran_readers.dataset import Mesh, poly_cell_types

#: VTK XML type name -> numpy type code (byte order added from the file)
TYPES = {
    "Int8": "i1",
    "UInt8": "u1",
    "Int16": "i2",
    "UInt16": "u2",
    "Int32": "i4",
    "UInt32": "u4",
    "Int64": "i8",
    "UInt64": "u8",
    "Float32": "f4",
    "Float64": "f8",
}
#: polydata sections in VTK's cell order, with the legacy name of their cell kind
POLY_SECTIONS = (
    ("Verts", "VERTICES"),
    ("Lines", "LINES"),
    ("Polys", "POLYGONS"),
    ("Strips", "TRIANGLE_STRIPS"),
)
_BASE64 = re.compile(rb"[A-Za-z0-9+/]*={0,2}")
_SEGMENT = re.compile(rb"[A-Za-z0-9+/]+=*")
_SPACE = re.compile(rb"\s+")


@dataclass
class _Node:
    """One XML element: what the reader needs of it, with its line for error messages."""

    tag: str
    attrs: dict[str, str]
    line: int
    children: list[_Node] = field(default_factory=list)
    text: list[str] = field(default_factory=list)

    def child(self, tag: str) -> _Node | None:
        return next((c for c in self.children if c.tag == tag), None)

    def arrays(self) -> list[_Node]:
        return [c for c in self.children if c.tag == "DataArray"]


class _XMLFile:
    """A parsed VTK XML file: its element tree, header attributes and appended data."""

    def __init__(self, path: Path, data: bytes) -> None:
        self.path = path
        self.appended: bytes = b""
        self.appended_base64 = False
        self.appended_line = 0
        xml = data
        start = data.find(b"<AppendedData")
        if start >= 0:
            close = data.find(b">", start)
            underscore = data.find(b"_", close)
            self.appended_line = data.count(b"\n", 0, start) + 1
            if close < 0 or underscore < 0 or data[close + 1 : underscore].strip():
                raise self.fail("<AppendedData> must hold '_' followed by the data", self.appended_line)
            end = data.rfind(b"</AppendedData>")
            self.appended = data[underscore + 1 : end if end > underscore else len(data)]
            xml = data[:underscore] + b"</AppendedData></VTKFile>"
        self.root = self._parse(xml)
        if self.root.tag != "VTKFile":
            raise self.fail(f"not a VTK XML file: the root element is <{self.root.tag}>", self.root.line)
        attrs = self.root.attrs
        order = attrs.get("byte_order", "LittleEndian")
        if order not in ("LittleEndian", "BigEndian"):
            raise self.fail(f"unknown byte_order {order!r}", self.root.line)
        self.order = "<" if order == "LittleEndian" else ">"
        header = attrs.get("header_type", "UInt32")
        if header not in ("UInt32", "UInt64"):
            raise self.fail(f"header_type must be UInt32 or UInt64, not {header!r}", self.root.line)
        self.header = np.dtype(self.order + TYPES[header])
        compressor = attrs.get("compressor")
        if compressor not in (None, "vtkZLibDataCompressor", "vtkLZMADataCompressor"):
            raise self.fail(
                f"compressor {compressor!r} is not supported (vtkZLibDataCompressor and "
                "vtkLZMADataCompressor are): write the file with one of these or none",
                self.root.line,
            )
        self.compressor = compressor
        appended = self.root.child("AppendedData")
        if appended is not None:
            encoding = appended.attrs.get("encoding", "raw")
            if encoding not in ("raw", "base64"):
                raise self.fail(f"unknown AppendedData encoding {encoding!r}", appended.line)
            self.appended_base64 = encoding == "base64"
            if self.appended_base64:
                self.appended = _SPACE.sub(b"", self.appended)
        elif start >= 0:
            raise self.fail("<AppendedData> is not a child of <VTKFile>", self.appended_line)
        # where each appended base64 array ends: at the next array's offset
        self._ends: list[int] = sorted(
            {
                self.count(n, "offset")
                for n in self._all_arrays(self.root)
                if n.attrs.get("format") == "appended"
            }
            | {len(self.appended)}
        )

    def fail(self, message: str, line: int) -> ReadError:
        return ReadError(f"{self.path}: frame 0, line {line}: {message}")

    def _parse(self, xml: bytes) -> _Node:
        parser = expat.ParserCreate()
        parser.buffer_text = True
        stack: list[_Node] = []
        roots: list[_Node] = []

        def start(tag: str, attrs: dict[str, str]) -> None:
            node = _Node(tag, attrs, parser.CurrentLineNumber)
            (stack[-1].children if stack else roots).append(node)
            stack.append(node)

        def end(tag: str) -> None:
            stack.pop()

        def text(chunk: str) -> None:
            if stack and stack[-1].tag == "DataArray":
                stack[-1].text.append(chunk)

        def doctype(*args: Any) -> None:
            raise self.fail("a DOCTYPE declaration has no place in a VTK file", parser.CurrentLineNumber)

        parser.StartElementHandler = start
        parser.EndElementHandler = end
        parser.CharacterDataHandler = text
        parser.StartDoctypeDeclHandler = doctype
        try:
            parser.Parse(xml, True)
        except expat.ExpatError as exc:
            raise self.fail(f"not well-formed XML: {expat.ErrorString(exc.code)}", exc.lineno) from None
        return roots[0]

    @staticmethod
    def _all_arrays(root: _Node) -> list[_Node]:
        found, todo = [], [root]
        while todo:
            node = todo.pop()
            found.extend(node.arrays())
            todo.extend(node.children)
        return found

    def count(self, node: _Node, name: str, default: int | None = None) -> int:
        """A non-negative integer attribute."""
        text = node.attrs.get(name)
        if text is None:
            if default is None:
                raise self.fail(f"<{node.tag}> has no {name} attribute", node.line)
            return default
        try:
            value = int(text)
        except ValueError:
            raise self.fail(f"{name}={text[:40]!r} is not an integer", node.line) from None
        if value < 0:
            raise self.fail(f"{name}={value} is negative", node.line)
        return value

    # -- data arrays ---------------------------------------------------------------------------
    def array(self, node: _Node, tuples: int | None, components: int | None = None) -> np.ndarray:
        """A DataArray's values, ``(tuples,)`` or ``(tuples, k)``; ``tuples=None`` takes
        the count from ``NumberOfTuples`` or, failing that, from the data itself."""
        name = node.attrs.get("Name", "unnamed")
        code = TYPES.get(node.attrs.get("type", ""))
        if code is None:
            raise self.fail(f"array {name!r}: unsupported type {node.attrs.get('type')!r}", node.line)
        dtype = np.dtype(self.order + code)
        k = self.count(node, "NumberOfComponents", 1)
        if k == 0 or (components is not None and k != components):
            raise self.fail(
                f"array {name!r} has {k} components, expected {components or 'at least 1'}", node.line
            )
        if tuples is None and "NumberOfTuples" in node.attrs:
            tuples = self.count(node, "NumberOfTuples")
        expected = None if tuples is None else tuples * k
        need = f"{tuples} tuples of {k} {node.attrs['type']} need"  # for messages
        form = node.attrs.get("format", "ascii")
        if form == "ascii":
            values = self._ascii(node, dtype, expected, need)
        elif form == "binary":
            data = self._decode("".join(node.text).encode("latin-1"), node)
            values = self._binary(node, data, 0, dtype, expected, need)
        elif form == "appended":
            offset = self.count(node, "offset")
            if self.appended_base64:
                end = next(e for e in self._ends if e > offset) if offset < len(self.appended) else offset
                data = self._decode(self.appended[offset:end], node)
                values = self._binary(node, data, 0, dtype, expected, need)
            else:
                values = self._binary(node, self.appended, offset, dtype, expected, need)
        else:
            raise self.fail(f"array {name!r}: unknown format {form!r}", node.line)
        if len(values) % k:
            raise self.fail(
                f"array {name!r}: {len(values)} values are not whole {k}-component tuples", node.line
            )
        values = values.astype(dtype.newbyteorder("="))
        return values.reshape(-1, k) if k > 1 else values

    def _ascii(self, node: _Node, dtype: np.dtype, expected: int | None, need: str) -> np.ndarray:
        tokens = "".join(node.text).split()
        name = node.attrs.get("Name", "unnamed")
        if expected is not None and len(tokens) != expected:
            raise self.fail(f"array {name!r} holds {len(tokens)} values; {need} {expected}", node.line)
        try:
            if dtype.kind == "f":
                return np.array(tokens, dtype=np.float64).astype(dtype)
            values = np.array(tokens, dtype=np.int64 if dtype.kind == "i" else np.uint64)
        except (ValueError, OverflowError) as exc:
            raise self.fail(
                f"array {name!r}: not a list of {dtype.name} numbers ({exc})", node.line
            ) from None
        limits = np.iinfo(dtype)
        if len(values) and (values.min() < limits.min or values.max() > limits.max):
            raise self.fail(f"array {name!r}: a value does not fit in {dtype.name}", node.line)
        return values.astype(dtype)

    def _decode(self, text: bytes, node: _Node) -> bytes:
        """Base64 that may be several encoded pieces one after the other (VTK encodes a
        compressed array's header and its data separately)."""
        text = _SPACE.sub(b"", text)
        if not _BASE64.fullmatch(text.replace(b"=", b"")):
            raise self.fail(f"array {node.attrs.get('Name', 'unnamed')!r}: the data is not base64", node.line)
        try:
            return b"".join(binascii.a2b_base64(piece) for piece in _SEGMENT.findall(text))
        except binascii.Error as exc:
            raise self.fail(
                f"array {node.attrs.get('Name', 'unnamed')!r}: bad base64 ({exc})", node.line
            ) from None

    def _binary(
        self, node: _Node, data: bytes, at: int, dtype: np.dtype, expected: int | None, need: str
    ) -> np.ndarray:
        """An array from binary data at ``at``: header (sizes), then raw or compressed bytes;
        ``expected`` values (if known) must be there, ``need`` says where they come from."""
        name = node.attrs.get("Name", "unnamed")

        def fail(message: str) -> ReadError:
            return self.fail(f"array {name!r}: {message}", node.line)

        def header(items: int, start: int) -> list[int]:
            size = items * self.header.itemsize
            if start > len(data) or start + size > len(data):
                raise fail(f"the data ends inside its {items}-item header")
            return [int(v) for v in np.frombuffer(data, self.header, items, start)]

        if self.compressor is None:
            (size,) = header(1, at)
            start = at + self.header.itemsize
            if expected is not None and size != expected * dtype.itemsize:
                raise fail(f"its header says {size} bytes; {need} {expected * dtype.itemsize}")
            if size % dtype.itemsize or start + size > len(data):
                raise fail(f"the header says {size} bytes but {len(data) - start} are there")
            return np.frombuffer(data, dtype, size // dtype.itemsize, start)
        blocks, block_size, last_size = header(3, at)
        if blocks > (len(data) - at) // self.header.itemsize:
            raise fail(f"the header counts {blocks} compressed blocks, more than the data can hold")
        sizes = header(3 + blocks, at)[3:]
        total = 0 if blocks == 0 else (blocks - 1) * block_size + (last_size or block_size)
        if blocks and (block_size == 0 or last_size > block_size):
            raise fail(f"bad compression header: block size {block_size}, last block {last_size}")
        if expected is not None and total != expected * dtype.itemsize:
            raise fail(f"its compression header says {total} bytes; {need} {expected * dtype.itemsize}")
        if total % dtype.itemsize:
            raise fail(f"{total} bytes are not whole {dtype.name} values")
        start = at + (3 + blocks) * self.header.itemsize
        if sum(sizes) > len(data) - start:
            raise fail(f"the compressed blocks need {sum(sizes)} bytes, {len(data) - start} are there")
        parts = []
        for index, size in enumerate(sizes):
            want = last_size if index == blocks - 1 and last_size else block_size
            parts.append(self._inflate(data[start : start + size], want, fail))
            start += size
        return np.frombuffer(b"".join(parts), dtype)

    def _inflate(self, block: bytes, size: int, fail: Any) -> bytes:
        """One compressed block, which must inflate to exactly ``size`` bytes (never more is made)."""
        try:
            if self.compressor == "vtkLZMADataCompressor":
                lz = lzma.LZMADecompressor()
                out = lz.decompress(block, max_length=size)
                complete = lz.eof
            else:
                zl = zlib.decompressobj()
                out = zl.decompress(block, size)
                complete = zl.eof
        except (zlib.error, lzma.LZMAError, OverflowError) as exc:
            raise fail(f"a compressed block is damaged ({exc})") from None
        if len(out) != size or not complete:
            raise fail(f"a compressed block inflates to {len(out)} bytes, not {size}")
        return out


def _points(xml: _XMLFile, piece: _Node, n: int) -> np.ndarray:
    node = piece.child("Points")
    arrays = node.arrays() if node is not None else []
    if not arrays:
        if n:
            raise xml.fail(f"the piece has {n} points but no <Points> array", piece.line)
        return np.empty((0, 3))
    return xml.array(arrays[0], n, 3).astype(np.float64).reshape(n, 3)


def _cells(xml: _XMLFile, piece: _Node, where: str, n_cells: int, n_points: int) -> list[np.ndarray]:
    """The cells of a piece's Cells/Verts/Lines/Polys/Strips: ``connectivity`` split at
    ``offsets`` (the end of each cell)."""
    parent = piece.child(where)
    arrays = {} if parent is None else {a.attrs.get("Name", ""): a for a in parent.arrays()}
    if n_cells == 0 and not arrays:
        return []
    for name in ("connectivity", "offsets"):
        if name not in arrays:
            raise xml.fail(f"<{where}> has no {name!r} array", (parent or piece).line)
    offsets = xml.array(arrays["offsets"], n_cells).astype(np.int64)
    if n_cells and (offsets[0] < 0 or np.any(np.diff(offsets) < 0)):
        raise xml.fail(f"<{where}> offsets do not increase from 0", arrays["offsets"].line)
    node = arrays["connectivity"]
    connectivity = xml.array(node, None).astype(np.int64)
    end = int(offsets[-1]) if n_cells else 0
    if len(connectivity) != end:
        raise xml.fail(
            f"<{where}> connectivity has {len(connectivity)} values, the offsets use {end}", node.line
        )
    if end and (connectivity.min() < 0 or connectivity.max() >= n_points):
        bad = int(connectivity.max() if connectivity.max() >= n_points else connectivity.min())
        raise xml.fail(f"<{where}> refers to point {bad} but the piece has {n_points} points", node.line)
    return np.split(connectivity, offsets[:-1]) if n_cells else []


def _data(xml: _XMLFile, parent: _Node | None, n: int | None) -> dict[str, np.ndarray]:
    """The named arrays of a PointData, CellData or FieldData element."""
    found: dict[str, np.ndarray] = {}
    for node in [] if parent is None else parent.arrays():
        name = node.attrs.get("Name")
        if not name:
            raise xml.fail("a data array has no Name", node.line)
        found[name] = xml.array(node, n)
    return found


def _merge(parts: list[dict[str, np.ndarray]], xml: _XMLFile, what: str) -> dict[str, np.ndarray]:
    """Per-piece data arrays joined; every piece must have the same ones."""
    names = list(parts[0])
    if any(list(p) != names or any(p[n].shape[1:] != parts[0][n].shape[1:] for n in names) for p in parts):
        raise xml.fail(f"the pieces have different {what} arrays", xml.root.line)
    return {name: np.concatenate([p[name] for p in parts]) for name in names}


def read_xml(path: Path) -> Mesh:
    """Parse a VTK XML unstructured grid (``.vtu``) or polydata (``.vtp``) file."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ReadError(f"{path}: frame 0: cannot read the file: {exc}") from exc
    xml = _XMLFile(path, data)
    kind = xml.root.attrs.get("type")
    if kind not in ("UnstructuredGrid", "PolyData"):
        raise xml.fail(f"only UnstructuredGrid and PolyData files are read, this is {kind!r}", xml.root.line)
    dataset = xml.root.child(kind)
    if dataset is None:
        raise xml.fail(f"no <{kind}> element", xml.root.line)
    pieces = [c for c in dataset.children if c.tag == "Piece"]
    if not pieces:
        raise xml.fail(f"<{kind}> has no <Piece>", dataset.line)
    points: list[np.ndarray] = []
    cells: list[np.ndarray] = []
    types: list[int] = []
    point_data: list[dict[str, np.ndarray]] = []
    cell_data: list[dict[str, np.ndarray]] = []
    for piece in pieces:
        n_points = xml.count(piece, "NumberOfPoints")
        points.append(_points(xml, piece, n_points))
        if kind == "UnstructuredGrid":
            n_cells = xml.count(piece, "NumberOfCells")
            found = _cells(xml, piece, "Cells", n_cells, n_points)
            node = piece.child("Cells")
            named = {} if node is None else {a.attrs.get("Name", ""): a for a in node.arrays()}
            if n_cells and "types" not in named:
                raise xml.fail("<Cells> has no 'types' array", (node or piece).line)
            piece_types = xml.array(named["types"], n_cells).astype(np.int64).tolist() if n_cells else []
        else:
            found, piece_types = [], []
            for section, legacy in POLY_SECTIONS:
                section_cells = _cells(
                    xml, piece, section, xml.count(piece, f"NumberOf{section}", 0), n_points
                )
                found.extend(section_cells)
                piece_types.extend(poly_cell_types(legacy, section_cells))
            n_cells = len(found)
        base = sum(len(p) for p in points[:-1])
        cells.extend(c + base for c in found)
        types.extend(piece_types)
        point_data.append(_data(xml, piece.child("PointData"), n_points))
        cell_data.append(_data(xml, piece.child("CellData"), n_cells))
    return Mesh(
        np.concatenate(points),
        cells,
        types,
        _merge(point_data, xml, "point data"),
        _merge(cell_data, xml, "cell data"),
        _data(xml, dataset.child("FieldData"), None),
    )
