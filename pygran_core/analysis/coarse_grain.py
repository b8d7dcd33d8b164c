"""Coarse-graining: continuum fields from particles and contacts (MercuryCG-style).

Following Goldhirsch (Granular Matter 12, 2010, 239) and Weinhart, Thornton, Luding and
Bokhove (Granular Matter 14, 2012, 289), every particle ``i`` (mass ``m_i``, centre ``r_i``,
velocity ``v_i``) and every contact (force ``f`` on particle ``id1`` by ``id2``, branch
vector ``b = r1 - r2``, or ``r1 - contact point`` for a wall) is spread over a grid with a
kernel ``phi`` of a chosen width:

- density ``rho(r) = sum_i m_i phi(r - r_i)``, momentum ``p = sum_i m_i v_i phi(r - r_i)``,
  velocity ``V = p / rho`` (NaN where ``rho = 0``);
- kinetic stress ``sigma_k = sum_i m_i v'_i ⊗ v'_i phi(r - r_i)`` with ``v'_i = v_i - V(r)``,
  computed as ``sum_i m_i v_i ⊗ v_i phi - p ⊗ p / rho`` (0 where ``rho = 0``);
- contact stress ``sigma_c = sum_contacts f ⊗ b ∫_0^1 phi(r - r_1 + s b) ds``, the kernel
  integrated along the line from the centre of ``id1`` to that of ``id2`` (for a wall: to
  the contact point), each contact recorded once;
- stress ``sigma = sigma_k + sigma_c``; ``sigma[..., a, b]`` pairs force component ``a``
  with branch component ``b``.

**Sign convention**: compressive stress is positive (soil mechanics): a bed at rest under
gravity has ``sigma_zz = rho_bulk g (H - z) > 0``. MercuryCG and continuum mechanics use the
Cauchy stress, tensile positive, which is ``-sigma``.

**Kernels** (``width`` ``w`` is the standard deviation along one axis, for every kernel, so
that different kernels of one width are comparable): on Cartesian grids the kernel is the
product of 1D kernels along the grid's axes (the other axes are integrated out): Gaussian
``exp(-u²/2w²)`` cut at ``|u| < 3w``; Lucy ``(1 + 3t)(1 - t)³``, ``t = |u|/c``,
``c = sqrt(21/2) w``; Heaviside (top hat) ``|u| < sqrt(3) w``. On cylindrical grids the
kernel is a radial 2D kernel in the plane across the axis (Gaussian cut at ``3w``, Lucy
``(1 + 3t)(1 - t)³`` with ``c = sqrt(56/5) w``, a disc of radius ``2w``) times the 1D kernel
along it. On Cartesian grids the products make every deposit separable (below).

**Discrete normalisation**: fields are evaluated at the cell centres, and each particle's
(each contact's) weights are divided by their sum over the grid's lattice times the cell
volumes, extended beyond the grid (as if it continued), so that a grid covering every
particle and its kernel's support holds the particles' mass exactly (to rounding), and
``sum(sigma_c * cell volume) = sum f ⊗ b`` exactly; what lies beyond a grid that does not
cover everything is lost. Along an axis that is periodic in the frame's ``boundary`` and
whose grid range is exactly the box, the kernels wrap round.

**Line integrals** (Cartesian): the kernel along a contact line is integrated by Gauss-Legendre
quadrature, each node a point deposit (three short vectors of 1D weights and their outer
product). The line is cut where it enters or leaves a cell's support along an axis (where the
Gaussian jumps at its cut-off and the top hat steps), and into equal pieces at most one width
long; each piece gets 2 nodes, and the top hat, constant on each piece, 1 (exact). Against a
fine sum along the line, the Gaussian and Lucy weights are within 1e-3 of the line's largest
weight (measured: up to 6e-4 for lines up to two widths long on cells half a width to two
widths wide, 1.2e-3 for four widths on cells of half a width). On cylindrical grids the
segment is sampled with 4-point Gauss-Legendre on pieces at most ``w / 2`` long (relative
accuracy about 1e-6 for the Gaussian and Lucy kernels, lower for the discontinuous Heaviside).
The normalisation keeps the sums exact on every grid.

**Grids**: :class:`Grid1D` (slabs along an axis; the kernel integrated over the other two,
divided by the cross-section ``area``), :class:`Grid2D` (averaged over the third axis, of
length ``depth``), :class:`Grid3D`, and :class:`GridCylindrical` (rings ``(r, z)`` about an
axis). Cylindrical fields are averaged over the angle: the weight of a ring of radius ``R``
is the in-plane kernel integrated over the ring, ``(1/π) ∫_0^θmax k(d(θ)) dθ`` with
``d² = R² + R_i² - 2 R R_i cos θ`` and ``θmax`` where ``d`` reaches the cutoff (16-point
Gauss-Legendre; a particle on the axis gives ``k(sqrt(R² + ...))`` directly). Cell centres lie
at ``(k + 1/2) dR``, so no centre is on the axis, and a ring's volume ``2π R dR dz`` is exact;
a particle near the axis keeps all its mass (it is normalised over the rings). Vectors and
tensors on a cylindrical grid have components ``(r, θ, axis)`` in the basis at each particle
(at the middle of each contact line), so a radial flow does not average to zero.

:class:`CoarseGrain` runs this over frames of a :class:`~pygran_core.analysis.system.System`
(``system.Particles``, and ``system.Contacts`` when the trajectory has contact records),
per species if asked, averaged over frames; :func:`coarse_grain` is the same for one set of
plain arrays. Time averages: density, momentum, ``sum m v ⊗ v phi`` and the contact stress
are averaged over the frames, then ``V = <p>/<rho>`` and ``sigma_k = <sum m v ⊗ v phi> -
<p> ⊗ <p> / <rho>`` (velocity fluctuations in time count as kinetic stress, as in MercuryCG).

The heavy loops run in the core's compiled kernels when built (Cartesian grids),
else in vectorised numpy; both give the same fields to rounding.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from pygran_core._compiled import kernels as _accel
from pygran_core.errors import AttributeProblem, ConfigError, SelectionError, unknown_key

if TYPE_CHECKING:
    from pygran_core.analysis.system import System

KERNELS = ("gaussian", "lucy", "heaviside")
_AXES = {"x": 0, "y": 1, "z": 2}
_NAMES = "xyz"
#: Grid points the numpy path handles per step (bounds its memory to some tens of MB).
_BLOCK = 1 << 20
#: How a contact line is integrated (see the module): Gauss-Legendre nodes per piece, and the
#: longest piece in kernel widths (None: no limit; the top hat is constant on each piece).
_LINE_RULE = {"gaussian": (2, 1.0), "lucy": (2, 1.0), "heaviside": (1, None)}
_GL4 = np.polynomial.legendre.leggauss(4)
_GL16 = np.polynomial.legendre.leggauss(16)
#: Columns of the accumulated sums: mass, momentum (3), momentum flux (6: xx yy zz xy xz yz).
_FLUX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


# -- kernels ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Kernel:
    """A coarse-graining kernel: ``name`` (gaussian, lucy, heaviside) and ``width``, its
    standard deviation along one axis (see the module's documentation)."""

    name: str
    width: float

    def __post_init__(self) -> None:
        if self.name not in KERNELS:
            raise unknown_key("kernel", self.name, KERNELS)
        try:
            width = float(self.width)
        except (TypeError, ValueError):
            width = math.nan
        if not (math.isfinite(width) and width > 0):
            raise ConfigError(
                f"kernel width must be a positive length (the kernel's standard deviation), got "
                f"{self.width!r}; a usual choice is the particle radius"
            )

    @property
    def code(self) -> int:
        """The kernel's number in the compiled kernels."""
        return KERNELS.index(self.name)

    @property
    def cutoff(self) -> float:
        """Half-width of the 1D kernel's support (Cartesian grids)."""
        return (
            self.width * {"gaussian": 3.0, "lucy": math.sqrt(21 / 2), "heaviside": math.sqrt(3.0)}[self.name]
        )

    @property
    def cutoff_plane(self) -> float:
        """Radius of the in-plane 2D kernel's support (cylindrical grids)."""
        return self.width * {"gaussian": 3.0, "lucy": math.sqrt(56 / 5), "heaviside": 2.0}[self.name]

    def profile(self, u: np.ndarray) -> np.ndarray:
        """The 1D kernel (up to its normalisation) at offsets ``u``."""
        return self._shape(np.abs(u), self.cutoff)

    def radial(self, rho: np.ndarray) -> np.ndarray:
        """The in-plane 2D kernel (up to its normalisation) at distances ``rho``."""
        return self._shape(rho, self.cutoff_plane)

    def _shape(self, r: np.ndarray, c: float) -> np.ndarray:
        inside = r < c
        if self.name == "gaussian":
            return np.where(inside, np.exp((r * r) * (-0.5 / (self.width * self.width))), 0.0)
        if self.name == "lucy":
            t = np.minimum(r * (1 / c), 1.0)
            return np.where(inside, (1 + 3 * t) * (1 - t) ** 3, 0.0)
        return inside.astype(float)


# -- grids ------------------------------------------------------------------------------------


def _axis(name: str, what: str) -> int:
    if name not in _AXES:
        raise unknown_key(f"{what} axis", name, _AXES)
    return _AXES[name]


def _bins(bins: Any, count: int, what: str) -> tuple[int, ...]:
    values = (bins,) * count if np.ndim(bins) == 0 and count == 1 else bins
    try:
        out = tuple(int(b) for b in values)
    except (TypeError, ValueError):
        out = ()
    if len(out) != count or any(b < 1 or b != v for b, v in zip(out, values)):
        raise ConfigError(f"{what}: bins must be {count} positive whole number(s), got {bins!r}")
    return out


def _range(value: Any, count: int, what: str) -> tuple[tuple[float, float], ...] | None:
    if value is None:
        return None
    pairs = (value,) if count == 1 and np.ndim(value) == 1 else value
    array = np.asarray(pairs, dtype=float) if np.ndim(pairs) == 2 else np.zeros(0)
    if array.shape != (count, 2) or not np.isfinite(array).all() or (array[:, 1] <= array[:, 0]).any():
        raise ConfigError(f"{what}: range must be {count} (low, high) pair(s) with low < high, got {value!r}")
    return tuple((float(lo), float(hi)) for lo, hi in array)


@dataclass(frozen=True)
class _Layout:
    """A grid made concrete for a frame: the lattice of cell centres and the cell volumes."""

    cylindrical: bool
    axes: tuple[int, ...]  #: Cartesian: the grid's axes; cylindrical: (plane 1, plane 2, axis)
    lower: np.ndarray
    spacing: np.ndarray
    n: np.ndarray
    wrap: np.ndarray
    volume: np.ndarray  #: cell volumes, broadcastable to the grid's shape
    names: tuple[str, ...]
    centre: np.ndarray  #: cylindrical: the axis's position in the plane

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(int(k) for k in self.n)

    @property
    def ncells(self) -> int:
        return int(np.prod(self.n))

    @property
    def coordinates(self) -> tuple[np.ndarray, ...]:
        return tuple(lo + (np.arange(k) + 0.5) * h for lo, h, k in zip(self.lower, self.spacing, self.n))

    @property
    def edges(self) -> tuple[np.ndarray, ...]:
        return tuple(lo + np.arange(k + 1) * h for lo, h, k in zip(self.lower, self.spacing, self.n))


def _box(box: Any) -> np.ndarray | None:
    return None if box is None else np.asarray(box, dtype=float).reshape(3, 2)


def _cartesian(
    axes: tuple[int, ...],
    bins: tuple[int, ...],
    ranges: tuple[tuple[float, float], ...] | None,
    extent: float | None,
    box: np.ndarray | None,
    boundary: Sequence[str] | None,
    what: str,
) -> _Layout:
    if ranges is None:
        if box is None:
            raise ConfigError(f"{what}: the frame has no box; give range=...")
        ranges = tuple((float(box[a, 0]), float(box[a, 1])) for a in axes)
    others = [a for a in range(3) if a not in axes]
    if others and extent is None:
        if box is None:
            size = "area" if len(others) == 2 else "depth"
            raise ConfigError(f"{what}: the frame has no box to average over; give {size}=...")
        extent = float(np.prod(box[others, 1] - box[others, 0]))
    lower = np.array([lo for lo, _ in ranges])
    spacing = np.array([(hi - lo) / k for (lo, hi), k in zip(ranges, bins)])
    flags = tuple(boundary or ())
    periodic = [len(flags) > a and str(flags[a]).startswith("p") for a in axes]
    wrap = np.array(
        [
            p and box is not None and np.allclose((lo, hi), box[a], rtol=1e-12, atol=0)
            for p, a, (lo, hi) in zip(periodic, axes, ranges)
        ],
        dtype=bool,
    )
    volume = np.array(float(np.prod(spacing)) * (1.0 if extent is None else extent))
    return _Layout(
        False, axes, lower, spacing, np.array(bins), wrap, volume, tuple(_NAMES[a] for a in axes), np.zeros(2)
    )


@dataclass(frozen=True)
class Grid1D:
    """Slabs along ``axis``: ``bins`` cells over ``range`` (default: the box), averaged over
    the other two axes, whose cross-section ``area`` defaults to the box's."""

    axis: str = "z"
    bins: int = 100
    range: tuple[float, float] | None = None
    area: float | None = None

    def __post_init__(self) -> None:
        _axis(self.axis, "Grid1D")
        _bins(self.bins, 1, "Grid1D")
        _range(self.range, 1, "Grid1D")
        if self.area is not None and not self.area > 0:
            raise ConfigError(f"Grid1D: area must be > 0, got {self.area!r}")

    def layout(self, box: Any = None, boundary: Sequence[str] | None = None) -> _Layout:
        """The lattice for a frame with this ``box`` and ``boundary``."""
        return _cartesian(
            (_AXES[self.axis],),
            _bins(self.bins, 1, "Grid1D"),
            _range(self.range, 1, "Grid1D"),
            self.area,
            _box(box),
            boundary,
            "Grid1D",
        )


@dataclass(frozen=True)
class Grid2D:
    """A plane of ``bins`` cells over ``range`` along ``axes`` (default: the box), averaged
    over the third axis, whose length ``depth`` defaults to the box's."""

    axes: tuple[str, str] = ("x", "z")
    bins: tuple[int, int] = (50, 50)
    range: tuple[tuple[float, float], tuple[float, float]] | None = None
    depth: float | None = None

    def __post_init__(self) -> None:
        if len(self.axes) != 2 or len({_axis(a, "Grid2D") for a in self.axes}) != 2:
            raise ConfigError(f"Grid2D: axes must be two different axes of x, y, z, got {self.axes!r}")
        _bins(self.bins, 2, "Grid2D")
        _range(self.range, 2, "Grid2D")
        if self.depth is not None and not self.depth > 0:
            raise ConfigError(f"Grid2D: depth must be > 0, got {self.depth!r}")

    def layout(self, box: Any = None, boundary: Sequence[str] | None = None) -> _Layout:
        """The lattice for a frame with this ``box`` and ``boundary``."""
        return _cartesian(
            tuple(_AXES[a] for a in self.axes),
            _bins(self.bins, 2, "Grid2D"),
            _range(self.range, 2, "Grid2D"),
            self.depth,
            _box(box),
            boundary,
            "Grid2D",
        )


@dataclass(frozen=True)
class Grid3D:
    """``bins`` cells over ``range`` along x, y and z (default: the box)."""

    bins: tuple[int, int, int] = (50, 50, 50)
    range: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] | None = None

    def __post_init__(self) -> None:
        _bins(self.bins, 3, "Grid3D")
        _range(self.range, 3, "Grid3D")

    def layout(self, box: Any = None, boundary: Sequence[str] | None = None) -> _Layout:
        """The lattice for a frame with this ``box`` and ``boundary``."""
        return _cartesian(
            (0, 1, 2),
            _bins(self.bins, 3, "Grid3D"),
            _range(self.range, 3, "Grid3D"),
            None,
            _box(box),
            boundary,
            "Grid3D",
        )


