"""Plain-text tables of spheres and triangles, the form DEM benchmarks publish their inputs in.

A sphere table has one row ``radius x y z`` per particle; a triangle table one row
``x1 y1 z1 x2 y2 z2 x3 y3 z3`` per triangle (both in metres, as in Dosta et al. 2024). Either
may be gzipped (``.gz``), start with a header line of column names, end lines with CRLF and
separate values by spaces or tabs. Blank lines are not rows. A line with the wrong number of
values, or a value that is not a finite number, is malformed: by default a
:class:`~pygran_core.errors.ReadError` names the file and its first malformed lines; with
``strict=False`` those lines are skipped, and a :class:`~pygran_core.errors.PyGranWarning`
names them (never skipped silently). Parsing is linear in the number of rows.
"""

from __future__ import annotations

import gzip
import math
import os
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pygran_core.errors import PyGranWarning, ReadError

SPHERE_COLUMNS = 4
TRIANGLE_COLUMNS = 9
_SHOWN = 5  # malformed lines named in a message


@dataclass(frozen=True)
class SphereTable:
    """The rows of a sphere table: ``radius`` (N,) and ``positions`` (N, 3), in file order;
    ``skipped``: the line numbers (1-based) of the malformed lines a lenient read left out."""

    radius: np.ndarray
    positions: np.ndarray
    skipped: tuple[int, ...] = ()

    def __len__(self) -> int:
        return len(self.radius)


def read_spheres(path: str | os.PathLike[str], *, strict: bool = True) -> SphereTable:
    """Read a ``radius x y z`` table (see the module docstring); radii must be positive."""
    rows, skipped = _read_rows(Path(path), SPHERE_COLUMNS, strict)
    radius = rows[:, 0].copy()
    if radius.size and not (radius > 0).all():
        line = int(np.flatnonzero(radius <= 0)[0])
        raise ReadError(f"{path}: radius {float(radius[line])!r} of data row {line + 1} is not positive")
    return SphereTable(radius, np.ascontiguousarray(rows[:, 1:]), skipped)


def read_triangles(path: str | os.PathLike[str], *, strict: bool = True) -> np.ndarray:
    """Read a table of triangles, nine vertex coordinates a row, as an ``(M, 3, 3)`` array;
    a triangle whose corners are collinear (no area) is a :class:`ReadError`."""
    rows, _ = _read_rows(Path(path), TRIANGLE_COLUMNS, strict)
    triangles = rows.reshape(-1, 3, 3)
    if len(triangles) == 0:
        raise ReadError(f"{path}: no triangles")
    areas = np.linalg.norm(
        np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
    )
    if not (areas > 0).all():
        raise ReadError(f"{path}: triangle of data row {int(np.flatnonzero(areas <= 0)[0]) + 1} has no area")
    return triangles


def _read_rows(path: Path, width: int, strict: bool) -> tuple[np.ndarray, tuple[int, ...]]:
    """The finite ``(N, width)`` rows of a table and the line numbers of its malformed lines."""
    lines = _text(path).splitlines()
    first = next((i for i, line in enumerate(lines) if line.strip()), len(lines))
    if first < len(lines) and not _numbers(lines[first].split()):
        first += 1  # a header: column names
    data = lines[first:]
    widths = np.fromiter((len(line.split()) for line in data), np.int64, len(data))
    candidates = np.flatnonzero(widths == width)
    rows = _parse([data[i] for i in candidates], width)
    if rows is None:  # a word that is not a number: find its lines, one by one
        finite = _finite_rows(data, candidates)
        rows = _parse([data[i] for i in candidates[finite]], width)
    else:
        finite = np.isfinite(rows).all(axis=1)
        rows = rows[finite]
    malformed = sorted([*np.flatnonzero((widths != width) & (widths > 0)), *candidates[~finite]])
    numbers = tuple(int(i) + first + 1 for i in malformed)
    if numbers:
        shown = ", ".join(map(str, numbers[:_SHOWN])) + (" ..." if len(numbers) > _SHOWN else "")
        what = f"{len(numbers)} malformed line(s) (not {width} finite numbers): {shown}"
        if strict:
            raise ReadError(f"{path}: {what}; pass strict=False to skip them with a warning")
        warnings.warn(f"{path}: skipped {what}", PyGranWarning, stacklevel=3)
    assert rows is not None  # the lines left hold only finite numbers
    return rows, numbers


def _parse(lines: list[str], width: int) -> np.ndarray | None:
    """The lines' values as ``(N, width)`` numbers, or None when a value is not a number."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # older numpy: a partial parse only warns
        try:
            values = np.fromstring(" ".join(lines), dtype=np.float64, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return values.reshape(-1, width) if values.size == width * len(lines) else None


def _finite_rows(lines: list[str], candidates: np.ndarray) -> np.ndarray:
    """Which candidate lines hold only finite numbers (the slow path, after a parse failed)."""
    return np.fromiter((_numbers(lines[i].split()) for i in candidates), bool, len(candidates))


def _numbers(values: list[str]) -> bool:
    """Whether every word is a finite number."""
    try:
        return all(math.isfinite(float(value)) for value in values)
    except ValueError:
        return False


def _text(path: Path) -> str:
    """The file's text, gunzipped when it is gzip (by its first bytes, not its name)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ReadError(f"File not found: {path}") from None
    except IsADirectoryError:
        raise ReadError(f"{path} is a folder, not a table file") from None
    except OSError as exc:
        raise ReadError(f"{path} cannot be read: {exc.strerror}") from None
    if data[:2] == b"\x1f\x8b":
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, zlib.error) as exc:
            raise ReadError(f"{path}: damaged gzip data ({exc})") from None
    try:
        return data.decode("ascii")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ReadError(f"{path}: not a text table (byte {exc.start}, line {line})") from None
