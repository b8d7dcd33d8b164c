"""Series of VTK files with a ParaView ``.pvd`` index: the writers' common part and the reader.

A writer of a series writes one file per frame (``walls*.vtk`` -> ``walls100.vtk``, ...) and,
after every frame, the index ``walls.pvd``: one ``<DataSet timestep="TIME" file="..."/>`` per
frame, in order, which ParaView, pyvista and OVITO open as one time series with the simulated
time on its axis. A frame whose content (every array, box and attribute but the time) equals
the last file's is not written again: its entry names that file, so a static wall is one file
indexed at every frame, and a wall's file is rewritten only when it moves or changes.

Each entry also carries ``cycle``, the frame's step number; ParaView, pyvista and OVITO ignore
attributes they do not know. :class:`pygran_readers.vtk.PVDTrajectory` reads an index back as a
trajectory: the time and step of each frame from the index, its data from the file it names;
steps that do not increase, and particle frames with repeated ids or a radius, mass or density
that is not positive, are a ``ReadError`` naming the index.
"""

from __future__ import annotations

import abc
import hashlib
import math
import os
from pathlib import Path
from typing import Any
from xml.parsers import expat
from xml.sax.saxutils import quoteattr

import numpy as np

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.io import Frame, PathLike, TrajectoryWriter, open_trajectory

#: What opens an index.
PVD_HEAD = (
    '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
    "<Collection>\n"
)
PVD_TAIL = "</Collection>\n</VTKFile>\n"


def index_path(pattern: Path) -> Path:
    """The index of the series ``pattern``: ``walls*.vtk`` -> ``walls.pvd``, ``mesh_*.vtp`` ->
    ``mesh.pvd``, ``traj.vtk`` -> ``traj.pvd``."""
    stem = pattern.name[: -len(pattern.suffix)] if pattern.suffix else pattern.name
    stem = stem.replace("*", "").rstrip("_.-") or "series"
    return pattern.with_name(stem + ".pvd")


def write_atomically(target: Path, data: bytes) -> None:
    """Write ``data`` to ``target`` through a temporary name, so a crash never leaves half a file."""
    partial = target.with_name(target.name + ".part")
    partial.write_bytes(data)
    os.replace(partial, target)


def content_digest(frame: Frame) -> bytes:
    """A SHA-256 digest of what a frame holds, its time and step aside: equal digests, equal
    files (kept instead of a copy of the frame, which may be large)."""
    digest = hashlib.sha256()
    for name, values in frame.arrays.items():
        array = np.ascontiguousarray(values)
        digest.update(f"{name}:{array.dtype.str}:{array.shape};".encode())
        digest.update(array.data)
    box = None if frame.box is None else np.asarray(frame.box).tolist()
    attrs = sorted(
        (k, repr(np.asarray(v).tolist() if isinstance(v, np.ndarray) else v)) for k, v in frame.attrs.items()
    )
    digest.update(repr((box, frame.boundary, attrs)).encode())
    return digest.digest()


