"""The interfaces every file format implements: :class:`Frame` (one snapshot),
:class:`Trajectory` (a lazy, random-access sequence of frames) and :class:`TrajectoryWriter`
(appends one frame at a time), and the expansion of file patterns.

A leaf module (it imports no other part of PyGran but the errors), so that the plugin records of
:mod:`pygran_core.hookspecs` can name these types. Users and format plugins import them from
:mod:`pygran_core.io`, which adds the lookups of formats through the registry.
"""

from __future__ import annotations

import abc
import glob
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import ReadError

PathLike = str | os.PathLike[str]


@dataclass
class Frame:
    """One snapshot: per-element arrays plus scalar metadata.

    Particles: ``arrays`` maps LIGGGHTS column names (``"id"``, ``"type"``, ``"x"``,
    ``"radius"``, ``"vx"``, ``"c_stress[1]"``, ...) to 1-D arrays of one length, ``int64``
    for ``id``/``type``/``mol`` and ``float64`` otherwise. Scaled coordinates are stored
    unscaled as ``x y z``.

    Meshes (``attrs["kind"] == "mesh"``): ``points`` is ``(P, 3)`` float64; ``cells`` is
    ``(C, k)`` int64 point indices, one row per cell, padded with -1 when cells have
    different sizes (triangles give ``(C, 3)``); ``cell_types`` is ``(C,)`` VTK cell type
    ids (5 triangle, 9 quad, 7 polygon, 1 vertex); every other key is point data (length
    P) or cell data (length C), listed in ``attrs["point_data"]`` / ``attrs["cell_data"]``
    (``(n, k)`` for k-component data; a name that is both gets ``point:``/``cell:``).

    ``box`` is ``(3, 2)`` lower/upper bounds or ``None`` (for a triclinic box, the bounds
    as a dump writes them, with ``attrs["tilt"] = (xy, xz, yz)``); ``boundary`` the
    LIGGGHTS boundary flags such as ``("pp", "pp", "ff")``; ``timestep`` the step number;
    ``time`` in the file's units.
    """

    arrays: dict[str, np.ndarray]
    timestep: int | None = None
    time: float | None = None
    box: np.ndarray | None = None
    boundary: tuple[str, ...] | None = None
    attrs: dict[str, Any] = field(default_factory=dict)


class Trajectory(abc.ABC):
    """A lazy sequence of frames: opening reads headers only; frames are read on demand.

    Subclasses implement :attr:`n_frames` and :meth:`_read_frame`; indexing, negative
    indices, bounds checks and iteration live here once.
    """

    @property
    @abc.abstractmethod
    def n_frames(self) -> int:
        """Number of frames."""

    @abc.abstractmethod
    def _read_frame(self, index: int) -> Frame:
        """Read frame ``index`` (already checked: ``0 <= index < n_frames``)."""

    def read_frame(self, index: int) -> Frame:
        """Frame ``index``; negative indices count from the end."""
        n = self.n_frames
        if not -n <= index < n:
            raise IndexError(f"Frame {index} is out of range: the trajectory has {n} frames")
        return self._read_frame(index % n)

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, index: int) -> Frame:
        return self.read_frame(index)

    def __iter__(self) -> Iterator[Frame]:
        for index in range(self.n_frames):
            yield self._read_frame(index)

    def contacts(self) -> Trajectory | None:
        """The contact records stored with these frames in the same file (an H5MD file's
        ``/contacts`` group), or None (the default: none)."""
        return None

    def close(self) -> None:
        """Release open files; the default holds none."""

    def __enter__(self) -> Trajectory:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TrajectoryWriter(abc.ABC):
    """Appends frames to a file; each frame is flushed so a crash loses at most one."""

    @abc.abstractmethod
    def write_frame(self, frame: Frame) -> None:
        """Append and flush one frame."""

    def resume(self, step: int) -> None:
        """Continue what an earlier run wrote here up to ``step`` (a simulation resumed from
        a checkpoint there): a writer of a file per frame with an index keeps the index's
        frames up to ``step``. The default keeps nothing: a single file is cut back by the
        engine, files of later frames are overwritten as they come."""

    def close(self) -> None:
        """Finish the file; the default holds nothing open."""

    def __enter__(self) -> TrajectoryWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def natural_key(text: str) -> list[Any]:
    """Sort key that orders embedded numbers numerically: ``f2`` before ``f10``."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def expand_paths(pattern: PathLike | Sequence[PathLike]) -> list[Path]:
    """Expand a path, a glob pattern or a list of them into existing files, in natural order.

    Raises :class:`ReadError` naming the pattern when nothing matches.
    """
    if isinstance(pattern, (str, os.PathLike)):
        text = os.fspath(pattern)
        if glob.has_magic(text) and not Path(text).is_file():  # a folder named 'run[1]' is no pattern
            found = sorted(glob.glob(text), key=natural_key)
            if not found:
                raise ReadError(f"No file matches {text!r} (looked in {Path(text).parent.resolve()})")
            return [Path(p) for p in found]
        path = Path(text)
        if not path.is_file():
            raise ReadError(f"File not found: {path.resolve()}")
        return [path]
    paths: list[Path] = []
    for item in pattern:
        paths.extend(expand_paths(item))
    if not paths:
        raise ReadError("An empty list of files was given")
    return paths
