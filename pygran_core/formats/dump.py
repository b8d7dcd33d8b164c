"""LIGGGHTS / LAMMPS text dump: lazy multi-frame reader and appending writer.

Frames are ``dump custom`` atoms (``ITEM: ATOMS``) or ``dump local`` entries
(``ITEM: ENTRIES``): the contact records of :mod:`~pygran_core.formats.contacts`, under their
own names as PyGran writes them or as the ``c_ID[k]`` columns of LIGGGHTS' ``compute
pair/gran/local`` (mapped with ``compute=...``), or any other local quantities.

Opening scans each file once for the line that starts every frame (normally
``ITEM: TIMESTEP``) and keeps only byte offsets and line numbers. ``read_frame(i)`` seeks,
reads the frame's bytes in one call and parses the atom block in one pass into a
column-major table: with the core's compiled parser when it is built, else (and for
anything that parser does not accept) with ``numpy.loadtxt``. Both round every number
correctly, so they give the same values; there is no Python loop per line or per field.

A ``.dump.gz`` cannot be seeked, so its scan decompresses it (with zlib, once) and keeps the
text of its first frames, up to :data:`GZIP_KEEP_BYTES` per trajectory; with the compiled
parser and more than one CPU, a second thread parses the atom rows of the frames kept while
the scan goes on (their tables count in the same budget). A frame kept is let go once read;
any other is decompressed again from the nearest restart point (one every ``_RESTART_SPAN``
bytes of text), or from where the last read stopped when reading in order.
"""

from __future__ import annotations

import dataclasses
import gzip
import io
import os
import re
import zlib
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import IO, Any

import numpy as np

from pygran_core._compiled import kernels as _accel
from pygran_core.errors import ReadError, UnsupportedFeature, WriteError, did_you_mean
from pygran_core.formats import contacts as _contacts
from pygran_core.formats.base import Frame, PathLike, Trajectory, TrajectoryWriter
from pygran_core.formats.sanity import particle_problem, step_problem

#: Columns read as integers.
INT_COLUMNS = frozenset({"id", "type", "mol", "proc", "procp1", "ix", "iy", "iz"})
#: Per-atom keywords of LAMMPS ``dump custom`` and LIGGGHTS, besides computes/fixes/variables.
KNOWN_COLUMNS = INT_COLUMNS | frozenset(
    """mass x y z xs ys zs xu yu zu xsu ysu zsu vx vy vz fx fy fz q mux muy muz mu radius
    diameter density omegax omegay omegaz angmomx angmomy angmomz tqx tqy tqz p rho
    shapex shapey shapez quat1 quat2 quat3 quat4 blockiness1 blockiness2 heatflux
    heatsource temperature""".split()
)
#: Columns of ``dump local`` read as integers (besides the contacts' ids).
LOCAL_INT_COLUMNS = frozenset({"index"}) | _contacts.INT_COLUMNS
#: Columns of ``dump local`` frames besides custom ones: LAMMPS' ``index``, the contacts'.
LOCAL_COLUMNS = frozenset({"index", *_contacts.COLUMNS})
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
#: Decompressed text of ``.dump.gz`` files that opening a trajectory keeps, in all: each frame
#: kept is served from memory (one decompression in all) and let go once read; the text past it
#: is decompressed again when read, from the nearest restart point.
GZIP_KEEP_BYTES = 256 << 20
#: Decompressed bytes between two restart points of a ``.dump.gz`` (each a copy of zlib's
#: state, about 40 kB), so reading any frame decompresses at most this much besides it.
_RESTART_SPAN = 32 << 20
#: Compressed bytes given to zlib at a time.
_FEED = 1 << 18
_GZIP_MAGIC = b"\x1f\x8b"
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


def _is_gzip(path: Path) -> bool:
    return path.name.lower().endswith(".gz")


@dataclass(frozen=True)
class _Restart:
    """A point a gzip file can be decompressed from: the decompressed offset, the file offset of
    the next compressed bytes, zlib's state (None before the first member) and its unread input."""

    position: int
    offset: int
    state: zlib._Decompress | None
    pending: bytes


