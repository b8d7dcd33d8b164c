"""LIGGGHTS / LAMMPS text dump: lazy multi-frame reader and appending writer.

Opening scans each file once for the line that starts every frame (normally
``ITEM: TIMESTEP``) and keeps only byte offsets and line numbers. ``read_frame(i)`` seeks,
reads the frame's bytes in one call and parses the atom block in one pass into a
column-major table: with pygran-native's compiled parser when it is installed, else (and for
anything that parser does not accept) with ``numpy.loadtxt``. Both round every number
correctly, so they give the same values; there is no Python loop per line or per field.
"""

from __future__ import annotations

import gzip
import io
import re
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from pygran_core._compiled import kernels as _accel
from pygran_core.errors import ReadError, UnsupportedFeature, did_you_mean
from pygran_core.formats.base import Frame, PathLike, Trajectory, TrajectoryWriter

#: Columns read as integers.
INT_COLUMNS = frozenset({"id", "type", "mol", "proc", "procp1", "ix", "iy", "iz"})
#: Per-atom keywords of LAMMPS ``dump custom`` and LIGGGHTS, besides computes/fixes/variables.
KNOWN_COLUMNS = INT_COLUMNS | frozenset(
    """mass x y z xs ys zs xu yu zu xsu ysu zsu vx vy vz fx fy fz q mux muy muz mu radius
    diameter density omegax omegay omegaz angmomx angmomy angmomz tqx tqy tqz p rho
    shapex shapey shapez quat1 quat2 quat3 quat4 blockiness1 blockiness2 heatflux
    heatsource temperature""".split()
)
#: Custom columns: computes, fixes, variables and per-atom properties, optionally indexed.
CUSTOM_COLUMN = re.compile(r"^(c|f|v|d|i|d2|i2)_[A-Za-z0-9_\-]+(\[\d+\])*$")
#: Scaled column -> unscaled name and axis.
SCALED = {
    "xs": ("x", 0),
    "ys": ("y", 1),
    "zs": ("z", 2),
    "xsu": ("xu", 0),
    "ysu": ("yu", 1),
    "zsu": ("zu", 2),
}
_CHUNK = 1 << 24
#: What reading a damaged or truncated file raises (gzip.BadGzipFile is an OSError).
_STREAM_ERRORS = (OSError, EOFError, zlib.error)
_FRAME_START = re.compile(rb"^(ITEM: TIME(?:STEP)?)[ \t\r]*$", re.MULTILINE)
_NOT_BLANK = re.compile(rb"\S")


@dataclass(frozen=True)
class _Block:
    """Where one frame lives: file, byte range and the line number of its first line."""

    file: int
    start: int
    end: int
    line: int
    problem: str | None = None  # known before parsing, e.g. a truncated gzip stream


def _open_binary(path: Path) -> io.BufferedIOBase:
    if path.name.lower().endswith(".gz"):
        return gzip.open(path, "rb")
    return open(path, "rb")


def can_open(path: Path) -> bool:
    """True when the file's first bytes are a dump ``ITEM:`` line."""
    try:
        with _open_binary(path) as handle:
            return handle.read(64).lstrip().startswith(b"ITEM:")
    except Exception:  # noqa: BLE001 - a hint must never raise
        return False


def _read_chunk(handle: io.BufferedIOBase) -> tuple[bytes, str | None]:
    """Up to ``_CHUNK`` bytes, and what went wrong if the (compressed) stream broke off."""
    parts: list[bytes] = []
    size = 0
    try:
        while size < _CHUNK:
            part = handle.read1(_CHUNK - size)
            if not part:
                break
            parts.append(part)
            size += len(part)
    except _STREAM_ERRORS as exc:
        return b"".join(parts), f"the compressed stream is damaged ({exc})"
    return b"".join(parts), None


def _newlines(buf: bytes, start: int, stop: int) -> int:
    """``buf.count(b"\\n", start, stop)``, counted by numpy (several times faster)."""
    return int(np.count_nonzero(np.frombuffer(buf, np.uint8, max(stop - start, 0), start) == 10))