@dataclass(frozen=True)
class GridCylindrical:
    """Rings about ``axis`` through ``centre`` (its position in the plane across it, in the
    order y, z for axis x; z, x for y; x, y for z): ``bins = (radial, axial)`` cells over
    ``range = ((r0, r1), (low, high))``, ``r0 >= 0``; fields averaged over the angle."""

    axis: str = "z"
    bins: tuple[int, int] = (50, 50)
    range: tuple[tuple[float, float], tuple[float, float]] | None = None
    centre: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        _axis(self.axis, "GridCylindrical")
        _bins(self.bins, 2, "GridCylindrical")
        ranges = _range(self.range, 2, "GridCylindrical")
        if ranges is None:
            raise ConfigError("GridCylindrical needs range=((r0, r1), (low, high)), e.g. ((0, R), (0, H))")
        if ranges[0][0] < 0:
            raise ConfigError(f"GridCylindrical: the radial range must start at r0 >= 0, got {ranges[0]}")
        if np.shape(self.centre) != (2,) or not np.isfinite(np.asarray(self.centre, dtype=float)).all():
            raise ConfigError(f"GridCylindrical: centre must be two numbers, got {self.centre!r}")

    def layout(self, box: Any = None, boundary: Sequence[str] | None = None) -> _Layout:
        """The lattice (``box`` and ``boundary`` are not used: rings do not wrap)."""
        a = _AXES[self.axis]
        ranges = _range(self.range, 2, "GridCylindrical")
        assert ranges is not None
        bins = _bins(self.bins, 2, "GridCylindrical")
        lower = np.array([lo for lo, _ in ranges])
        spacing = np.array([(hi - lo) / k for (lo, hi), k in zip(ranges, bins)])
        radii = lower[0] + (np.arange(bins[0]) + 0.5) * spacing[0]
        volume = np.repeat(2 * np.pi * radii * spacing[0] * spacing[1], bins[1]).reshape(bins)
        axes = ((a + 1) % 3, (a + 2) % 3, a)
        return _Layout(
            True,
            axes,
            lower,
            spacing,
            np.array(bins),
            np.zeros(2, dtype=bool),
            volume,
            ("r", self.axis),
            np.asarray(self.centre, dtype=float),
        )