class _Inflater:
    """Decompresses a gzip file with zlib, from its start or from a restart point, as gzip.open
    reads it (every member, zero padding between them, the same errors), in pieces of at most
    ``_CHUNK`` bytes: one pass, no copy of the text."""

    def __init__(self, path: Path, restart: _Restart | None = None) -> None:
        start = restart or _Restart(0, 0, None, b"")
        self._file = open(path, "rb")
        self._file.seek(start.offset)
        self.position = start.position  # decompressed offset of the next byte read() returns
        self._state: zlib._Decompress | None = None if start.state is None else start.state.copy()
        self._pending = start.pending
        self._started = start.state is not None
        self._ahead = b""
        self._damage: zlib.error | None = None  # raised by the next read()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> _Inflater:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def restart(self) -> _Restart | None:
        """A restart point at the current position (None between two members)."""
        if self._state is None or self._ahead:
            return None
        return _Restart(self.position, self._file.tell(), self._state.copy(), self._pending)

    def unread(self, data: bytes) -> None:
        """Give back the end of the last piece: the next read() returns it first."""
        self._ahead = data
        self.position -= len(data)

    def read(self) -> bytes:
        """The next decompressed bytes; b"" at the end of the file."""
        if self._ahead:
            out, self._ahead = self._ahead, b""
            self.position += len(out)
            return out
        if self._damage is not None:
            raise self._damage
        while True:
            state = self._state or self._next_member()
            if state is None:
                return b""
            data = self._pending or self._file.read(_FEED)
            if not data:
                raise EOFError("Compressed file ended before the end-of-stream marker was reached")
            before = state.copy()
            try:
                out = state.decompress(data, _CHUNK)
            except zlib.error as exc:
                out, self._damage = self._salvage(before, data), exc
                if not out:
                    raise
                self.position += len(out)
                return out
            self._pending = state.unconsumed_tail
            if state.eof:
                self._pending, self._state = state.unused_data, None
            if out:
                self.position += len(out)
                return out

    @staticmethod
    def _salvage(state: zlib._Decompress, data: bytes) -> bytes:
        """The text before the damage in ``data`` (zlib gives none when a call meets damage)."""
        out: list[bytes] = []
        for start in range(0, len(data), 256):
            try:
                out.append(state.decompress(data[start : start + 256]))
            except zlib.error:
                break
        return b"".join(out)

    def _next_member(self) -> zlib._Decompress | None:
        """Start the next member; None at the end of the file."""
        data = self._pending
        while True:
            if self._started:  # zero bytes may pad a file after a member
                data = data.lstrip(b"\0")
            if len(data) >= 2:
                break
            more = self._file.read(_FEED)
            if not more:
                break
            data += more
        if not data:
            return None
        if data[:2] != _GZIP_MAGIC:
            raise gzip.BadGzipFile(f"Not a gzipped file ({data[:2]!r})")
        self._state, self._pending, self._started = zlib.decompressobj(31), data, True
        return self._state


#: An atom table parsed ahead: (offset of the rows in the frame's text, columns, rows), the result.
_Ahead = tuple[tuple[int, int, int], "Future[np.ndarray | None]"]


