"""Pairs of points within a distance, found in a cell list: the pair search behind
``Particles.computeRDF`` and ``equilibrium.Neighbors``.

Points are sorted by cell (cells at least ``reach / m`` wide, x fastest), so the cells
``cx - k .. cx + k`` of one row are one contiguous run of sorted points. The sweep visits half
of the neighbour rows of each point (those the sphere of radius ``reach`` can reach, each
with the x run it needs), so each pair, or each periodic image of a pair, is met once;
periodic axes wrap with explicit image shifts. The numpy path runs the sweep vectorised over
all points at once (no Python loop per point or per cell); when the core's compiled kernels
are built (``pygran_core._compiled``) they run the same sweep in C on OpenMP threads. Both compute
a separation exactly as a brute-force minimum-image loop does, ``(x_j - x_i) + shift`` then
``dx² + dy² + dz²``, so they give the same pairs and the same histogram counts.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from pygran_core._compiled import kernels as _accel

#: Cells are this much wider than ``reach / m``, so round-off in a point's cell never hides a pair.
_MARGIN = 1e-9
#: Candidate pairs the numpy path handles per step (bounds its memory to a few tens of MB).
_BLOCK = 1 << 17


@dataclass(frozen=True)
class CellList:
    """Points sorted by cell; ``start[c]:start[c + 1]`` are the sorted points of cell ``c``."""

    order: np.ndarray  #: sorted index -> original index
    x: np.ndarray  #: (3, N) sorted coordinates
    cell: np.ndarray  #: (3, N) cell of each sorted point along each axis
    start: np.ndarray  #: (cells + 1,) first sorted index of each cell, x fastest
    shape: np.ndarray  #: (3,) cells along each axis
    width: np.ndarray  #: (3,) cell widths
    lengths: np.ndarray  #: (3,) periodic box lengths, 0 along open axes
    reach: float

    @property
    def rows(self) -> list[tuple[int, int, int]]:
        """(dy, dz, k): the neighbour rows of the sweep (half of them) and how many cells each
        side of a point's own cell along x can hold a pair; the own row (0, 0) comes first."""
        reach = self.reach * (1 + _MARGIN)
        # minimum images lie within half a period; beyond the open faces there are no cells
        along = np.where(self.lengths > 0, np.minimum(reach, self.lengths / 2 * (1 + _MARGIN)), reach)
        k = np.floor(along / self.width).astype(int) + 1
        k = np.where(self.lengths > 0, k, np.minimum(k, self.shape - 1))
        rows = []
        for dz in range(k[2] + 1):
            for dy in range(-k[1] if dz else 0, k[1] + 1):
                gap2 = (max(abs(dy) - 1, 0) * self.width[1]) ** 2 + (max(dz - 1, 0) * self.width[2]) ** 2
                if gap2 <= reach**2:
                    rows.append((dy, dz, min(int(k[0]), int(np.sqrt(reach**2 - gap2) / self.width[0]) + 1)))
        return rows


def cell_list(points: np.ndarray, lengths: np.ndarray, reach: float) -> CellList:
    """Sort ``points`` (N, 3) into cells for pairs up to ``reach`` apart; along periodic axes
    (``lengths > 0``) the points must lie in ``[0, L)``."""
    x = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3).T)
    n = x.shape[1]
    lengths = np.asarray(lengths, dtype=float)
    periodic = lengths > 0
    lower, extent = np.zeros(3), lengths.copy()
    if n:
        lower = np.where(periodic, 0.0, x.min(axis=1))
        extent = np.where(periodic, lengths, x.max(axis=1) - lower)
    # m = 1 in a box under two reaches long keeps a row of 2m + 1 cells within one period; the
    # compiled sweep is fastest with m = 1 too (its cell table stays in the CPU's cache)
    small_box = (periodic & (lengths < 2 * reach)).any()
    m = 1 if small_box or _accel is not None else _cells_per_reach(n, extent, reach)
    shape = np.clip(np.floor(extent * m / (reach * (1 + _MARGIN))), 1, 1 << 20).astype(np.int64)
    while np.prod(shape) > 8 * n + (1 << 20):  # sparse points: coarser cells
        shape[np.argmax(shape)] //= 2
    cell = np.empty((3, n), dtype=np.int64)
    for axis in range(3):
        scale = shape[axis] / extent[axis] if extent[axis] > 0 else 0.0
        np.clip(((x[axis] - lower[axis]) * scale).astype(np.int64), 0, shape[axis] - 1, out=cell[axis])
    linear = cell[0] + shape[0] * (cell[1] + shape[1] * cell[2])
    start = np.zeros(int(np.prod(shape)) + 1, dtype=np.int64)
    np.cumsum(np.bincount(linear, minlength=len(start) - 1), out=start[1:])
    order = np.argsort(linear, kind="stable") if _accel is None else _accel.cell_order(linear, start)
    width = np.where(extent > 0, extent / shape, reach)
    return CellList(
        order, np.take(x, order, axis=1), np.take(cell, order, axis=1), start, shape, width, lengths, reach
    )


