"""Neighbour analysis of one configuration: contacts, overlaps, coordination, force chains.

Pairs come from the cell list of :mod:`._neighbors` (compiled when pygran-native is
installed); everything after is vectorised numpy, so there is no Python loop over particles or
pairs. Periodic boundaries (``boundary`` flags ``p`` with a ``box``) use minimum-image distances.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, NamedTuple

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from pygran_core.analysis import _neighbors
from pygran_core.analysis.particles import Particles
from pygran_core.errors import ConfigError

#: Relative round-off allowance: spheres touch when ``d <= (r_i + r_j) * (1 + CONTACT_TOLERANCE)``
#: and overlap when ``r_i + r_j - d > (r_i + r_j) * CONTACT_TOLERANCE``.
CONTACT_TOLERANCE = 1e-9


def _plain_results(
    self: np.ndarray, array: np.ndarray, context: Any = None, return_scalar: bool = False
) -> Any:
    """Ufunc and reduction results (``coon.mean()``, ``overlaps * 2``) as plain arrays or scalars."""
    array = np.asarray(array)
    return array[()] if return_scalar else array


class Overlap(NamedTuple):
    """One overlapping pair: the overlap ``d`` and the particle indices ``i < j``."""

    d: float
    i: int
    j: int


class Overlaps(np.ndarray):
    """(K, 3) float rows ``(d, i, j)``, as the original's ``overlaps``, with integer indices at hand.

    ``overlaps[:, 0]`` are the overlaps; :attr:`d`, :attr:`i` and :attr:`j` the columns
    (``i`` and ``j`` as integer arrays, ready to index particles); iterating yields
    :class:`Overlap` rows whose ``i`` and ``j`` are ints, so ``for d, i, j in overlaps`` and
    the original's ``int(contact[1])`` both work.
    """

    _pairs: np.ndarray | None  # (K, 2) indices; None in views and slices

    def __new__(cls, d: np.ndarray, pairs: np.ndarray) -> Overlaps:
        rows = np.column_stack((d, pairs)).astype(float).reshape(-1, 3)
        new = rows.view(cls)
        new._pairs = pairs.astype(np.intp).reshape(-1, 2)
        new.setflags(write=False)
        return new

    def __array_finalize__(self, obj: Any) -> None:
        self._pairs = None  # views and slices are plain float arrays

    __array_wrap__ = _plain_results

    @property
    def d(self) -> np.ndarray:
        """(K,) overlap of each pair."""
        return np.asarray(self)[:, 0]

    @property
    def i(self) -> np.ndarray:
        """(K,) index of the first particle of each pair."""
        return self._pairs[:, 0] if self._pairs is not None else np.asarray(self)[:, 1].astype(np.intp)

    @property
    def j(self) -> np.ndarray:
        """(K,) index of the second particle of each pair."""
        return self._pairs[:, 1] if self._pairs is not None else np.asarray(self)[:, 2].astype(np.intp)

    def __iter__(self) -> Iterator[Any]:
        if self._pairs is None:
            return iter(np.asarray(self))
        return (Overlap(float(d), int(i), int(j)) for d, (i, j) in zip(np.asarray(self)[:, 0], self._pairs))


class Coordination(np.ndarray):
    """Coordination number per particle (an int array), also callable as the original's method:
    ``neighbors.coon()`` is the same array, ``neighbors.coon(type1, type2)`` the number of
    ``type2`` neighbours of each ``type1`` particle (:meth:`Neighbors.coordination`)."""

    _neighbors: Neighbors | None

    def __array_finalize__(self, obj: Any) -> None:
        self._neighbors = None

    __array_wrap__ = _plain_results

    def __call__(self, type1: int | None = None, type2: int | None = None) -> np.ndarray:
        if type1 is None and type2 is None:
            return np.asarray(self)
        if type1 is None or type2 is None or self._neighbors is None:
            raise ConfigError(
                "coon(type1, type2) needs both types, e.g. coon(1, 2); coon() gives every particle's"
            )
        return self._neighbors.coordination(type1, type2)


class ForceChains(NamedTuple):
    """Result of :meth:`Neighbors.forceChain`."""

    chains: list[np.ndarray]  #: particle indices of each chain, largest chain first
    contacts: np.ndarray  #: (K, 2) particle pairs in contact
    forces: np.ndarray  #: (K,) normal force of each contact
    strong: np.ndarray  #: (K,) bool, contacts carrying more than threshold x the mean force
    ax: Any = None  #: the matplotlib Axes drawn on, when plotted


class Neighbors:
    """Neighbour pairs of a :class:`Particles` object.

    With ``cutoff=None`` two particles are neighbours when they touch or overlap
    (``d <= r_i + r_j``); with a ``cutoff`` (a length) when ``d <= cutoff``. Overlaps are
    always those of touching pairs, whatever the cutoff.
    """

    def __init__(self, particles: Particles, cutoff: float | None = None) -> None:
        if not isinstance(particles, Particles):
            raise ConfigError(f"Neighbors needs a Particles object, not {type(particles).__name__}")
        if cutoff is not None and not cutoff > 0:
            raise ConfigError(f"Neighbors: cutoff must be positive, got {cutoff}")
        self.particles = particles
        self.cutoff = cutoff
        radii = particles._radii() if len(particles) else np.zeros(0)
        data, lengths = particles._wrapped() if len(particles) else (np.zeros((0, 3)), np.zeros(3))
        reach = max(2 * radii.max(initial=0.0), cutoff or 0.0) * (1 + CONTACT_TOLERANCE)
        pairs = (
            _neighbors.pairs(_neighbors.cell_list(data, lengths, reach)) if reach else np.zeros((0, 2), int)
        )
        delta = np.empty((len(pairs), 3))
        for axis, length in enumerate(lengths):  # minimum image along periodic axes
            column = np.take(data[:, axis], pairs[:, 1]) - np.take(data[:, axis], pairs[:, 0])
            delta[:, axis] = column - length * np.round(column / length) if length > 0 else column
        distance = np.sqrt((delta**2).sum(axis=1))
        touch = radii[pairs[:, 0]] + radii[pairs[:, 1]]
        self._overlap = touch - distance
        self._touching = distance <= touch * (1 + CONTACT_TOLERANCE)
        self._overlapping = self._overlap > touch * CONTACT_TOLERANCE
        chosen = self._touching if cutoff is None else distance <= cutoff
        self._all_pairs = pairs
        self._pairs, self._distances = pairs[chosen], distance[chosen]

    @property
    def pairs(self) -> np.ndarray:
        """(M, 2) indices ``i < j`` of the neighbour pairs, sorted."""
        return self._pairs

    @property
    def distances(self) -> np.ndarray:
        """(M,) centre distance of each pair in :attr:`pairs`."""
        return self._distances

    @property
    def overlaps(self) -> Overlaps:
        """(K, 3) rows ``(d, i, j)`` for every pair whose spheres overlap by ``d`` (beyond round-off);
        see :class:`Overlaps` for the integer columns ``.i`` and ``.j``."""
        hit = self._overlapping
        return Overlaps(self._overlap[hit], self._all_pairs[hit])

    @property
    def coon(self) -> Coordination:
        """Coordination number of every particle; ``coon()`` and ``coon(type1, type2)`` as the original."""
        counts = np.bincount(self._pairs.ravel(), minlength=len(self.particles)).view(Coordination)
        counts._neighbors = self
        counts.setflags(write=False)
        return counts

    def coordination(self, type1: int, type2: int) -> np.ndarray:
        """The number of ``type2`` neighbours of each ``type1`` particle (in their order)."""
        n = len(self.particles)
        i, j = self._pairs.T
        types = self.particles.type
        counts = np.bincount(i[types[j] == type2], minlength=n) + np.bincount(
            j[types[i] == type2], minlength=n
        )
        return counts[types == type1]

    def filter(self, percent: float) -> Particles:
        """The particles left once overlaps larger than ``percent`` % of a particle's radius are removed.

        Two particles conflict when their overlap exceeds ``percent`` % of the radius of
        either. Particles without conflicts are all kept; among the others a maximal set
        without conflicts is kept (rounds of Luby's algorithm, vectorised over pairs; fewer
        conflicts first, ties broken by index), so a conflicting pair loses one particle, not
        both. The result has the class of the particles.
        """
        if not percent >= 0:
            raise ConfigError(f"filter: percent must be >= 0, got {percent}")
        n = len(self.particles)
        radii = self.particles._radii() if n else np.zeros(0)
        i, j = self._all_pairs.T
        edges = self._all_pairs[self._overlap > percent / 100.0 * np.minimum(radii[i], radii[j])]
        degree = np.bincount(edges.ravel(), minlength=n)
        priority = np.lexsort((-np.arange(n), -degree))  # ascending: most conflicts, then highest index first
        rank = np.empty(n, dtype=np.intp)
        rank[priority] = np.arange(n)
        keep = degree == 0
        active = ~keep
        while edges.size:
            best = np.full(n, -1, dtype=np.intp)
            np.maximum.at(best, edges[:, 0], rank[edges[:, 1]])
            np.maximum.at(best, edges[:, 1], rank[edges[:, 0]])
            chosen = active & (rank > best)
            keep |= chosen
            dropped = np.zeros(n, dtype=bool)
            dropped[edges[chosen[edges[:, 0]], 1]] = True
            dropped[edges[chosen[edges[:, 1]], 0]] = True
            active &= ~(chosen | dropped)
            edges = edges[active[edges[:, 0]] & active[edges[:, 1]]]
        keep |= active  # nodes whose conflicts were all resolved
        return self.particles[keep]

    def forceChain(
        self,
        threshold: float = 1.0,
        min_size: int = 3,
        stiffness: float = 1.0,
        plot: bool = False,
        ax: Any = None,
        axes: tuple[int, int] = (0, 2),
    ) -> ForceChains:
        """Force chains: clusters of particles linked by contacts that carry more than
        ``threshold`` times the mean contact force, with at least ``min_size`` particles.

        Contact forces are Hertzian, ``stiffness * sqrt(R*) * overlap**1.5`` with
        ``R* = r_i r_j / (r_i + r_j)``; ``stiffness`` (``4/3 E*``) only scales them, so the
        chains do not depend on it. With ``plot=True`` the strong contacts are drawn on ``ax``
        (a new figure if None) in the plane of ``axes``, line widths proportional to force.
        """
        radii = self.particles._radii() if len(self.particles) else np.zeros(0)
        hit = self._overlapping
        contacts, overlap = self._all_pairs[hit], self._overlap[hit]
        r_i, r_j = radii[contacts[:, 0]], radii[contacts[:, 1]]
        forces = stiffness * np.sqrt(r_i * r_j / (r_i + r_j)) * overlap**1.5
        strong = forces > threshold * forces.mean() if forces.size else np.zeros(0, dtype=bool)
        n = len(self.particles)
        links = contacts[strong]
        graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(n, n))
        _, label = connected_components(graph, directed=False)
        sizes = np.bincount(label, minlength=n)
        members = np.split(np.argsort(label, kind="stable"), np.cumsum(sizes)[:-1])
        big = np.flatnonzero(sizes >= max(min_size, 2))
        chains = [members[c] for c in big[np.argsort(-sizes[big], kind="stable")]]
        if plot:
            ax = self._plot(contacts[strong], forces[strong], ax, axes)
        return ForceChains(chains, contacts, forces, strong, ax)

    def _plot(self, links: np.ndarray, forces: np.ndarray, ax: Any, axes: tuple[int, int]) -> Any:
        from matplotlib.collections import LineCollection

        if ax is None:
            import matplotlib.pyplot as plt

            _, ax = plt.subplots()
        centres = self.particles.positions[:, list(axes)]
        widths = 0.5 + 3.0 * forces / forces.max() if forces.size else []
        ax.add_collection(LineCollection(centres[links], linewidths=widths, colors="black"))
        ax.set_xlabel("xyz"[axes[0]])
        ax.set_ylabel("xyz"[axes[1]])
        ax.autoscale()
        ax.set_aspect("equal")
        return ax