def _scan(path: Path, file_index: int) -> list[_Block]:
    """Blocks of one file: every frame starts with the same line as the file's first line."""
    try:
        with _open_binary(path) as handle:
            head, problem = _read_chunk(handle)
            first_line = head.split(b"\n", 1)[0].rstrip()
            if not first_line.startswith(b"ITEM:") or (problem and b"\n" not in head):
                reason = problem or (
                    f"not a LAMMPS dump: the first line is {first_line[:60].decode('latin-1')!r}, "
                    "not an ITEM: line"
                )
                return [_Block(file_index, 0, len(head), 1, reason)]
            # A frame starts at ITEM: TIME when present (LAMMPS writes it before the
            # timestep), else at ITEM: TIMESTEP; ITEM: UNITS appears in the first frame only.
            found = _FRAME_START.search(head)
            marker = b"\n" + (found.group(1) if found else first_line)
            skip = 0 if head.startswith(marker[1:]) else 1
            starts, lines = [0], [1]
            buf, base, counted, line = head, 0, 0, 1  # buf = file[base:base+len(buf)]
            while True:
                pos = buf.find(marker)
                while pos >= 0:
                    after = buf[pos + len(marker) : pos + len(marker) + 1]
                    if after in (b"\n", b"\r", b" ", b"\t") and skip:
                        skip -= 1
                    elif after in (b"\n", b"\r", b" ", b"\t"):
                        line += _newlines(buf, counted, pos + 1)
                        counted = pos + 1
                        starts.append(base + pos + 1)
                        lines.append(line)
                    pos = buf.find(marker, pos + 1)
                chunk, problem = (b"", problem) if problem else _read_chunk(handle)
                if not chunk:
                    end = base + len(buf)
                    break
                keep = len(marker)
                cut = max(len(buf) - keep, 0)
                line += _newlines(buf, counted, cut)
                base, buf, counted = base + cut, buf[cut:] + chunk, 0
    except _STREAM_ERRORS as exc:
        raise ReadError(f"{path}: cannot read the file: {exc}") from exc
    ends = [*starts[1:], end]
    blocks = [_Block(file_index, s, e, ln) for s, e, ln in zip(starts, ends, lines)]
    if problem is not None:
        blocks[-1] = _Block(file_index, blocks[-1].start, blocks[-1].end, blocks[-1].line, problem)
    return blocks


@dataclass
class _Header:
    timestep: int | None = None
    time: float | None = None
    natoms: int | None = None
    box: np.ndarray | None = None
    tilt: np.ndarray | None = None
    boundary: tuple[str, ...] | None = None
    units: str | None = None
    columns: list[str] | None = None
    natoms_line: int = 0
    body: int = 0  # byte offset of the atom block within the frame
    body_line: int = 0  # its line number


