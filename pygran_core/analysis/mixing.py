"""Mixing of a binary mixture in one configuration: Lacey's index and Danckwerts' segregation.

Every statistic samples the particles with the cells of a cubic grid of side ``resol``
(default three mean diameters), anchored at the lowest particle centre; a particle belongs
to the cell holding its centre and only cells holding particles count. ``species`` is the
particle type whose share is measured (required unless there are exactly two types).
Works on any frame: ``Temporal(system).timeseries(mixing.lacey, resol=...)`` gives the mixing
index over time. How the index depends on ``resol``, and how to choose it: :func:`lacey`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from pygran_core.analysis.subsystem import SubSystem
from pygran_core.errors import ConfigError

__all__ = ["Cells", "ScaleSegregation", "cells", "intensity", "lacey", "scale"]


@dataclass(frozen=True)
class Cells:
    """The non-empty sample cells of a grid: per-cell totals and integer coordinates."""

    count: np.ndarray  #: (C,) particles in each cell
    species: np.ndarray  #: (C,) particles of the species in each cell
    volume: np.ndarray  #: (C,) particle volume in each cell
    species_volume: np.ndarray  #: (C,) volume of the species' particles in each cell
    index: np.ndarray  #: (C, 3) integer cell coordinates
    size: float  #: the cell side ``resol``


class ScaleSegregation(NamedTuple):
    """Danckwerts' correlation coefficient ``R`` at each separation ``r`` of grid cells."""

    R: np.ndarray
    r: np.ndarray