Grid = Grid1D | Grid2D | Grid3D | GridCylindrical


# -- the numpy deposits -----------------------------------------------------------------------


def _stencil(lay: _Layout, d: int, low: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lattice indices ``low + 0..count-1`` along grid dimension ``d``: (indices wrapped or
    clipped into the grid, valid mask, cell-centre coordinates)."""
    k = low[:, None] + np.arange(count)
    centres = lay.lower[d] + (k + 0.5) * lay.spacing[d]
    n = int(lay.n[d])
    if lay.wrap[d]:
        return k % n, np.ones(k.shape, dtype=bool), centres
    valid = (k >= 0) & (k < n)
    return np.clip(k, 0, n - 1), valid, centres


def _scatter(out: np.ndarray, index: np.ndarray, weight: np.ndarray, values: np.ndarray) -> None:
    """``out[index[p], :] += weight[p] * values[row of p, :]``; index and weight (M, P)."""
    flat, w = index.ravel(), weight.ravel()
    keep = w != 0
    flat, w = flat[keep], w[keep]
    rows = np.repeat(np.arange(len(index)), index.shape[1])[keep]
    for j in range(values.shape[1]):
        out[:, j] += np.bincount(flat, w * values[rows, j], minlength=len(out))


def _points_numpy(lay: _Layout, kern: Kernel, positions: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum over particles of ``values`` times normalised weights (they add up to 1 over the
    lattice) on a Cartesian grid: (cells, q)."""
    out = np.zeros((lay.ncells, values.shape[1]))
    c = kern.cutoff
    counts = [int(np.floor(2 * c / h)) + 2 for h in lay.spacing]
    block = max(1, _BLOCK // int(np.prod(counts)))
    for start in range(0, len(positions), block):
        sl = slice(start, start + block)
        index = np.zeros((len(positions[sl]), 1), dtype=np.int64)
        weight = np.ones((len(positions[sl]), 1))
        valid = np.ones(index.shape, dtype=bool)
        for d, a in enumerate(lay.axes):
            x = positions[sl, a]
            low = np.floor((x - lay.lower[d]) / lay.spacing[d] - 0.5 - c / lay.spacing[d]).astype(np.int64)
            k, ok, centres = _stencil(lay, d, low, counts[d])
            w = kern.profile(centres - x[:, None])
            w /= w.sum(axis=1, keepdims=True)
            stride = int(np.prod(lay.n[d + 1 :]))
            index = (index[:, :, None] + k[:, None, :] * stride).reshape(len(x), -1)
            weight = (weight[:, :, None] * w[:, None, :]).reshape(len(x), -1)
            valid = (valid[:, :, None] & ok[:, None, :]).reshape(len(x), -1)
        _scatter(out, index, np.where(valid, weight, 0.0), values[sl])
    return out


def _line_rule(kern: Kernel) -> tuple[np.ndarray, np.ndarray, float]:
    """Gauss-Legendre nodes and weights on [-1, 1] for a contact line's pieces, and the longest
    piece (a length; inf: no limit)."""
    m, piece = _LINE_RULE[kern.name]
    nodes, weights = np.polynomial.legendre.leggauss(m)
    return nodes, weights, math.inf if piece is None else piece * kern.width


def _segments_numpy(
    lay: _Layout, kern: Kernel, start: np.ndarray, branch: np.ndarray, values: np.ndarray
) -> np.ndarray:
    """Sum over segments ``start -> start - branch`` of ``values`` times normalised line weights
    (they add up to 1 over the lattice) on a Cartesian grid: (cells, q). The line integral is a
    sum of point deposits at its quadrature nodes (see the module)."""
    out = np.zeros((lay.ncells, values.shape[1]))
    c = kern.cutoff
    nodes, weights, piece = _line_rule(kern)
    axes = list(lay.axes)
    b = branch[:, axes]
    low = np.floor((np.minimum(start, start - branch)[:, axes] - lay.lower - c) / lay.spacing - 0.5)
    low = low.astype(np.int64)
    span = np.floor((np.abs(b) + 2 * c) / lay.spacing).astype(np.int64) + 2
    pieces = np.maximum(np.ceil(np.sqrt((b * b).sum(axis=1)) / piece), 1).astype(np.int64)
    # quadrature nodes per segment at most (a line crosses 2 (|b| / h + 1) support edges per axis)
    crossings = (2 * (np.floor(np.abs(b) / lay.spacing) + 1)).sum(axis=1).astype(np.int64)
    cost = np.prod(span, axis=1) * len(nodes) * (pieces + crossings)
    order = np.argsort(cost, kind="stable")  # blocks of similar stencils
    first = 0
    while first < len(order):
        last = first + 1
        while last < len(order) and cost[order[last]] * (last + 1 - first) <= _BLOCK:
            last += 1
        rows = order[first:last]
        first = last
        m = len(rows)
        counts = span[rows].max(axis=0)
        index = np.zeros((m, 1), dtype=np.int64)
        valid = np.ones(index.shape, dtype=bool)
        offsets, mine = [], []
        for d, a in enumerate(axes):
            k, ok, centres = _stencil(lay, d, low[rows, d], int(counts[d]))
            stride = int(np.prod(lay.n[d + 1 :]))
            index = (index[:, :, None] + k[:, None, :] * stride).reshape(m, -1)
            valid = (valid[:, :, None] & ok[:, None, :]).reshape(m, -1)
            offsets.append(centres - start[rows, a][:, None])
            mine.append(np.arange(counts[d]) < span[rows, d][:, None])  # the row's own stencil
        # the pieces: [0, 1] cut into equal parts and where |offset + t b| = c along an axis
        steps = np.arange(int(pieces[rows].max()) + 1)
        cuts = [np.minimum(steps / pieces[rows][:, None], 1.0)]
        with np.errstate(divide="ignore", invalid="ignore"):
            for d in range(len(axes)):
                bd = b[rows, d][:, None]
                for edge in (-c, c):
                    t = (edge - offsets[d]) * (1 / bd)
                    cuts.append(np.where(mine[d] & (bd != 0) & (t > 0) & (t < 1), t, 1.0))
        ends = np.sort(np.concatenate(cuts, axis=1), axis=1)
        ends = ends[:, : int((ends < 1).sum(axis=1).max()) + 1]
        half = 0.5 * (ends[:, 1:] - ends[:, :-1])
        mid = 0.5 * (ends[:, 1:] + ends[:, :-1])
        s = (mid[:, :, None] + half[:, :, None] * nodes).reshape(m, -1)
        product = (half[:, :, None] * weights).reshape(m, -1, 1)
        for d in range(len(axes)):
            g = kern.profile(offsets[d][:, None, :] + s[:, :, None] * b[rows, d][:, None, None])
            g = np.where(mine[d][:, None, :], g, 0.0)
            if d < len(axes) - 1:
                product = (product[:, :, :, None] * g[:, :, None, :]).reshape(m, s.shape[1], -1)
            else:
                weight = np.matmul(product.transpose(0, 2, 1), g).reshape(m, -1)
        total = weight.sum(axis=1, keepdims=True)
        with np.errstate(divide="ignore", invalid="ignore"):
            _scatter(out, index, np.where(valid & (total > 0), weight / total, 0.0), values[rows])
    return out


def _ring(kern: Kernel, radii: np.ndarray, source: np.ndarray) -> np.ndarray:
    """The in-plane kernel averaged over rings of ``radii`` about the axis, for sources at
    distance ``source`` from it: ``(1/π) ∫_0^θmax k(d(θ)) dθ`` (see the module)."""
    c = kern.cutoff_plane
    product = 2 * radii * source
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = (radii * radii + source * source - c * c) / product
    cosine = np.where(product > 0, cosine, np.where(radii * radii + source * source < c * c, -np.inf, np.inf))
    theta = np.arccos(np.clip(cosine, -1.0, 1.0))
    nodes, weights = _GL16
    total = np.zeros(theta.shape)
    for node, wq in zip(nodes, weights):
        angle = 0.5 * theta * (node + 1)
        d2 = radii * radii + source * source - product * np.cos(angle)
        total += wq * kern.radial(np.sqrt(np.maximum(d2, 0.0)))
    return np.where(cosine > 1, 0.0, total * theta / (2 * np.pi))


def _rings_numpy(
    lay: _Layout, kern: Kernel, local: np.ndarray, node: np.ndarray, group: np.ndarray, values: np.ndarray
) -> np.ndarray:
    """Sum over groups (particles, or the quadrature nodes of each contact) of ``values`` times
    weights normalised per group, on a cylindrical grid: (cells, q). ``local`` (S, 2) holds
    each source's distance from the axis and its coordinate along it, ``node`` its weight."""
    out = np.zeros((lay.ncells, values.shape[1]))
    spacing = lay.spacing
    counts = [int(np.floor(2 * c / h)) + 2 for c, h in zip((kern.cutoff_plane, kern.cutoff), spacing)]
    radial_low = np.floor((local[:, 0] - lay.lower[0] - kern.cutoff_plane) / spacing[0] - 0.5).astype(
        np.int64
    )
    axial_low = np.floor((local[:, 1] - lay.lower[1] - kern.cutoff) / spacing[1] - 0.5).astype(np.int64)
    # the radial lattice goes on down to r = 0 (its part below the grid counts in the normalisation)
    first = math.floor(-lay.lower[0] / spacing[0])
    radial_low = np.maximum(radial_low, first)
    k_r = radial_low[:, None] + np.arange(counts[0])
    radii = lay.lower[0] + (k_r + 0.5) * spacing[0]
    w_r = np.where(radii > 0, _ring(kern, np.maximum(radii, 0.0), local[:, :1]), 0.0)
    k_z, _, centres = _stencil(lay, 1, axial_low, counts[1])
    w_z = kern.profile(centres - local[:, 1:])
    # normalise per group: sum over all lattice cells of weight times cell volume
    mass = node * (w_r * radii).sum(axis=1) * w_z.sum(axis=1)
    total = np.bincount(group, mass, minlength=len(values))
    scale = np.where(total[group] > 0, node / np.where(total[group] > 0, total[group], 1.0), 0.0)
    radial = w_r * radii * scale[:, None]
    valid = ((k_r >= 0) & (k_r < lay.n[0]))[:, :, None] & ((k_z >= 0) & (k_z < lay.n[1]))[:, None, :]
    index = np.clip(k_r, 0, lay.n[0] - 1)[:, :, None] * lay.n[1] + k_z[:, None, :]
    weight = np.where(valid, radial[:, :, None] * w_z[:, None, :], 0.0).reshape(len(local), -1)
    _scatter(out, index.reshape(len(local), -1), weight, values[group])
    return out


# -- dispatch ---------------------------------------------------------------------------------


def _check_resolution(lay: _Layout, kern: Kernel) -> None:
    cutoffs = (kern.cutoff_plane, kern.cutoff) if lay.cylindrical else (kern.cutoff,) * len(lay.axes)
    for name, c, h in zip(lay.names, cutoffs, lay.spacing):
        if c < h:
            raise ConfigError(
                f"kernel {kern.name!r} of width {kern.width:g} reaches {c:g}, less than one cell along "
                f"{name} "
                f"({h:g}): some particles would fall between the cell centres; use width >= "
                f"{kern.width * h / c:.3g} or fewer bins"
            )


def _cylindrical_frame(lay: _Layout, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from the axis and coordinate along it (S, 2), and the angle about it."""
    p1 = positions[:, lay.axes[0]] - lay.centre[0]
    p2 = positions[:, lay.axes[1]] - lay.centre[1]
    return np.column_stack((np.hypot(p1, p2), positions[:, lay.axes[2]])), np.arctan2(p2, p1)


def _to_cylindrical(lay: _Layout, vectors: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Vectors (S, 3) in components (r, θ, axis) of the basis at ``angle``."""
    cos, sin = np.cos(angle), np.sin(angle)
    u, v = vectors[:, lay.axes[0]], vectors[:, lay.axes[1]]
    return np.column_stack((cos * u + sin * v, -sin * u + cos * v, vectors[:, lay.axes[2]]))


def _deposit_points(lay: _Layout, kern: Kernel, positions: np.ndarray, values: np.ndarray) -> np.ndarray:
    if lay.cylindrical:
        local, _ = _cylindrical_frame(lay, positions)
        every = np.arange(len(positions))
        return _rings_numpy(lay, kern, local, np.ones(len(positions)), every, values)
    if _accel is not None:
        order = _by_cell(lay, positions)
        return _accel.cg_points(*_compiled_layout(lay, kern), *_contiguous(positions, values), order)
    return _points_numpy(lay, kern, positions, values)


def _deposit_segments(
    lay: _Layout, kern: Kernel, start: np.ndarray, branch: np.ndarray, values: np.ndarray
) -> np.ndarray:
    if lay.cylindrical:
        # composite 4-point Gauss-Legendre along each segment, pieces at most w/2 long
        pieces = np.clip(np.ceil(np.linalg.norm(branch, axis=1) / (0.5 * kern.width)), 1, 4096).astype(
            np.int64
        )
        group = np.repeat(np.arange(len(start)), pieces * 4)
        piece = np.arange(len(group)) // 4 - np.repeat(np.cumsum(pieces) - pieces, pieces * 4)
        nodes, weights = _GL4
        node = np.tile(nodes, len(group) // 4)
        s = (piece + 0.5 * (node + 1)) / pieces[group]
        points = start[group] - s[:, None] * branch[group]
        local, _ = _cylindrical_frame(lay, points)
        return _rings_numpy(
            lay, kern, local, np.tile(weights, len(group) // 4) / pieces[group], group, values
        )
    if _accel is not None:
        order = _by_cell(lay, start)
        arrays = _contiguous(start, branch, values)
        return _accel.cg_segments(*_compiled_layout(lay, kern), *arrays, order, *_line_rule(kern))
    return _segments_numpy(lay, kern, start, branch, values)


def _by_cell(lay: _Layout, positions: np.ndarray) -> np.ndarray:
    """An order of ``positions`` by grid cell (a counting sort): the compiled deposits then write
    to nearby cells one after the other, which keeps the grid in the CPU's caches."""
    linear = np.zeros(len(positions), dtype=np.int64)
    for d, a in enumerate(lay.axes):
        k = np.clip(np.floor((positions[:, a] - lay.lower[d]) / lay.spacing[d]), -1, lay.n[d]).astype(
            np.int64
        )
        linear = linear * (int(lay.n[d]) + 2) + (k + 1)
    start = np.zeros(int(np.prod(lay.n + 2)) + 1, dtype=np.int64)
    np.cumsum(np.bincount(linear, minlength=len(start) - 1), out=start[1:])
    assert _accel is not None
    return _accel.cell_order(linear, start)


def _contiguous(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(np.ascontiguousarray(a, dtype=float) for a in arrays)


def _compiled_layout(lay: _Layout, kern: Kernel) -> tuple[Any, ...]:
    return (
        np.asarray(lay.axes, dtype=np.int64),
        np.ascontiguousarray(lay.lower, dtype=float),
        np.ascontiguousarray(lay.spacing, dtype=float),
        np.asarray(lay.n, dtype=np.int64),
        np.asarray(lay.wrap, dtype=np.uint8),
        kern.code,
        kern.width,
        kern.cutoff,
    )


# -- fields of one set of arrays --------------------------------------------------------------


@dataclass
class _Sums:
    """Per-cell sums of one or more frames: mass, momentum, momentum flux, contact stress."""

    points: np.ndarray  #: (cells, 10): mass, momentum (3), momentum flux (6) per unit volume
    contacts: np.ndarray | None  #: (cells, 9) contact stress, or None without contact records
    velocities: bool
    frames: int = 1

    def __iadd__(self, other: _Sums) -> _Sums:
        self.points += other.points
        if self.contacts is None or other.contacts is None:
            self.contacts = None
        else:
            self.contacts += other.contacts
        self.velocities = self.velocities and other.velocities
        self.frames += other.frames
        return self


def _particle_sums(
    lay: _Layout, kern: Kernel, positions: np.ndarray, mass: np.ndarray, velocity: np.ndarray | None
) -> np.ndarray:
    v = np.zeros((len(positions), 3)) if velocity is None else np.asarray(velocity, dtype=float)
    if lay.cylindrical:
        _, angle = _cylindrical_frame(lay, positions)
        v = _to_cylindrical(lay, v, angle)
    values = np.empty((len(positions), 10))
    values[:, 0] = mass
    values[:, 1:4] = mass[:, None] * v
    for j, (a, b) in enumerate(_FLUX):
        values[:, 4 + j] = mass * v[:, a] * v[:, b]
    return _deposit_points(lay, kern, positions, values) / np.reshape(lay.volume, (-1, 1))


def _contact_sums(
    lay: _Layout, kern: Kernel, start: np.ndarray, branch: np.ndarray, force: np.ndarray
) -> np.ndarray:
    if lay.cylindrical:
        _, angle = _cylindrical_frame(lay, start - 0.5 * branch)
        force, rotated = _to_cylindrical(lay, force, angle), _to_cylindrical(lay, branch, angle)
    else:
        rotated = branch
    values = (force[:, :, None] * rotated[:, None, :]).reshape(-1, 9)
    return _deposit_segments(lay, kern, start, branch, values) / np.reshape(lay.volume, (-1, 1))


def coarse_grain(
    grid: Grid,
    positions: np.ndarray,
    mass: np.ndarray,
    velocity: np.ndarray | None = None,
    contacts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    *,
    kernel: str = "gaussian",
    width: float,
    box: Any = None,
    boundary: Sequence[str] | None = None,
) -> Fields:
    """The fields of one set of plain arrays: ``positions`` (N, 3), ``mass`` (N,), ``velocity``
    (N, 3) or None, ``contacts`` = (line starts (M, 3), branch vectors (M, 3), forces (M, 3))
    or None; the segments run from each start to ``start - branch``. ``box`` and ``boundary``
    as in a frame (for the grid's defaults and periodic wrapping)."""
    kern = Kernel(kernel, width)
    lay = grid.layout(box, boundary)
    _check_resolution(lay, kern)
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    mass = np.asarray(mass, dtype=float).reshape(-1)
    if len(mass) != len(positions) or (velocity is not None and np.shape(velocity) != positions.shape):
        raise ConfigError(
            f"coarse_grain: positions {positions.shape}, mass {mass.shape} and velocity "
            f"{np.shape(velocity) if velocity is not None else None} must describe the same particles"
        )
    sums = _Sums(_particle_sums(lay, kern, positions, mass, velocity), None, velocity is not None)
    if contacts is not None:
        start, branch, force = (np.asarray(a, dtype=float).reshape(-1, 3) for a in contacts)
        sums.contacts = _contact_sums(lay, kern, start, branch, force)
    return Fields(sums, lay, kern, frames=(0,), species=None)


# -- the results ------------------------------------------------------------------------------


@dataclass(eq=False)
class Fields:
    """Coarse-grained fields on a grid (time-averaged over ``frames``).

    Arrays have the grid's shape (``(bins,)`` for 1D, ``(n1, n2)`` for 2D and cylindrical,
    ``(nx, ny, nz)`` for 3D), followed by ``(3,)`` for vectors and ``(3, 3)`` for tensors
    (components x, y, z; on a cylindrical grid r, θ, axis). Stresses are compressive positive.
    """

    _sums: _Sums = field(repr=False)
    _layout: _Layout = field(repr=False)
    kernel: Kernel
    frames: tuple[int, ...]
    species: tuple[int, ...] | None

    def _field(self, columns: slice) -> np.ndarray:
        return self._sums.points[:, columns] / self._sums.frames

    @property
    def shape(self) -> tuple[int, ...]:
        """The grid's shape."""
        return self._layout.shape

    @property
    def names(self) -> tuple[str, ...]:
        """The grid's coordinate names (``('z',)``, ``('x', 'z')``, ``('r', 'z')`` ...)."""
        return self._layout.names

    @property
    def coordinates(self) -> tuple[np.ndarray, ...]:
        """Cell centres along each grid dimension."""
        return self._layout.coordinates

    @property
    def edges(self) -> tuple[np.ndarray, ...]:
        """Cell edges along each grid dimension."""
        return self._layout.edges

    @property
    def cell_volume(self) -> np.ndarray:
        """The volume of each cell (broadcastable to :attr:`shape`)."""
        return np.broadcast_to(self._layout.volume, self.shape)

    @property
    def density(self) -> np.ndarray:
        """Mass per unit volume."""
        return self._field(slice(0, 1)).reshape(self.shape)

    def _require_velocities(self, what: str) -> None:
        if not self._sums.velocities:
            raise AttributeProblem(
                f"Fields.{what} needs the particles' velocities (columns vx, vy, vz), which the frames lack"
            )

    @property
    def momentum(self) -> np.ndarray:
        """Momentum per unit volume."""
        self._require_velocities("momentum")
        return self._field(slice(1, 4)).reshape((*self.shape, 3))

    @property
    def velocity(self) -> np.ndarray:
        """Momentum over density (NaN where there is no mass)."""
        rho = self.density[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(rho > 0, self.momentum / rho, np.nan)

    @property
    def kinetic_stress(self) -> np.ndarray:
        """``sum m v' ⊗ v' phi`` about the local mean velocity (0 where there is no mass)."""
        self._require_velocities("kinetic_stress")
        flux = self._field(slice(4, 10))
        full = np.empty((len(flux), 3, 3))
        for j, (a, b) in enumerate(_FLUX):
            full[:, a, b] = full[:, b, a] = flux[:, j]
        p = self._field(slice(1, 4))
        rho = self._field(slice(0, 1))
        with np.errstate(divide="ignore", invalid="ignore"):
            mean = np.where(rho[:, :, None] > 0, p[:, :, None] * p[:, None, :] / rho[:, :, None], 0.0)
        return (full - mean).reshape((*self.shape, 3, 3))

    @property
    def contact_stress(self) -> np.ndarray:
        """``sum f ⊗ b ∫ phi ds`` over the contacts."""
        if self._sums.contacts is None:
            raise ConfigError(
                "Fields.contact_stress needs contact records, and the frames have none: run the "
                "simulation with contact output (its trajectory then holds a Contacts group read as "
                "system.Contacts), or pass contacts=... to coarse_grain"
            )
        return (self._sums.contacts / self._sums.frames).reshape((*self.shape, 3, 3))

    @property
    def stress(self) -> np.ndarray:
        """Kinetic plus contact stress."""
        return self.kinetic_stress + self.contact_stress

    @property
    def mass(self) -> float:
        """The mass in the grid: the sum of density times cell volume."""
        return float((self.density * self.cell_volume).sum())

    def __repr__(self) -> str:
        grid = " x ".join(f"{n} {name}" for n, name in zip(self.shape, self.names))
        return (
            f"Fields({grid}; {self.kernel.name} kernel of width {self.kernel.width:g}; "
            f"{len(self.frames)} frame(s); species {'all' if self.species is None else list(self.species)})"
        )

    # -- plots and files ------------------------------------------------------------------------

    def _quantity(self, quantity: str) -> np.ndarray:
        """``density``, ``velocity_z``, ``stress_zz``, ``kinetic_stress_xz``, ``momentum_x`` ..."""
        components = "rθ" + self.names[-1] if self._layout.cylindrical else _NAMES
        for name in ("density", "momentum", "velocity", "kinetic_stress", "contact_stress", "stress"):
            if quantity == name and name == "density":
                return self.density
            if quantity.startswith(name + "_"):
                suffix = quantity[len(name) + 1 :]
                index = tuple(components.index(ch) for ch in suffix if ch in components)
                rank = 1 if name in ("momentum", "velocity") else 2
                if len(index) == rank == len(suffix):
                    return getattr(self, name)[(Ellipsis,) + index]
        raise ConfigError(
            f"Unknown quantity {quantity!r}: use density, or momentum_<a>, velocity_<a> or "
            f"(kinetic_|contact_)stress_<ab> with components {', '.join(components)}"
        )

    def plot(
        self,
        quantity: str = "density",
        *,
        ax: Any = None,
        quiver: bool = False,
        path: str | os.PathLike[str] | None = None,
        **options: Any,
    ) -> Any:
        """Plot ``quantity`` (see :meth:`_quantity` for the names: ``density``, ``velocity_z``,
        ``stress_zz`` ...): a profile on a 1D grid, a map (``pcolormesh``) with ``quiver=True``
        adding velocity arrows on a 2D or cylindrical grid. Draws into ``ax`` (a new figure
        when None), saves to ``path`` if given; returns the axes. Needs matplotlib."""
        try:
            import matplotlib.pyplot as plt
        except ImportError as exc:  # pragma: no cover - depends on the installation
            raise ConfigError("Fields.plot needs matplotlib: pip install matplotlib") from exc
        values = self._quantity(quantity)
        if ax is None:
            _, ax = plt.subplots()
        if len(self.shape) == 1:
            ax.plot(self.coordinates[0], values, **options)
            ax.set_xlabel(self.names[0])
            ax.set_ylabel(quantity)
        elif len(self.shape) == 2:
            mesh = ax.pcolormesh(*self.edges, values.T, shading="flat", **options)
            ax.figure.colorbar(mesh, ax=ax, label=quantity)
            if quiver:
                lay = self._layout
                first, second = (0, 2) if lay.cylindrical else (lay.axes[0], lay.axes[1])
                velocity = self.velocity
                centres = np.meshgrid(*self.coordinates, indexing="ij")
                ax.quiver(*centres, velocity[..., first], velocity[..., second])
            ax.set_xlabel(self.names[0])
            ax.set_ylabel(self.names[1])
            ax.set_aspect("equal")
        else:
            raise ConfigError("Fields.plot draws 1D and 2D grids; write 3D fields with to_vtk() for ParaView")
        if path is not None:
            ax.figure.savefig(path)
        return ax

    def to_vtk(self, path: str | os.PathLike[str]) -> None:
        """Write the fields as VTK image data (``.vti`` XML, ASCII) for ParaView: cell data
        ``density``, ``velocity`` and ``momentum`` (3 components), ``kinetic_stress``,
        ``contact_stress`` and ``stress`` (9 components, row-major) where available. A 1D or 2D
        grid is one cell thick along the averaged axes; a cylindrical grid is written in the
        ``(r, axis)`` plane (x = r, z = axis)."""
        lay = self._layout
        origin, spacing, cells = np.zeros(3), np.ones(3), np.ones(3, dtype=np.int64)
        dims = (0, 2) if lay.cylindrical else lay.axes
        for d, a in enumerate(dims):
            origin[a], spacing[a], cells[a] = lay.lower[d], lay.spacing[d], lay.n[d]
        arrays: dict[str, np.ndarray] = {"density": self.density}
        if self._sums.velocities:
            arrays |= {
                "velocity": self.velocity,
                "momentum": self.momentum,
                "kinetic_stress": self.kinetic_stress,
            }
        if self._sums.contacts is not None:
            arrays["contact_stress"] = self.contact_stress
            if self._sums.velocities:
                arrays["stress"] = self.stress
        extent = " ".join(f"0 {n}" for n in cells)
        root = ET.Element("VTKFile", type="ImageData", version="1.0", byte_order="LittleEndian")
        image = ET.SubElement(
            root,
            "ImageData",
            WholeExtent=extent,
            Origin=" ".join(repr(float(x)) for x in origin),
            Spacing=" ".join(repr(float(x)) for x in spacing),
        )
        cell_data = ET.SubElement(ET.SubElement(image, "Piece", Extent=extent), "CellData", Scalars="density")
        missing = [a for a in range(3) if a not in dims]
        for name, array in arrays.items():
            components = int(np.prod(array.shape[len(self.shape) :]))
            full = array.reshape(self.shape + (1,) * len(missing) + (components,))
            full = np.moveaxis(full, range(3), [*dims, *missing])  # dimensions onto x, y, z
            flat = np.transpose(full, (2, 1, 0, 3)).reshape(-1)  # VTK orders cells x fastest
            element = ET.SubElement(
                cell_data,
                "DataArray",
                type="Float64",
                Name=name,
                NumberOfComponents=str(components),
                format="ascii",
            )
            element.text = " ".join(repr(float(x)) for x in np.nan_to_num(flat, nan=0.0))
        ET.indent(root)
        ET.ElementTree(root).write(os.fspath(path), xml_declaration=True, encoding="utf-8")


# -- frames of a System -----------------------------------------------------------------------


class CoarseGrain:
    """Coarse-graining of a :class:`~pygran_core.analysis.system.System`'s frames onto ``grid`` with
    ``kernel`` (gaussian, lucy, heaviside) of ``width`` (its standard deviation along one
    axis). Particle masses come from a ``mass`` column, else from ``density`` (a true density,
    or the particles' ``density`` column) and the radii. Contact stress needs contact records
    (``system.Contacts``, columns ``id1 id2 fx fy fz cx cy cz bx by bz``).

    ``cg = CoarseGrain(system, grid=Grid1D(axis='z', bins=100), kernel='lucy', width=r)`` then
    ``fields = cg.compute(frames=slice(10, 20), species=None)``.
    """

    def __init__(
        self,
        system: System,
        grid: Grid,
        kernel: str = "gaussian",
        width: float | None = None,
        density: float | None = None,
    ) -> None:
        if not isinstance(grid, (Grid1D, Grid2D, Grid3D, GridCylindrical)):
            raise ConfigError(
                f"CoarseGrain: grid must be a Grid1D, Grid2D, Grid3D or GridCylindrical, not {grid!r}"
            )
        if width is None:
            raise ConfigError(
                "CoarseGrain needs width=... (the kernel's standard deviation, e.g. a particle radius)"
            )
        if "Particles" not in system.names:
            raise ConfigError(f"CoarseGrain needs a System with Particles; it has {', '.join(system.names)}")
        self.system, self.grid, self.kernel, self.density = system, grid, Kernel(kernel, width), density

    def _frames(self, frames: int | slice | Sequence[int] | None) -> list[int]:
        n = len(self.system)
        if frames is None:
            return [self.system.frame]
        if isinstance(frames, slice):
            chosen = list(range(n))[frames]
        elif isinstance(frames, (int, np.integer)) and not isinstance(frames, bool):
            chosen = [int(frames)]
        else:
            chosen = [int(f) for f in frames]  # type: ignore[union-attr]
        if not chosen:
            raise SelectionError(f"frames={frames!r} selects no frame of the system's {n}")
        for f in chosen:
            if not -n <= f < n:
                raise SelectionError(f"Frame {f} is out of range: the system has {n} frames (0..{n - 1})")
        return [f % n for f in chosen]

    def compute(
        self, frames: int | slice | Sequence[int] | None = None, species: int | Sequence[int] | None = None
    ) -> Fields:
        """Fields averaged over ``frames`` (an index, a slice, a list; None: the current frame)
        for the particles of ``species`` (a ``type`` or several; None: all). With species, a
        contact's line is split at its contact point: each half counts for its own particle's
        species (a wall contact for the particle's), so the species' stresses add up to the
        total."""
        chosen = self._frames(frames)
        wanted = None if species is None else tuple(int(s) for s in np.atleast_1d(species))
        here = self.system.frame
        total: _Sums | None = None
        layout: _Layout | None = None
        try:
            for f in chosen:
                self.system.goto(f)
                sums, layout = self._one_frame(wanted)
                if total is None:
                    total = sums
                else:
                    total += sums
        finally:
            self.system.goto(here)
        assert total is not None and layout is not None
        return Fields(total, layout, self.kernel, frames=tuple(chosen), species=wanted)

    def _one_frame(self, species: tuple[int, ...] | None) -> tuple[_Sums, _Layout]:
        particles = self.system.Particles
        lay = self.grid.layout(particles.meta.get("box"), particles.meta.get("boundary"))
        _check_resolution(lay, self.kernel)
        positions = particles.positions
        mass = particles.computeMass(self.density) if len(particles) else np.zeros(0)
        columns = ("vx", "vy", "vz")
        velocities = all(c in particles for c in columns)
        velocity = np.column_stack([particles[c] for c in columns]).astype(float) if velocities else None
        types = np.asarray(particles["type"]) if species is not None else None
        keep = np.ones(len(particles), dtype=bool) if types is None else np.isin(types, list(species or ()))
        sums = _Sums(
            _particle_sums(
                lay, self.kernel, positions[keep], mass[keep], None if velocity is None else velocity[keep]
            ),
            None,
            velocities,
        )
        if "Contacts" in self.system.names:
            sums.contacts = self._contacts(lay, particles, positions, types, species)
        return sums, lay

    def _contacts(
        self,
        lay: _Layout,
        particles: Any,
        positions: np.ndarray,
        types: np.ndarray | None,
        species: tuple[int, ...] | None,
    ) -> np.ndarray:
        contacts = self.system.Contacts
        needed = ("id1", "id2", "fx", "fy", "fz", "bx", "by", "bz") + (("cx", "cy", "cz") if species else ())
        missing = [c for c in needed if c not in contacts]
        if missing:
            raise ConfigError(f"CoarseGrain: the contact records lack the columns {missing}")
        ids = np.asarray(particles["id"], dtype=np.int64)
        order = np.argsort(ids, kind="stable")

        def lookup(wanted: np.ndarray) -> np.ndarray:
            at = np.minimum(np.searchsorted(ids, wanted, sorter=order), len(ids) - 1)
            found = order[np.maximum(at, 0)] if len(ids) else np.zeros(len(wanted), dtype=np.int64)
            bad = ids[found] != wanted if len(ids) else np.ones(len(wanted), dtype=bool)
            if bad.any():
                raise ConfigError(
                    f"CoarseGrain: contact records name particle ids {np.unique(wanted[bad])[:5].tolist()} "
                    "that "
                    f"frame {self.system.frame} has no particle for"
                )
            return found

        id1 = np.asarray(contacts["id1"], dtype=np.int64)
        id2 = np.asarray(contacts["id2"], dtype=np.int64)
        force = np.column_stack([contacts[c] for c in ("fx", "fy", "fz")]).astype(float).reshape(-1, 3)
        branch = np.column_stack([contacts[c] for c in ("bx", "by", "bz")]).astype(float).reshape(-1, 3)
        first = lookup(id1)
        start = positions[first]
        if species is None or types is None:
            return _contact_sums(lay, self.kernel, start, branch, force)
        point = np.column_stack([contacts[c] for c in ("cx", "cy", "cz")]).astype(float).reshape(-1, 3)
        mine = np.isin(types[first], species)
        pair = id2 >= 0
        second = lookup(id2[pair])
        theirs = np.zeros(len(id2), dtype=bool)
        theirs[pair] = np.isin(types[second], species)
        # id1's half: from its centre to the contact point; id2's: from its centre (start - b)
        # to the contact point, with the reaction force; together they make f ⊗ b
        starts = np.concatenate((start[mine], (start - branch)[theirs]))
        branches = np.concatenate(((start - point)[mine], (start - branch - point)[theirs]))
        forces = np.concatenate((force[mine], -force[theirs]))
        return _contact_sums(lay, self.kernel, starts, branches, forces)