def _cells_per_reach(n: int, extent: np.ndarray, reach: float) -> int:
    """Cells per reach minimising the sweep's work: rows visited per point against candidate pairs
    (per point: m=1..5 visit 5, 13, 25, 39, 55 rows holding 13.5, 7.8, 5.8, 4.8, 4.1 reach³)."""
    per_reach_cube = n / np.prod(np.maximum(extent, reach)) * reach**3
    rows = np.array([5, 13, 25, 39, 55])
    volume = np.array([13.5, 7.8, 5.8, 4.8, 4.1])
    return 1 + int(np.argmin(rows * 8 + volume * per_reach_cube * 30))


def histogram(cells: CellList, edges: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """Ordered pairs ``(i, j)``, ``i != j`` and ``i`` a reference point (all when None), per bin
    ``edges[k] < d <= edges[k + 1]`` (compared as squares); ``edges`` uniform from 0 to ``reach``."""
    edges = np.asarray(edges, dtype=float)
    squared = edges**2
    weights = None if reference is None else np.asarray(reference, dtype=float)[cells.order]
    if _accel is not None:
        return _accel.histogram(cells, squared, weights)
    nbins = len(edges) - 1
    scale = nbins / edges[-1]
    counts = np.zeros(nbins + 1)
    for i, j, d2 in _close_pairs(cells, weights is not None):
        k = np.minimum((np.sqrt(d2) * scale).astype(np.intp), nbins - 1)
        k -= d2 <= squared[k]  # the estimate is at most one bin off either way
        k += d2 > squared[k + 1]  # k = -1 for coincident points, dropped below
        counts += np.bincount(
            k + 1, None if weights is None else weights[i] + weights[j], minlength=nbins + 1
        )
    return np.rint(counts[1:] * (2 if weights is None else 1)).astype(np.int64)


def pairs(cells: CellList) -> np.ndarray:
    """(K, 2) original indices ``i < j`` of the pairs at most ``reach`` apart (minimum image), sorted."""
    n = len(cells.order)
    if _accel is not None:
        keys = _accel.pair_keys(cells)
    else:
        parts = [np.zeros(0, dtype=np.int64)]
        for i, j, _ in _close_pairs(cells, True):
            first, second = cells.order[i], cells.order[j]
            parts.append(np.minimum(first, second) * n + np.maximum(first, second))
        keys = np.concatenate(parts)
    keys.sort()
    keys = keys[np.r_[True, keys[1:] != keys[:-1]]] if len(keys) else keys  # repeats: images in small boxes
    first, second = np.divmod(keys, max(n, 1))
    keep = first != second  # a point and its own image, in a box under one reach long
    return np.column_stack((first[keep], second[keep])).astype(np.intp)


def _close_pairs(cells: CellList, indices: bool) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Blocks of (i, j, d²), sorted indices, of every pair image with ``d <= reach`` (``i`` and
    ``j`` empty unless ``indices``)."""
    reach2 = cells.reach * cells.reach
    x, y, z = cells.x
    for point, first, stop, shift in _runs(cells):
        count = stop - first
        ends = np.cumsum(count)
        if not len(ends) or ends[-1] == 0:
            continue
        cuts = np.searchsorted(ends, np.arange(_BLOCK, ends[-1], _BLOCK))
        for lo, hi in zip([0, *cuts], [*cuts, len(ends)]):
            c = count[lo:hi]
            total = int(c.sum())
            if total == 0:
                continue
            i = np.repeat(point[lo:hi], c)
            j = np.arange(total) + np.repeat(first[lo:hi] - (np.cumsum(c) - c), c)
            dx, dy, dz = x[j] - x[i], y[j] - y[i], z[j] - z[i]
            if shift is not None:
                dx += np.repeat(shift[0, lo:hi], c)
                dy += np.repeat(shift[1, lo:hi], c)
                dz += np.repeat(shift[2, lo:hi], c)
            d2 = dx * dx
            d2 += dy * dy
            d2 += dz * dz
            hit = d2 <= reach2
            yield (i[hit], j[hit], d2[hit]) if indices else (i[:0], j[:0], d2[hit])


def _runs(cells: CellList) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]]:
    """(point, first, stop, shift): each point is compared with the sorted points first..stop-1,
    whose separations get the image shift (3, K) added (None: no shift in the batch)."""
    nx, ny, nz = (int(n) for n in cells.shape)
    start = cells.start
    cx, cy, cz = cells.cell
    everyone = np.arange(len(cx))
    row = nx * (cy + ny * cz)  # the linear index of each point's own row
    runs: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # k -> first and last cell (+1) of each run
    for dy, dz, k in cells.rows:
        if k not in runs:
            runs[k] = (row + np.maximum(cx - k, 0), row + np.minimum(cx + k, nx - 1) + 1)
        # every point's run in its neighbour row as it lies: right unless the row is beyond
        # the y or z faces (then emptied here, and wrapped round or dropped below)
        offset = nx * (dy + ny * dz)
        own_row = dy == 0 and dz == 0
        stop = np.take(start, runs[k][1] + offset, mode="clip")
        first = everyone + 1 if own_row else np.take(start, runs[k][0] + offset, mode="clip")
        beyond = (cy < -dy) if dy < 0 else (cy >= ny - dy) if dy > 0 else np.zeros(len(cx), dtype=bool)
        if dz:
            beyond[start[nx * ny * (nz - dz)] :] = True  # cz >= nz - dz: the last points
        beyond = np.flatnonzero(beyond)
        stop[beyond] = first[beyond]
        yield everyone, first, stop, None
        yield _wrapped(cells, beyond, dy, dz, k, "inside")
        if cells.lengths[0] > 0:  # the cells of the run beyond the x faces, wrapped round
            yield _wrapped(cells, np.flatnonzero(cx >= nx - k), dy, dz, k, "above")
            if not own_row:
                yield _wrapped(cells, np.flatnonzero(cx < k), dy, dz, k, "below")


def _wrapped(
    cells: CellList, point: np.ndarray, dy: int, dz: int, k: int, part: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Runs of a few points in row ``(cy + dy, cz + dz)``, wrapped round periodic y and z faces:
    the cells ``cx - k .. cx + k`` ``inside`` the x faces, or those ``above`` or ``below`` them
    wrapped round the x period."""
    nx, ny, nz = (int(n) for n in cells.shape)
    cx, cy, cz = (c[point] for c in cells.cell)
    ry, sy, valid = _wrap(cy + dy, ny, cells.lengths[1])
    rz, sz, valid_z = _wrap(cz + dz, nz, cells.lengths[2])
    sx = {"inside": 0.0, "above": cells.lengths[0], "below": -cells.lengths[0]}[part]
    if part == "inside":
        low, high = np.maximum(cx - k, 0), np.minimum(cx + k, nx - 1)
    elif part == "above":
        low, high = np.zeros_like(cx), cx + k - nx
    else:
        low, high = cx - k + nx, np.full_like(cx, nx - 1)
    base = nx * (ry + ny * rz)
    first = np.where(valid & valid_z, cells.start[base + low], 0)
    stop = np.where(valid & valid_z, cells.start[base + high + 1], 0)
    return point, first, stop, np.stack((np.full(len(point), sx), sy, sz))


def _wrap(coordinate: np.ndarray, cells: int, length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell coordinates moved into ``0 .. cells-1``: (wrapped, image shift, valid); open axes do not wrap."""
    if length > 0:
        image = np.floor_divide(coordinate, cells)
        return coordinate - image * cells, image * length, np.ones(len(coordinate), dtype=bool)
    valid = (coordinate >= 0) & (coordinate < cells)
    return np.where(valid, coordinate, 0), np.zeros(len(coordinate)), valid
