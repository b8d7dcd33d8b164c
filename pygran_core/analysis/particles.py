"""Particles: a SubSystem of spheres (LIGGGHTS columns) and the granular statistics on them.

All statistics are vectorised with numpy (pair searches in the cell list of
:mod:`._neighbors`, compiled when pygran-native is installed); none loops over particles in
Python. Lengths are in the object's ``units``; angles in degrees.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pygran_core.analysis import _neighbors, mixing
from pygran_core.analysis.subsystem import SubSystem
from pygran_core.errors import ConfigError, unknown_key

_SHAPES = ("box", "cylinder-x", "cylinder-y", "cylinder-z")
_AXES = {"x": 0, "y": 1, "z": 2}


class RDF(NamedTuple):
    """Radial distribution function: ``g`` at bin centres ``r``; ``references`` are the indices
    of the particles used as centres (all of them when every direction is periodic)."""

    g: np.ndarray
    r: np.ndarray
    references: np.ndarray


class Particles(SubSystem):
    """Spherical particles: one array per LIGGGHTS column (``id``, ``type``, ``x``, ``radius``,
    ``vx``, ``fx``, ...) plus ``positions`` (N, 3), and the statistics of powder technology."""

    @property
    def natoms(self) -> int:
        """Number of particles (the original's ``natoms``; the same as ``len(particles)``)."""
        return len(self)

    # -- geometry helpers -------------------------------------------------------------------

    @property
    def positions(self) -> np.ndarray:
        """Centres as an (N, 3) array (a new array each call)."""
        return np.column_stack((self.x, self.y, self.z)).astype(float, copy=False).reshape(-1, 3)

    def _radii(self) -> np.ndarray:
        return np.asarray(self.radius, dtype=float)

    def _periodic(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lower bounds, box lengths, periodic mask) of the simulation box; periodic needs a box."""
        box, boundary = self._meta.get("box"), self._meta.get("boundary")
        if box is None or boundary is None:
            return np.zeros(3), np.zeros(3), np.zeros(3, dtype=bool)
        box = np.asarray(box, dtype=float).reshape(3, 2)
        periodic = np.array([str(flag).startswith("p") for flag in boundary][:3], dtype=bool)
        return box[:, 0], box[:, 1] - box[:, 0], periodic

    def _wrapped(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions moved into ``[0, L)`` along periodic axes, and the box lengths along
        them (0 along the others): the input of :func:`._neighbors.cell_list`."""
        positions = self.positions
        lower, length, periodic = self._periodic()
        if not periodic.any():
            return positions, np.zeros(3)
        for axis in np.flatnonzero(periodic):
            column = positions[:, axis]
            np.subtract(column, lower[axis], out=column)
            np.remainder(column, length[axis], out=column)
            column[column == length[axis]] = 0.0  # a tiny negative value wraps to L
        return positions, np.where(periodic, length, 0.0)

    def _extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corners of the region the spheres occupy (centres +- radius)."""
        positions, radii = self.positions, self._radii()[:, None]
        return (positions - radii).min(axis=0), (positions + radii).max(axis=0)

    def _require(self, what: str) -> None:
        if len(self) == 0:
            raise ConfigError(f"{what} needs at least one particle; this {type(self).__name__} is empty")

    # -- structure ---------------------------------------------------------------------------

    def computeRDF(self, dr: float | None = None, rMax: float | None = None) -> RDF:
        """Radial distribution function g(r) on bins of width ``dr`` (default ``rMax / 100``) up to ``rMax``.

        Periodic directions (``boundary`` flags ``p`` with a ``box``) wrap around; along the
        others only particles at least ``rMax`` from the faces of the particles' bounding box
        serve as centres, which removes edge effects. The number density is
        ``(N - 1) / V`` with ``V`` the periodic box lengths times the bounding extents, so an
        ideal gas gives g = 1. ``rMax`` defaults to half the smallest periodic length or a
        quarter of the smallest non-periodic extent. A pair counts in bin ``k`` when
        ``edges[k]² < d² <= edges[k+1]²`` (``d²`` of the minimum image).
        """
        if len(self) < 2:
            raise ConfigError(
                f"computeRDF needs at least two particles; this {type(self).__name__} has {len(self)}"
            )
        data, lengths = self._wrapped()
        periodic = lengths > 0
        lower = np.where(periodic, 0.0, data.min(axis=0))
        length = np.where(periodic, lengths, data.max(axis=0) - lower)
        limit = np.where(periodic, length / 2, length / 4)
        rMax = float(limit.min() if rMax is None else rMax)
        if rMax <= 0 or (periodic & (rMax > length / 2)).any():
            raise ConfigError(
                f"computeRDF: rMax={rMax} must be > 0 and at most half of each periodic box length"
            )
        nbins = max(1, int(round(rMax / (dr or rMax / 100))))
        edges = np.linspace(0.0, rMax, nbins + 1)
        inside = (((data >= lower + rMax) & (data <= lower + length - rMax)) | periodic).all(axis=1)
        references = np.flatnonzero(inside)
        if references.size == 0:
            raise ConfigError(
                f"computeRDF: no particle lies at least rMax={rMax:g} from every non-periodic face of the "
                f"region {lower} + {length}; choose a smaller rMax"
            )
        cells = _neighbors.cell_list(data, lengths, rMax)
        counts = _neighbors.histogram(
            cells, edges, None if references.size == len(self) else np.asarray(inside)
        )
        volume = np.prod(np.where(periodic | (length > 0), length, 1.0))
        shells = 4.0 / 3.0 * np.pi * np.diff(edges**3)
        g = counts / (references.size * (len(self) - 1) / volume * shells)
        return RDF(g, 0.5 * (edges[1:] + edges[:-1]), references)

    rdf = computeRDF

    def computeCOM(self) -> np.ndarray:
        """Centre of mass: weighted by ``mass`` if present, else by volume (uniform density)."""
        self._require("computeCOM")
        weights = np.asarray(self.mass, dtype=float) if "mass" in self else self._radii() ** 3
        return weights @ self.positions / weights.sum()

    def computeROG(self) -> float:
        """Radius of gyration ``sqrt(<|r_i - r_mean|^2>)`` of the centres (unweighted)."""
        self._require("computeROG")
        positions = self.positions
        return float(np.sqrt(((positions - positions.mean(axis=0)) ** 2).sum(axis=1).mean()))

    def computeRadius(self, N: int = 100) -> float:
        """Radius of the assembly: mean distance from the centroid of the ``N`` farthest centres."""
        self._require("computeRadius")
        positions = self.positions
        distance = np.sqrt(((positions - positions.mean(axis=0)) ** 2).sum(axis=1))
        return float(np.sort(distance)[-N:].mean())

    # -- mass, volume, density ------------------------------------------------------------------

    def computeMass(self, density: float | None = None) -> np.ndarray:
        """Mass of each particle: ``density * 4/3 pi r^3``, or the ``mass`` column, or the
        ``density`` column times the volume (in that order)."""
        if density is None and "mass" in self:
            return np.asarray(self.mass, dtype=float)
        if density is None and "density" not in self:
            raise ConfigError(
                "computeMass needs a true density: pass density=... or give the particles a 'mass' or "
                f"'density' attribute (they have {self.keys()})"
            )
        rho = np.asarray(self.density if density is None else density, dtype=float)
        return rho * 4.0 / 3.0 * np.pi * self._radii() ** 3

    def computeVolume(self, shape: str = "box") -> float:
        """Volume of the ``shape`` enclosing every sphere: ``box`` or ``cylinder-x|y|z`` (whose
        radius is the mean half-extent across its axis). 0 for no particles."""
        if shape not in _SHAPES:
            raise unknown_key("shape", shape, _SHAPES)
        if len(self) == 0:
            return 0.0
        lower, upper = self._extent()
        extent = upper - lower
        if shape == "box":
            return float(np.prod(extent))
        axis = _AXES[shape[-1]]
        across = np.delete(extent, axis)
        return float(np.pi * (across.sum() / 4) ** 2 * extent[axis])

    def computeDensity(self, density: float | None = None, shape: str = "box") -> float:
        """Bulk density: total mass (see :meth:`computeMass`) over :meth:`computeVolume`."""
        self._require("computeDensity")
        return float(self.computeMass(density).sum() / self.computeVolume(shape))

    def computeDensityLocal(
        self, density: float | None = None, dr: float | None = None, axis: str = "z"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bulk density in slabs of thickness ``dr`` (default one diameter) along ``axis``.

        A particle counts in the slab holding its centre; a slab's volume is ``dr`` times
        the cross-section of the box enclosing every sphere. Returns (slab centres, densities).
        """
        if axis not in _AXES:
            raise unknown_key("axis", axis, _AXES)
        self._require("computeDensityLocal")
        k = _AXES[axis]
        lower, upper = self._extent()
        dr = float(dr or 2 * self._radii().max())
        nbins = max(1, int(np.ceil((upper[k] - lower[k]) / dr - 1e-9)))
        slab = np.minimum(((self.positions[:, k] - lower[k]) // dr).astype(np.intp), nbins - 1)
        mass = np.bincount(slab, weights=self.computeMass(density), minlength=nbins)
        area = np.prod(np.delete(upper - lower, k))
        return lower[k] + dr * (np.arange(nbins) + 0.5), mass / (area * dr)

    def computeAngleRepose(self) -> float:
        """Angle of repose of a heap, in degrees: ``arctan(H / L)`` with ``H`` the height of the
        spheres and ``L`` the mean base half-width ``(extent_x + extent_y) / 4``."""
        self._require("computeAngleRepose")
        lower, upper = self._extent()
        extent = upper - lower
        return float(np.degrees(np.arctan2(extent[2], (extent[0] + extent[1]) / 4)))

    # -- mixing and segregation (pygran_core.analysis.mixing) ------------------------------------

    def computeIntensitySegregation(self, resol: float | None = None, species: int | None = None) -> float:
        """Danckwerts' intensity of segregation on cells of side ``resol``: :func:`.mixing.intensity`."""
        return mixing.intensity(self, resol, species)

    def computeScaleSegregation(
        self, resol: float | None = None, maxDist: float | None = None, species: int | None = None
    ) -> mixing.ScaleSegregation:
        """Danckwerts' coefficient of correlation ``R(r)`` up to ``maxDist``: :func:`.mixing.scale`."""
        return mixing.scale(self, resol, maxDist, species)

    def computeLaceyIndex(self, resol: float | None = None, species: int | None = None) -> float:
        """Lacey's mixing index on cells of side ``resol`` (0 segregated, 1 random): :func:`.mixing.lacey`."""
        return mixing.lacey(self, resol, species)