class DumpTrajectory(Trajectory):
    """Frames of one or more dump files (plain or ``.gz``), in the order given.

    ``extra_columns`` names further per-atom columns to accept (read as floats); any other
    column that is neither a LAMMPS/LIGGGHTS keyword nor ``c_``/``f_``/``v_``/``d_``/``i_``
    custom column is a :class:`ReadError`.
    """

    def __init__(self, paths: Sequence[PathLike], extra_columns: Iterable[str] = ()) -> None:
        self.paths = [Path(p) for p in paths]
        self.extra_columns = frozenset(extra_columns)
        self._blocks: list[_Block] = []
        for index, path in enumerate(self.paths):
            self._blocks.extend(_scan(path, index))
        self._gz: tuple[int, io.BufferedIOBase] | None = None

    @property
    def n_frames(self) -> int:
        return len(self._blocks)

    def close(self) -> None:
        if self._gz is not None:
            self._gz[1].close()
            self._gz = None

    def _read_bytes(self, index: int, block: _Block) -> bytes:
        """The bytes of ``block`` (frame ``index``, or its start)."""
        path = self.paths[block.file]
        try:
            if path.name.lower().endswith(".gz"):
                if self._gz is None or self._gz[0] != block.file:
                    self.close()
                    self._gz = (block.file, gzip.open(path, "rb"))
                handle = self._gz[1]
                handle.seek(block.start)
                return handle.read(block.end - block.start)
            with open(path, "rb") as handle:
                handle.seek(block.start)
                return handle.read(block.end - block.start)
        except _STREAM_ERRORS as exc:
            self.close()
            raise self._error(index, block.line, f"cannot read the frame: {exc}") from exc

    def _error(self, index: int, line: int, message: str) -> ReadError:
        block = self._blocks[index]
        return ReadError(f"{self.paths[block.file]}: frame {index}, line {line}: {message}")

    def _read_frame(self, index: int) -> Frame:
        block = self._blocks[index]
        if block.problem is not None:
            raise self._error(index, block.line, block.problem)
        data = self._read_bytes(index, block)
        header = self._parse_header(index, data)
        table = self._parse_atoms(index, data, header)
        return self._build_frame(index, header, table)

    def read_header(self, index: int) -> dict[str, Any]:
        """Timestep, atom count, box and columns of frame ``index`` without parsing its atoms."""
        index %= self.n_frames
        block = self._blocks[index]
        if block.problem is not None:
            raise self._error(index, block.line, block.problem)
        head = self._read_bytes(
            index, _Block(block.file, block.start, min(block.end, block.start + 65536), block.line)
        )
        header = self._parse_header(index, head)
        return {
            "timestep": header.timestep,
            "natoms": header.natoms,
            "box": header.box,
            "boundary": header.boundary,
            "columns": header.columns,
        }

    def _parse_header(self, index: int, data: bytes) -> _Header:
        header = _Header()
        line_no = self._blocks[index].line
        pos = 0

        def next_line() -> str:
            nonlocal pos, line_no
            end = data.find(b"\n", pos)
            if end < 0:
                if pos >= len(data):
                    raise self._error(index, line_no, "the frame is truncated inside its header")
                end = len(data)
            text = data[pos:end].decode("latin-1").strip()
            pos, line_no = end + 1, line_no + 1
            return text

        def number(kind: type, text: str, what: str) -> Any:
            try:
                return kind(text)
            except ValueError:
                raise self._error(index, line_no - 1, f"{what} {text!r} is not a number") from None

        while True:
            item = next_line()
            if not item.startswith("ITEM:"):
                raise self._error(index, line_no - 1, f"expected an ITEM: line, found {item[:60]!r}")
            words = item[5:].split()
            name = " ".join(words)
            if name == "TIMESTEP":
                header.timestep = number(int, next_line(), "timestep")
            elif name == "TIME":
                header.time = number(float, next_line(), "time")
            elif name == "UNITS":
                header.units = next_line()
            elif name == "NUMBER OF ATOMS":
                header.natoms = number(int, next_line(), "atom count")
                header.natoms_line = line_no - 1
                if header.natoms < 0:
                    raise self._error(index, line_no - 1, f"negative atom count {header.natoms}")
            elif name.startswith("BOX BOUNDS"):
                flags = words[2:]
                triclinic = flags[:3] == ["xy", "xz", "yz"]
                flags = flags[3:] if triclinic else flags
                header.boundary = tuple(flags) if len(flags) == 3 else None
                rows = []
                for _ in range(3):
                    text = next_line()
                    values = [number(float, v, "box bound") for v in text.split()]
                    if len(values) != (3 if triclinic else 2):
                        raise self._error(index, line_no - 1, f"bad box bounds line {text!r}")
                    rows.append(values)
                table = np.array(rows, dtype=np.float64)
                header.box = np.ascontiguousarray(table[:, :2])
                header.tilt = table[:, 2].copy() if triclinic else None
            elif name.startswith("ATOMS"):
                header.columns = words[1:]
                self._check_columns(index, line_no - 1, header.columns)
                break
            else:
                raise self._error(index, line_no - 1, f"unknown header item {item!r}")
        if header.natoms is None:
            raise self._error(index, line_no - 1, "the frame has no ITEM: NUMBER OF ATOMS")
        header.body, header.body_line = pos, line_no
        return header

    def _check_columns(self, index: int, line: int, columns: list[str]) -> None:
        for name in columns:
            if name in KNOWN_COLUMNS or name in self.extra_columns or CUSTOM_COLUMN.match(name):
                continue
            raise self._error(
                index,
                line,
                f"unknown column {name!r}.{did_you_mean(name, KNOWN_COLUMNS)} "
                "Pass extra_columns=[...] to read it as floats.",
            )
        if len(set(columns)) != len(columns):
            raise self._error(index, line, f"repeated column names in {columns}")
        if not columns:
            raise self._error(index, line, "ITEM: ATOMS names no columns")

    def _parse_atoms(self, index: int, data: bytes, header: _Header) -> np.ndarray:
        assert header.columns is not None and header.natoms is not None
        body = memoryview(data)[header.body :]
        ncols, natoms = len(header.columns), header.natoms
        if natoms == 0:
            if _NOT_BLANK.search(body):
                raise self._error(index, header.body_line, "the header says 0 atoms but rows follow")
            return np.empty((0, ncols))
        table = None if _accel is None else _accel.parse_table(body, ncols, natoms)
        if table is None:
            table = self._loadtxt(index, body, header)
        if table.shape[1] != ncols:
            raise self._error(
                index,
                header.body_line,
                f"rows have {table.shape[1]} fields but ITEM: ATOMS names {ncols} columns",
            )
        if table.shape[0] != natoms:
            last = self._blocks[index].end == self._file_end(index)
            if table.shape[0] < natoms and last:
                reason = "the frame is truncated (or its header lies about the atom count)"
            else:
                reason = "the header lies about the atom count"
            raise self._error(
                index,
                header.natoms_line,
                f"{reason}: ITEM: NUMBER OF ATOMS says {natoms} but {table.shape[0]} rows follow",
            )
        return table

    def _loadtxt(self, index: int, body: memoryview, header: _Header) -> np.ndarray:
        """The atom rows parsed by numpy.loadtxt, column-major; a ReadError names the bad row."""
        assert header.columns is not None
        if not _NOT_BLANK.search(body):
            return np.empty((0, len(header.columns)))
        text = bytes(body)
        try:
            table = np.loadtxt(io.BytesIO(text), dtype=np.float64, comments=None, ndmin=2, encoding="latin-1")
        except ValueError as exc:
            raise self._locate(index, text, header, str(exc)) from None
        return np.asfortranarray(table)

    def _file_end(self, index: int) -> int:
        file = self._blocks[index].file
        return max(b.end for b in self._blocks if b.file == file)

    def _locate(self, index: int, body: bytes, header: _Header, reason: str) -> ReadError:
        """The first bad row of an atom block (only on the error path, so a Python loop is fine)."""
        assert header.columns is not None
        ncols = len(header.columns)
        for offset, raw in enumerate(body.split(b"\n")):
            fields = raw.split()
            if not fields:
                continue
            line = header.body_line + offset
            if len(fields) != ncols:
                truncated = offset == body.count(b"\n") and not body.endswith(b"\n")
                what = "the frame is truncated: " if truncated else ""
                return self._error(index, line, f"{what}row has {len(fields)} fields, expected {ncols}")
            for name, field in zip(header.columns, fields):
                try:
                    float(field)
                except ValueError:
                    return self._error(
                        index, line, f"column {name!r} holds {field.decode('latin-1')[:40]!r}, not a number"
                    )
        return self._error(index, header.body_line, f"cannot parse the atom block: {reason}")

    def _build_frame(self, index: int, header: _Header, table: np.ndarray) -> Frame:
        assert header.columns is not None
        arrays: dict[str, np.ndarray] = {}
        for j, name in enumerate(header.columns):
            column = table[:, j]
            if name in INT_COLUMNS:
                with np.errstate(invalid="ignore"):
                    as_int = column.astype(np.int64)
                if not np.array_equal(as_int, column):
                    row = int(np.flatnonzero(as_int != column)[0])
                    raise self._error(
                        index, header.body_line + row, f"integer column {name!r} holds {float(column[row])!r}"
                    )
                arrays[name] = as_int
            else:
                arrays[name] = np.ascontiguousarray(column)
        if any(name in SCALED for name in arrays):
            if header.box is None:
                raise self._error(index, header.body_line, "scaled coordinates need ITEM: BOX BOUNDS")
            arrays = _unscale(arrays, header.box, header.tilt)
        attrs: dict[str, Any] = {}
        if header.tilt is not None:
            attrs["tilt"] = header.tilt
        if header.units is not None:
            attrs["units"] = header.units
        return Frame(
            arrays,
            timestep=header.timestep,
            time=header.time,
            box=header.box,
            boundary=header.boundary,
            attrs=attrs,
        )