class _Kept:
    """What the scan of a gzip file keeps: the text of its first frames (at most ``budget``
    bytes, each let go once read), the atom tables of those frames parsed ahead on a second
    thread by the compiled parser (counted in the budget), and restart points."""

    def __init__(self, budget: int, ahead: ThreadPoolExecutor | None) -> None:
        self.budget = budget
        self.size = 0
        self.texts: dict[int, bytes] = {}  # frame start -> its whole text
        self.tables: dict[int, _Ahead] = {}
        self.restarts: list[_Restart] = [_Restart(0, 0, None, b"")]
        self._ahead = ahead
        self._pid = os.getpid()
        self._pending: deque[bytes] = deque()  # the text from _start on, while it fits
        self._waiting = 0  # its length
        self._start = 0
        self._full = False

    def add(self, piece: bytes, inflater: _Inflater) -> None:
        """Called by the scan with every piece of text in order."""
        if not self._full and self.size + self._waiting > self.budget:
            self._stop()
        if not self._full:  # pending text is at most one piece past the budget
            self._pending.append(piece)
            self._waiting += len(piece)
        if inflater.position - self.restarts[-1].position >= _RESTART_SPAN:
            point = inflater.restart()
            if point is not None:
                self.restarts.append(point)

    def cut(self, end: int) -> None:
        """The frame from the last cut (or the start) ends at ``end``."""
        length = end - self._start
        if not self._full and self.size + length > self.budget:
            self._stop()
        if self._full:
            return
        self.size += length
        self._waiting -= length
        parts, size = [], 0
        while size < length:
            piece = self._pending.popleft()
            if size + len(piece) > length:
                rest = length - size
                self._pending.appendleft(piece[rest:])
                piece = piece[:rest]
            parts.append(piece)
            size += len(piece)
        text = parts[0] if len(parts) == 1 else b"".join(parts)
        self.texts[self._start] = text
        self._parse_ahead(text)
        self._start = end

    def _stop(self) -> None:
        """Keep nothing more: the budget is spent."""
        self._full = True
        self._pending.clear()

    def _parse_ahead(self, text: bytes) -> None:
        """Queue the compiled parser on the atom rows of the frame ``text``, if it fits."""
        if self._ahead is None or _accel is None:
            return
        shape = _atoms_at(text)
        if shape is None or shape[2] == 0 or self.size + shape[1] * shape[2] * 8 > self.budget:
            return
        self.size += shape[1] * shape[2] * 8
        body = memoryview(text)[shape[0] :]
        self.tables[self._start] = (shape, self._ahead.submit(_accel.parse_table, body, *shape[1:]))

    def take(self, start: int) -> _Ahead | None:
        """Let go of the frame at ``start`` (it is being read); its table parsed ahead, if any
        (none in a process forked since: the thread that parses them is not there)."""
        self.texts.pop(start, None)
        ahead = self.tables.pop(start, None)
        return ahead if os.getpid() == self._pid else None

    def close(self) -> None:
        for _, future in self.tables.values():
            future.cancel()
        self.texts.clear()
        self.tables.clear()

    def nearest(self, position: int) -> _Restart:
        """The last restart point at or before ``position``."""
        return max((r for r in self.restarts if r.position <= position), key=lambda r: r.position)


_ATOM_COUNT = re.compile(rb"^ITEM: NUMBER OF ATOMS[ \t\r]*\n[ \t]*(\d+)[ \t\r]*$", re.MULTILINE)
#: The most atoms a frame may declare: LAMMPS counts them in 64-bit integers.
MAX_ATOMS = 2**63 - 1


def _atoms_at(text: bytes) -> tuple[int, int, int] | None:
    """Where a frame's atom rows start, how many columns and rows its header names, or None:
    enough to parse the rows ahead (the header is checked when the frame is read)."""
    head = text[:65536]
    count = _ATOM_COUNT.search(head)
    atoms = head.find(b"\nITEM: ATOMS", count.end()) if count else -1
    end = head.find(b"\n", atoms + 1) if atoms >= 0 else -1
    if count is None or end < 0 or int(count.group(1)) > MAX_ATOMS:
        return None
    return end + 1, len(head[atoms + 12 : end].split()), int(count.group(1))


def can_open(path: Path) -> bool:
    """True when the file's first bytes are a dump ``ITEM:`` line."""
    try:
        with gzip.open(path, "rb") if _is_gzip(path) else open(path, "rb") as handle:
            return handle.read(64).lstrip().startswith(b"ITEM:")
    except Exception:  # noqa: BLE001 - a hint must never raise
        return False


