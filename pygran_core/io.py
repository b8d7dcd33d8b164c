"""File access for trajectories and meshes: what users and format plugins import.

Formats are registered like plugins (the core's own in :mod:`pygran_core.formats`,
``pygran-readers`` and third-party ones). This module gives the interfaces they implement,
:class:`Frame`, :class:`Trajectory` and :class:`TrajectoryWriter` (defined in
:mod:`pygran_core.formats.base`), and :func:`open_trajectory` / :func:`open_writer`, which
pick the format through the registry.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pygran_core import registry
from pygran_core.formats.base import Frame, PathLike, Trajectory, TrajectoryWriter, expand_paths, natural_key

__all__ = [
    "Frame",
    "PathLike",
    "Trajectory",
    "TrajectoryWriter",
    "expand_paths",
    "natural_key",
    "open_trajectory",
    "open_writer",
]


def open_trajectory(
    pattern: PathLike | Sequence[PathLike], format: str | None = None, **options: Any
) -> Trajectory:
    """Open one file, a glob or a list of files as a lazy :class:`Trajectory`.

    The format is ``format`` if given, else the first reader whose ``can_open`` accepts the
    first file, else the reader registered for the longest matching extension.
    """
    paths = expand_paths(pattern)
    spec = registry.reader_for(paths[0], format)
    return spec.open(paths, **options)


def open_writer(path: PathLike, format: str | None = None, **options: Any) -> TrajectoryWriter:
    """Open a :class:`TrajectoryWriter` for ``path``; the format comes from ``format`` or the name."""
    spec = registry.writer_for(Path(path), format)
    return spec.open(Path(path), **options)