def cells(particles: SubSystem, resol: float | None = None, species: int | None = None) -> Cells:
    """Bin ``particles`` on the cubic grid of side ``resol`` (see the module docstring)."""
    if len(particles) == 0:
        raise ConfigError("Mixing statistics need at least one particle; the Particles are empty")
    if "type" not in particles:
        raise ConfigError(f"Mixing statistics need a 'type' attribute; the particles have {particles.keys()}")
    types = np.unique(particles.type)
    if species is None:
        if types.size != 2:
            raise ConfigError(
                f"Mixing statistics of {types.size} types {types.tolist()}: pass species=<type> to "
                "compare one type against the rest"
            )
        species = types[0]
    elif species not in types:
        raise ConfigError(f"species={species} is not among the particle types {types.tolist()}")
    radii = np.asarray(particles.radius, dtype=float)
    size = float(3 * 2 * radii.mean() if resol is None else resol)
    if not size > 0:
        raise ConfigError(f"resol must be a length > 0, got {resol!r}")
    positions = np.column_stack((particles.x, particles.y, particles.z)).astype(float)
    cell = ((positions - positions.min(axis=0)) // size).astype(np.intp)
    shape = tuple(cell.max(axis=0) + 1)
    occupied, flat = np.unique(np.ravel_multi_index(cell.T, shape), return_inverse=True)
    mine = particles.type == species
    volume = 4.0 / 3.0 * np.pi * radii**3

    def per_cell(weights: np.ndarray) -> np.ndarray:
        return np.bincount(flat, weights=weights, minlength=occupied.size)

    return Cells(
        count=np.bincount(flat, minlength=occupied.size),
        species=per_cell(mine.astype(float)),
        volume=per_cell(volume),
        species_volume=per_cell(np.where(mine, volume, 0.0)),
        index=np.column_stack(np.unravel_index(occupied, shape)),
        size=size,
    )


def lacey(particles: SubSystem, resol: float | None = None, species: int | None = None) -> float:
    """Lacey's (1954) mixing index ``M = (s0^2 - s^2) / (s0^2 - sr^2)``: 0 segregated, 1 random.

    Each grid cell is a sample of ``n_c`` particles of which a number fraction ``x_c`` is
    ``species``; ``p`` is the fraction over all particles. ``s^2 = sum n_c (x_c - p)^2 / N``
    is the variance of the sample compositions (weighted by sample size), ``s0^2 = p (1-p)``
    that of the fully segregated mixture (every sample pure) and ``sr^2 = p (1-p) / n``
    that of the random mixture, ``n = N / C`` the mean sample size over the ``C`` cells.
    With this weighting a segregated mixture whose cells are pure gives exactly 0, and a
    random mixture 1 on average; an ordered mixture (every cell at ``p``) gives
    ``n / (n - 1)``.

    The cell side ``resol`` is part of the measurement. Default: three mean particle
    diameters (cells of about 10 to 15 particles in a packed bed). The index depends on it:
    larger cells average away segregation on scales below the cell (a bed segregated into
    layers thinner than ``resol`` reads as mixed, so ``M`` rises towards 1 as ``resol`` grows),
    while cells of only a few particles make ``s^2`` and ``sr^2`` noisy, so that ``M`` scatters
    from frame to frame (below one particle per cell it is undefined). Choose cells several
    particles across and smaller than the pattern you look for (such as a tenth of the bed),
    give ``resol`` explicitly, and compare indices only at the same ``resol`` (report it).
    """
    sample = cells(particles, resol, species)
    n_total = sample.count.sum()
    p = sample.species.sum() / n_total
    if p in (0.0, 1.0):
        raise ConfigError("lacey: the mixture has a single species; Lacey's index needs two")
    n_mean = n_total / sample.count.size
    if n_mean <= 1:
        raise ConfigError(
            f"lacey: the cells hold {n_mean:g} particles on average; choose a resol larger than "
            f"{sample.size:g}"
        )
    s2 = (sample.species - p * sample.count) ** 2 / sample.count
    s0 = p * (1 - p)
    return float((s0 - s2.sum() / n_total) / (s0 - s0 / n_mean))


def intensity(particles: SubSystem, resol: float | None = None, species: int | None = None) -> float:
    """Danckwerts' intensity of segregation ``var(a) / (mean(a) (1 - mean(a)))``, ``a`` the volume
    fraction of ``species`` in each non-empty cell: 1 when every cell holds one species, near 0
    for a fine random mixture."""
    sample = cells(particles, resol, species)
    fraction = sample.species_volume / sample.volume
    mean = fraction.mean()
    if mean in (0.0, 1.0):
        raise ConfigError("intensity: every cell holds one and the same species")
    return float(fraction.var() / (mean * (1.0 - mean)))


def scale(
    particles: SubSystem, resol: float | None = None, maxDist: float | None = None, species: int | None = None
) -> ScaleSegregation:
    """Danckwerts' correlation ``R(r) = <(a_i - m)(a_j - m)> / var(a)`` over every pair of non-empty
    cells ``r`` apart, up to ``maxDist`` (default ten cells), ``a`` as in :func:`intensity`.

    The average is exact (all pairs, found with cKDTree), one value per distinct
    separation; ``R(0) = 1``. Its integral over r is the scale of segregation.
    """
    sample = cells(particles, resol, species)
    reach = 10.0 if maxDist is None else maxDist / sample.size
    deviation = sample.species_volume / sample.volume
    deviation = deviation - deviation.mean()
    variance = deviation.var()
    if variance == 0:
        raise ConfigError("scale: the composition is the same in every cell")
    index = sample.index
    pairs = cKDTree(index).query_pairs(reach + 1e-9, output_type="ndarray")
    d2 = ((index[pairs[:, 0]] - index[pairs[:, 1]]) ** 2).sum(axis=1)
    sums = np.bincount(d2, weights=deviation[pairs[:, 0]] * deviation[pairs[:, 1]], minlength=1)
    counts = np.bincount(d2, minlength=1)
    sums[0], counts[0] = (deviation**2).sum(), deviation.size
    seen = np.flatnonzero(counts)
    return ScaleSegregation(sums[seen] / counts[seen] / variance, np.sqrt(seen) * sample.size)