def _cpus() -> int:
    """CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _newlines(buf: bytes, start: int, stop: int) -> int:
    """``buf.count(b"\\n", start, stop)``, counted by numpy (several times faster)."""
    return int(np.count_nonzero(np.frombuffer(buf, np.uint8, max(stop - start, 0), start) == 10))


def _scan(
    path: Path, file_index: int, budget: int, ahead: ThreadPoolExecutor | None
) -> tuple[list[_Block], _Kept | None]:
    """Blocks of one file: every frame starts with the same line as the file's first line. Of a
    gzip file, also what it keeps (at most ``budget`` bytes, tables parsed ``ahead``)."""
    kept = _Kept(budget, ahead) if _is_gzip(path) else None
    problem: str | None = None
    try:
        with _Inflater(path) if kept is not None else open(path, "rb") as handle:

            def read() -> bytes:
                """The next piece of text; b"" at the end or once the stream broke off."""
                nonlocal problem
                if problem is not None:
                    return b""
                try:
                    if not isinstance(handle, _Inflater):
                        return handle.read(_CHUNK)
                    piece = handle.read()
                except _STREAM_ERRORS as exc:
                    problem = f"the compressed stream is damaged ({exc})"
                    return b""
                if kept is not None and piece:
                    kept.add(piece, handle)
                return piece

            head = read()
            while 0 < len(head) < _CHUNK and b"\n" not in head:
                more = read()
                if not more:
                    break
                head += more
            first_line = head.split(b"\n", 1)[0].rstrip()
            if not first_line.startswith(b"ITEM:") or (problem and b"\n" not in head):
                reason = problem or (
                    f"not a LAMMPS dump: the first line is {first_line[:60].decode('latin-1')!r}, "
                    "not an ITEM: line"
                )
                return [_Block(file_index, 0, len(head), 1, reason)], None
            # A frame starts at ITEM: TIME when present (LAMMPS writes it before the
            # timestep), else at ITEM: TIMESTEP; ITEM: UNITS appears in the first frame only.
            found = _FRAME_START.search(head)
            marker = b"\n" + (found.group(1) if found else first_line)
            skip = 0 if head.startswith(marker[1:]) else 1
            starts, lines = [0], [1]
            buf, base, counted, line = head, 0, 0, 1  # buf = text[base:base+len(buf)]
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
                        if kept is not None:
                            kept.cut(base + pos + 1)
                    pos = buf.find(marker, pos + 1)
                chunk = read()
                if not chunk:
                    end = base + len(buf)
                    break
                cut = max(len(buf) - len(marker), 0)
                line += _newlines(buf, counted, cut)
                base, buf, counted = base + cut, buf[cut:] + chunk, 0
    except _STREAM_ERRORS as exc:
        raise ReadError(f"{path}: cannot read the file: {exc}") from exc
    ends = [*starts[1:], end]
    blocks = [_Block(file_index, s, e, ln) for s, e, ln in zip(starts, ends, lines)]
    if problem is not None:
        blocks[-1] = _Block(file_index, blocks[-1].start, blocks[-1].end, blocks[-1].line, problem)
    if kept is not None and problem is None:
        kept.cut(end)
    return blocks, kept


#: Makes the ReadError of a frame's line: ``fail(line, message)``.
_Fail = Callable[[int, str], ReadError]


@dataclass
class _Header:
    """A frame's ``ITEM:`` lines up to its atom (or entry) columns, and where its rows start."""

    timestep: int | None = None
    time: float | None = None
    natoms: int | None = None
    box: np.ndarray | None = None
    tilt: np.ndarray | None = None
    boundary: tuple[str, ...] | None = None
    units: str | None = None
    columns: list[str] | None = None
    local: bool = False  # ITEM: ENTRIES (dump local) rather than ITEM: ATOMS
    natoms_line: int = 0
    body: int = 0  # byte offset of the atom block within the frame
    body_line: int = 0  # its line number

    @classmethod
    def parse(cls, data: bytes, line_no: int, extra_columns: frozenset[str], fail: _Fail) -> _Header:
        """The header of the frame ``data`` whose first line is ``line_no``; ``extra_columns``
        are accepted besides the known and custom ones (:func:`_check_columns`)."""
        header = cls()
        pos = 0

        def next_line() -> str:
            nonlocal pos, line_no
            end = data.find(b"\n", pos)
            if end < 0:
                if pos >= len(data):
                    raise fail(line_no, "the frame is truncated inside its header")
                end = len(data)
            text = data[pos:end].decode("latin-1").strip()
            pos, line_no = end + 1, line_no + 1
            return text

        def number(kind: type, text: str, what: str) -> Any:
            try:
                return kind(text)
            except ValueError:
                raise fail(line_no - 1, f"{what} {text!r} is not a number") from None

        while True:
            item = next_line()
            if not item.startswith("ITEM:"):
                raise fail(line_no - 1, f"expected an ITEM: line, found {item[:60]!r}")
            words = item[5:].split()
            name = " ".join(words)
            if name == "TIMESTEP":
                header.timestep = number(int, next_line(), "timestep")
            elif name == "TIME":
                header.time = number(float, next_line(), "time")
            elif name == "UNITS":
                header.units = next_line()
            elif name in ("NUMBER OF ATOMS", "NUMBER OF ENTRIES"):
                header.natoms = number(int, next_line(), "atom count" if name[10] == "A" else "entry count")
                header.natoms_line = line_no - 1
                if not 0 <= header.natoms <= MAX_ATOMS:
                    raise fail(line_no - 1, f"atom count {header.natoms} is outside 0 to {MAX_ATOMS}")
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
                        raise fail(line_no - 1, f"bad box bounds line {text!r}")
                    rows.append(values)
                table = np.array(rows, dtype=np.float64)
                header.box = np.ascontiguousarray(table[:, :2])
                header.tilt = table[:, 2].copy() if triclinic else None
            elif name.startswith(("ATOMS", "ENTRIES")):
                header.columns = words[1:]
                header.local = words[0] == "ENTRIES"
                _check_columns(header.columns, header.local, extra_columns, partial(fail, line_no - 1))
                break
            else:
                raise fail(line_no - 1, f"unknown header item {item!r}")
        if header.natoms is None:
            noun = "ENTRIES" if header.local else "ATOMS"
            raise fail(line_no - 1, f"the frame has no ITEM: NUMBER OF {noun}")
        header.body, header.body_line = pos, line_no
        return header