def _unscale(
    arrays: dict[str, np.ndarray], bounds: np.ndarray, tilt: np.ndarray | None
) -> dict[str, np.ndarray]:
    """Replace ``xs ys zs`` (and ``xsu ysu zsu``) by box coordinates, triclinic included."""
    xy, xz, yz = tilt if tilt is not None else (0.0, 0.0, 0.0)
    lo = bounds[:, 0] - [min(0.0, xy, xz, xy + xz), min(0.0, yz), 0.0]
    hi = bounds[:, 1] - [max(0.0, xy, xz, xy + xz), max(0.0, yz), 0.0]
    length = hi - lo
    out: dict[str, np.ndarray] = {}
    for name, values in arrays.items():
        if name not in SCALED:
            out[name] = values
            continue
        target, axis = SCALED[name]
        group = ("xs", "ys", "zs") if target in "xyz" else ("xsu", "ysu", "zsu")
        s = [arrays.get(g, np.zeros_like(values)) for g in group]
        if axis == 0:
            out[target] = lo[0] + s[0] * length[0] + s[1] * xy + s[2] * xz
        elif axis == 1:
            out[target] = lo[1] + s[1] * length[1] + s[2] * yz
        else:
            out[target] = lo[2] + s[2] * length[2]
    return out


class DumpWriter(TrajectoryWriter):
    """Writes particle frames as a LIGGGHTS/LAMMPS text dump.

    A ``*`` in the file name writes one file per frame with the timestep in its place (as
    LIGGGHTS does); otherwise frames are appended to one file. Floats are written with the
    shortest text that reads back to the same float64, integers exactly.
    """

    def __init__(self, path: PathLike, **options: Any) -> None:
        if options:
            raise UnsupportedFeature(f"The dump writer takes no options, got {sorted(options)}")
        self.path = Path(path)
        self.count = 0
        self._handle: IO[bytes] | None = None

    def write_frame(self, frame: Frame) -> None:
        text = format_frame(frame, self.count).encode("ascii")
        if "*" in self.path.name:
            step = frame.timestep if frame.timestep is not None else self.count
            with open(self.path.with_name(self.path.name.replace("*", str(step))), "wb") as handle:
                handle.write(text)
        else:
            if self._handle is None:
                self._handle = open(self.path, "wb")
            self._handle.write(text)
            self._handle.flush()
        self.count += 1

    def close(self) -> None:
        if self._handle is not None:
            self._handle.close()
            self._handle = None