class SeriesWriter(TrajectoryWriter):
    """One file per frame, a ``.pvd`` index after each frame, unchanged frames not written again.

    ``path`` names the files: a ``*`` is replaced by the frame's step, else the step goes
    before the extension. ``index`` is the index file (default :func:`index_path`). A frame
    without a time is indexed at its step. Subclasses give :meth:`encode`.
    """

    def __init__(self, path: PathLike, index: PathLike | None = None) -> None:
        self.path = Path(path)
        self.index = Path(index) if index is not None else index_path(self.path)
        self.count = 0
        self._indexed = False  # whether the index holds this writer's (or the resumed) entries
        self._last: bytes | None = None  # the content digest of the last file indexed
        self._last_file = ""
        self._last_step: int | None = None  # the step of the last frame indexed

    @abc.abstractmethod
    def encode(self, frame: Frame) -> bytes:
        """One frame as the bytes of its file."""

    def file_for(self, step: int) -> Path:
        """The file of the frame at ``step``."""
        name = self.path.name
        if "*" in name:
            return self.path.with_name(name.replace("*", str(step)))
        return self.path.with_name(f"{self.path.stem}{step}{self.path.suffix}")

    def resume(self, step: int) -> None:
        """Keep the entries of the index an earlier run wrote for the frames up to ``step``; a
        solver's file after them holding the last kept frame unchanged is then indexed as that
        frame's file (:meth:`index_file`), as if the run had never stopped."""
        if not self.index.is_file():
            return
        kept = []
        for entry in read_index(self.index):
            try:
                cycle, time = int(entry.get("cycle", "")), float(entry.get("timestep", ""))
            except ValueError:
                break  # not PyGran's entry, or one it cannot place: the frames from here are written anew
            if cycle > step:
                break
            kept.append(_entry(time, cycle, entry.get("file", "")))
            self._last_step, self._last_file = cycle, entry.get("file", "")
        self.count = len(kept)
        write_atomically(self.index, (PVD_HEAD + "".join(kept) + PVD_TAIL).encode("utf-8"))
        self._indexed = True
        if not kept:
            return
        try:
            with open_trajectory(self.index.parent / self._last_file) as frames:
                self._last = content_digest(frames[0])
        except (OSError, ReadError, IndexError):
            self._last = None  # its file unreadable: the next frame is written in full

    def write_frame(self, frame: Frame) -> None:
        step = int(frame.timestep) if frame.timestep is not None else self.count
        time = float(frame.time) if frame.time is not None else float(step)
        if not math.isfinite(time):
            raise UnsupportedFeature(f"A .pvd index needs a finite time; frame {self.count} has {time}")
        content = content_digest(frame)
        if content != self._last:
            target = self.file_for(step)
            write_atomically(target, self.encode(frame))
            self._last = content
            self._last_file = Path(os.path.relpath(target, self.index.parent)).as_posix()
        self._append(_entry(time, step, self._last_file), step)

    def index_file(self, file: Path, step: int, time: float) -> None:
        """Index ``file``, the frame at ``step`` (``time``) that a solver wrote itself. A file
        holding what the last one indexed holds (time and step aside) is removed and that one
        indexed in its place, as :meth:`write_frame` writes an unchanged frame once. A frame
        the index holds already (a solver writes the frame it resumes at again) is not indexed
        twice: its file is removed unless it is the one the index names."""
        name = Path(os.path.relpath(file, self.index.parent)).as_posix()
        if self._last_step is not None and step <= self._last_step:
            if name != self._last_file:
                file.unlink()
            return
        with open_trajectory(file) as frames:
            content = content_digest(frames[0])
        if content == self._last:
            file.unlink()
        else:
            self._last, self._last_file = content, name
        self._append(_entry(time, step, self._last_file), step)

    def _append(self, entry: str, step: int) -> None:
        """Add ``entry``, the frame at ``step``, to the index."""
        self._last_step = step
        if self._indexed:  # the new entry replaces the closing tags, which follow it again
            with open(self.index, "r+b") as handle:
                handle.seek(-len(PVD_TAIL), os.SEEK_END)
                handle.write((entry + PVD_TAIL).encode("utf-8"))
        else:
            write_atomically(self.index, (PVD_HEAD + entry + PVD_TAIL).encode("utf-8"))
            self._indexed = True
        self.count += 1


def _entry(time: float, step: int, file: str) -> str:
    """An index entry: ``timestep`` is the time (as ParaView names it), ``cycle`` the step."""
    return f'<DataSet timestep="{time!r}" cycle="{step}" part="0" file={quoteattr(file)}/>\n'


def can_open(path: Path) -> bool:
    """True for a VTK XML collection (a ``.pvd`` index)."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(256)
    except OSError:
        return False
    return b"<VTKFile" in head and b'type="Collection"' in head


def read_index(path: Path) -> list[dict[str, str]]:
    """The ``DataSet`` entries of a ``.pvd`` file, in order, as attribute dictionaries."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ReadError(f"{path}: cannot read the file: {exc}") from exc
    entries: list[dict[str, str]] = []
    tags: list[str] = []
    parser = expat.ParserCreate()

    def start(tag: str, attrs: dict[str, str]) -> None:
        tags.append(tag)
        if tag == "DataSet":
            entries.append(dict(attrs, line=str(parser.CurrentLineNumber)))

    def refuse(*args: Any) -> None:
        raise ReadError(f"{path}: a .pvd index has no document type declaration")

    parser.StartElementHandler = start
    parser.StartDoctypeDeclHandler = refuse
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise ReadError(f"{path}: not a valid .pvd index (XML error: {exc})") from None
    if tags[:2] != ["VTKFile", "Collection"]:
        raise ReadError(f"{path}: not a .pvd index (no <VTKFile type='Collection'><Collection>)")
    return entries