def _check_columns(
    columns: list[str], local: bool, extra_columns: frozenset[str], fail: Callable[[str], ReadError]
) -> None:
    """Refuse an unknown, repeated or missing column name of ``ITEM: ATOMS`` (or ``ENTRIES``)."""
    known = LOCAL_COLUMNS if local else KNOWN_COLUMNS
    for name in columns:
        if name in known or name in extra_columns or CUSTOM_COLUMN.match(name):
            continue
        raise fail(
            f"unknown column {name!r}.{did_you_mean(name, known)} "
            "Pass extra_columns=[...] to read it as floats."
        )
    if len(set(columns)) != len(columns):
        raise fail(f"repeated column names in {columns}")
    if not columns:
        raise fail(f"ITEM: {'ENTRIES' if local else 'ATOMS'} names no columns")


class DumpTrajectory(Trajectory):
    """Frames of one or more dump files (plain or ``.gz``), in the order given.

    ``extra_columns`` names further per-atom columns to accept (read as floats); any other
    column that is neither a LAMMPS/LIGGGHTS keyword nor ``c_``/``f_``/``v_``/``d_``/``i_``
    custom column is a :class:`ReadError`.

    ``dump local`` frames whose columns are the contact schema's become contacts frames
    (``attrs["kind"] == "contacts"``); ``compute`` (LIGGGHTS' compute style and keywords, e.g.
    ``"pair/gran/local pos id force contactPoint"``) maps the ``c_ID[k]`` columns of a dump
    LIGGGHTS wrote to them; any other local frame has ``attrs["kind"] == "local"``.
    ``contacts=True`` makes every frame that is not a contacts frame a :class:`ReadError`.
    """

    def __init__(
        self,
        paths: Sequence[PathLike],
        extra_columns: Iterable[str] = (),
        compute: str | None = None,
        contacts: bool = False,
    ) -> None:
        self.paths = [Path(p) for p in paths]
        self.extra_columns = frozenset(extra_columns)
        self.compute = compute
        self.contacts_only = contacts
        self._blocks: list[_Block] = []
        self._kept: dict[int, _Kept] = {}
        budget = GZIP_KEEP_BYTES
        ahead = None
        if _accel is not None and _cpus() > 1 and any(_is_gzip(path) for path in self.paths):
            ahead = ThreadPoolExecutor(1, thread_name_prefix="pygran-dump")
        try:
            for index, path in enumerate(self.paths):
                blocks, kept = _scan(path, index, budget, ahead)
                self._blocks.extend(blocks)
                if kept is not None:
                    self._kept[index] = kept
                    budget -= kept.size
        finally:
            if ahead is not None:
                ahead.shutdown(wait=False)  # its thread ends once the tables queued are parsed
        self._gz: tuple[int, _Inflater] | None = None
        self._steps: dict[int, int] = {}  # the step of each frame read, for the order check
        self._walls = self._wall_contacts()

    def _wall_contacts(self) -> DumpTrajectory | None:
        """The wall contacts written beside these contacts files (``contacts.dump`` ->
        ``wall-contacts.dump``), one frame for each of theirs; None without such files."""
        if self.compute is not None:
            return None
        walls = [_contacts.wall_file(path) for path in self.paths]
        present = [path.is_file() for path in walls]
        if not any(present):
            return None
        if not all(present):
            at = present.index(False)
            raise ReadError(f"{walls[at]} is missing: the wall contacts of the frames of {self.paths[at]}")
        found = DumpTrajectory(walls, self.extra_columns, contacts=True)
        if found.n_frames != self.n_frames:
            found.close()
            raise ReadError(
                f"{walls[0]} holds {found.n_frames} frames of wall contacts, but {self.paths[0]} "
                f"holds {self.n_frames} frames of pair contacts"
            )
        return found

    @property
    def n_frames(self) -> int:
        return len(self._blocks)

    def close(self) -> None:
        self._close_stream()
        for kept in self._kept.values():
            kept.close()
        if self._walls is not None:
            self._walls.close()

    def _close_stream(self) -> None:
        if self._gz is not None:
            self._gz[1].close()
            self._gz = None

    def _read_bytes(self, index: int, block: _Block) -> bytes:
        """The bytes of ``block`` (frame ``index``, or its start)."""
        path = self.paths[block.file]
        try:
            if block.file in self._kept:
                return self._inflate(block)
            with open(path, "rb") as handle:
                handle.seek(block.start)
                return handle.read(block.end - block.start)
        except _STREAM_ERRORS as exc:
            self._close_stream()
            raise self._error(index, block.line, f"cannot read the frame: {exc}") from exc

    def _inflate(self, block: _Block) -> bytes:
        """The text of ``block`` in a gzip file: kept by the scan, else decompressed from the open
        stream when it is not past the block, else from the nearest restart point."""
        kept = self._kept[block.file]
        text = kept.texts.get(block.start)
        if text is not None:
            return text[: block.end - block.start]
        point = kept.nearest(block.start)
        if (
            self._gz is None
            or self._gz[0] != block.file
            or not point.position <= self._gz[1].position <= block.start
        ):
            self._close_stream()
            self._gz = (block.file, _Inflater(self.paths[block.file], point))
        inflater = self._gz[1]
        parts: list[memoryview] = []
        position = block.start
        while position < block.end:
            at = inflater.position
            piece = inflater.read()
            if not piece:
                break
            lo, hi = max(position - at, 0), min(block.end - at, len(piece))
            if lo < hi:
                parts.append(memoryview(piece)[lo:hi])
                position = at + hi
            if hi < len(piece):
                inflater.unread(piece[hi:])
        return b"".join(parts)

    def _error(self, index: int, line: int, message: str) -> ReadError:
        block = self._blocks[index]
        return ReadError(f"{self.paths[block.file]}: frame {index}, line {line}: {message}")

    def _read_frame(self, index: int) -> Frame:
        block = self._blocks[index]
        if block.problem is not None:
            raise self._error(index, block.line, block.problem)
        data = self._read_bytes(index, block)
        kept = self._kept.get(block.file)
        ahead = None if kept is None else kept.take(block.start)
        header = self._header(index, data)
        table = self._parse_atoms(index, data, header, ahead)
        frame = self._build_frame(index, header, table)
        self._check_sanity(index, block, frame)
        if self._walls is not None and frame.attrs.get("kind") == _contacts.KIND:
            walls = self._walls[index]
            if walls.timestep != frame.timestep:
                raise self._error(
                    index,
                    block.line,
                    f"its wall contacts ({self._walls.paths[0].name}) are of step {walls.timestep}",
                )
            frame.arrays = {
                name: np.concatenate([frame.arrays[name], walls.arrays[name]]) for name in frame.arrays
            }
        return frame

    def _check_sanity(self, index: int, block: _Block, frame: Frame) -> None:
        """Refuse a particle frame that is physically impossible (:mod:`~.sanity`), and a step
        that does not follow its neighbours' (those read so far: reading in order checks all)."""
        problem = None if frame.attrs.get("kind") else particle_problem(frame.arrays)
        if problem is None and frame.timestep is not None:
            self._steps[index] = frame.timestep
            before, after = self._steps.get(index - 1), self._steps.get(index + 1)
            problem = step_problem(before, frame.timestep)
            if problem is None and after is not None:
                problem = step_problem(frame.timestep, after)
        if problem:
            raise self._error(index, block.line, problem)

    def read_header(self, index: int) -> dict[str, Any]:
        """Timestep, atom count, box and columns of frame ``index`` without parsing its atoms."""
        index %= self.n_frames
        block = self._blocks[index]
        if block.problem is not None:
            raise self._error(index, block.line, block.problem)
        head = self._read_bytes(
            index, _Block(block.file, block.start, min(block.end, block.start + 65536), block.line)
        )
        header = self._header(index, head)
        return {
            "timestep": header.timestep,
            "natoms": header.natoms,
            "box": header.box,
            "boundary": header.boundary,
            "columns": header.columns,
        }

    def _header(self, index: int, data: bytes) -> _Header:
        """The header of frame ``index``, whose text (or its start) is ``data``."""
        return _Header.parse(data, self._blocks[index].line, self.extra_columns, partial(self._error, index))

    def _parse_atoms(self, index: int, data: bytes, header: _Header, ahead: _Ahead | None) -> np.ndarray:
        assert header.columns is not None and header.natoms is not None
        body = memoryview(data)[header.body :]
        ncols, natoms = len(header.columns), header.natoms
        if natoms == 0:
            if _NOT_BLANK.search(body):
                raise self._error(index, header.body_line, "the header says 0 atoms but rows follow")
            return np.empty((0, ncols))
        if ahead is not None and ahead[0] == (header.body, ncols, natoms):
            table = ahead[1].result()  # the same call, made while the file was scanned
        else:
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
        integers = LOCAL_INT_COLUMNS if header.local else INT_COLUMNS
        for j, name in enumerate(header.columns):
            column = table[:, j]
            if name in integers:
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
        if header.local:
            arrays, attrs["kind"] = self._local(index, header, arrays)
        elif self.contacts_only:
            raise self._error(
                index, header.body_line, "ITEM: ATOMS: particles, not contacts (a dump local file)"
            )
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

    def _local(
        self, index: int, header: _Header, arrays: dict[str, np.ndarray]
    ) -> tuple[dict[str, np.ndarray], str]:
        """The arrays and kind of a ``dump local`` frame: contacts when its columns are the
        schema's or ``compute`` maps them, else ``"local"`` (a :class:`ReadError` with
        ``contacts=True``)."""
        assert header.columns is not None
        if self.compute is not None:
            try:
                found = _contacts.from_liggghts(
                    header.columns, arrays, self.compute, header.box, header.boundary
                )
            except ValueError as exc:
                raise self._error(index, header.body_line - 1, str(exc)) from None
            return found, _contacts.KIND
        if _contacts.is_contacts(header.columns):
            return {name: arrays[name] for name in _contacts.COLUMNS}, _contacts.KIND
        if self.contacts_only:
            raise self._error(
                index,
                header.body_line - 1,
                f"ITEM: ENTRIES {' '.join(header.columns)} are not contact records "
                f"({' '.join(_contacts.COLUMNS)}); for a dump of LIGGGHTS' compute pair/gran/local pass "
                "compute='pair/gran/local <its keywords>'",
            )
        return arrays, "local"


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
    """Writes particle frames as a LIGGGHTS/LAMMPS text dump, exactly as LIGGGHTS' ``dump
    custom`` lays it out, so that every dump reader (OVITO, MDAnalysis, LIGGGHTS' tools) opens it.

    A ``*`` in the file name writes one file per frame with the timestep in its place (as
    LIGGGHTS does); otherwise frames are appended to one file. Floats are written with the
    shortest text that reads back to the same float64, integers exactly. ``time=True`` writes
    each frame's time in an ``ITEM: TIME`` block before ``ITEM: TIMESTEP``, as LAMMPS'
    ``dump_modify time yes`` does (OVITO reads it; MDAnalysis' dump reader does not).
    Contacts frames are written as ``dump local`` entries: the pair contacts in this file,
    the wall contacts in :func:`~pygran_core.formats.contacts.wall_file` beside it.
    """

    def __init__(self, path: PathLike, time: bool = False, **options: Any) -> None:
        if options:
            raise UnsupportedFeature(f"The dump writer takes one option, time=True|False: {sorted(options)}")
        if not isinstance(time, bool):
            raise UnsupportedFeature(f"The dump writer's option time is True or False, got {time!r}")
        self.path = Path(path)
        self.time = time
        self.count = 0
        self._handle: IO[bytes] | None = None
        self._walls: DumpWriter | None = None

    def write_frame(self, frame: Frame) -> None:
        if frame.attrs.get("kind") == _contacts.KIND:
            pairs, walls = _contacts.split(frame.arrays)
            if self._walls is None:
                self._walls = DumpWriter(_contacts.wall_file(self.path), time=self.time)
            self._walls._write(dataclasses.replace(frame, arrays=walls))
            frame = dataclasses.replace(frame, arrays=pairs)
        self._write(frame)

    def _write(self, frame: Frame) -> None:
        text = format_frame(frame, self.count, time=self.time).encode("ascii")
        step = frame.timestep if frame.timestep is not None else self.count
        target = self.path.with_name(self.path.name.replace("*", str(step)))
        try:
            if "*" in self.path.name:
                with open(target, "wb") as handle:
                    handle.write(text)
            else:
                if self._handle is None:
                    self._handle = open(self.path, "wb")
                self._handle.write(text)
                self._handle.flush()
        except OSError as exc:
            raise WriteError(
                f"{target}: frame {self.count} could not be written: {exc.strerror or exc}"
            ) from None
        self.count += 1

    def close(self) -> None:
        if self._handle is not None:
            self._handle.close()
            self._handle = None
        if self._walls is not None:
            self._walls.close()


def format_frame(frame: Frame, index: int = 0, time: bool = False) -> str:
    """One frame as dump text: ``ITEM: ENTRIES`` (``dump local``) for contacts or local frames;
    ``time``: an ``ITEM: TIME`` block first (LAMMPS' ``dump_modify time yes``) when the frame
    has a time."""
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
    if time and frame.time is not None:
        lines.insert(0, f"ITEM: TIME\n{float(frame.time)!r}\n")
    noun = "ENTRIES" if frame.attrs.get("kind") in (_contacts.KIND, "local") else "ATOMS"
    lines.append(f"ITEM: NUMBER OF {noun}\n{n}\n")
    if tilt is None:
        lines.append(f"ITEM: BOX BOUNDS {boundary}\n")
        lines += [f"{float(lo)!r} {float(hi)!r}\n" for lo, hi in np.asarray(box)]
    else:
        lines.append(f"ITEM: BOX BOUNDS xy xz yz {boundary}\n")
        lines += [f"{float(lo)!r} {float(hi)!r} {float(t)!r}\n" for (lo, hi), t in zip(box, tilt)]
    lines.append(f"ITEM: {noun} " + " ".join(columns) + "\n")
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