def format_frame(frame: Frame, index: int = 0) -> str:
    """One frame as dump text."""
    columns = list(frame.arrays)
    bad = [c for c in columns if np.ndim(frame.arrays[c]) != 1]
    if bad:
        raise UnsupportedFeature(
            f"A dump holds one value per particle per column; {bad} are not 1-D (is this a mesh frame?)"
        )
    n = len(frame.arrays[columns[0]]) if columns else 0
    box = frame.box if frame.box is not None else _bounding_box(frame)
    tilt = frame.attrs.get("tilt")
    boundary = " ".join(frame.boundary) if frame.boundary else "pp pp pp"
    step = frame.timestep if frame.timestep is not None else index
    lines = [f"ITEM: TIMESTEP\n{int(step)}\n"]
    if frame.time is not None:
        lines.insert(0, f"ITEM: TIME\n{float(frame.time)!r}\n")
    lines.append(f"ITEM: NUMBER OF ATOMS\n{n}\n")
    if tilt is None:
        lines.append(f"ITEM: BOX BOUNDS {boundary}\n")
        lines += [f"{float(lo)!r} {float(hi)!r}\n" for lo, hi in np.asarray(box)]
    else:
        lines.append(f"ITEM: BOX BOUNDS xy xz yz {boundary}\n")
        lines += [f"{float(lo)!r} {float(hi)!r} {float(t)!r}\n" for (lo, hi), t in zip(box, tilt)]
    lines.append("ITEM: ATOMS " + " ".join(columns) + "\n")
    if n:
        values = []
        formats = []
        for name in columns:
            array = np.asarray(frame.arrays[name])
            if array.dtype.kind in "iub":
                formats.append("%d")
                values.append(array.astype(np.int64).tolist())
            else:
                formats.append("%r")
                values.append(array.astype(np.float64).tolist())
        row = " ".join(formats) + "\n"
        flat = [v for record in zip(*values) for v in record]
        lines.append((row * n) % tuple(flat))
    return "".join(lines)


def _bounding_box(frame: Frame) -> np.ndarray:
    box = np.zeros((3, 2))
    for axis, name in enumerate("xyz"):
        values = frame.arrays.get(name)
        if values is not None and len(values):
            box[axis] = values.min(), values.max()
    return box
