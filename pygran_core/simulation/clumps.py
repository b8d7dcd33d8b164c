"""Rigid clumps of overlapping spheres (multisphere species): their mass properties and
orientations, shared by the engines that integrate clumps themselves and by their tests.

A clump's template is a sequence of spheres ``(x, y, z, r)`` in its own frame. Its mass,
centre and inertia are those of the union of the spheres (overlaps counted once), integrated
by Monte Carlo with a fixed seed (:func:`mass_properties`). Orientations are unit
quaternions ``(w, x, y, z)`` turning the template frame into the world frame. A clump is
placed, and counted in a region, by the centre of its bounding sphere, as LIGGGHTS does
(:func:`bounding_sphere`, :func:`bounding_centres`).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

#: A template: rows ``(x, y, z, r)`` of the spheres in the body's frame.
Spheres = Sequence[Sequence[float]] | np.ndarray

__all__ = [
    "MassProperties",
    "bounding_centres",
    "bounding_sphere",
    "mass_properties",
    "orientations",
    "quaternion_of",
    "random_orientations",
    "rotation_matrix",
]

#: Monte Carlo samples of :func:`mass_properties` (about 0.1 % noise on a mass or moment).
SAMPLES = 500_000
#: :func:`bounding_sphere` tries every order of up to this many spheres, else as many random orders
#: as there are orders of this many (720).
ALL_ORDERS = 6


@dataclass(frozen=True)
class MassProperties:
    """Mass (kg), centre (m, template frame) and inertia tensor (kg m^2, about the centre,
    template frame) of a clump; ``moments`` and ``axes`` are its principal moments and axes
    (the columns of a proper rotation, ``inertia = axes @ diag(moments) @ axes.T``)."""

    mass: float
    centre: np.ndarray
    inertia: np.ndarray
    moments: np.ndarray
    axes: np.ndarray


def _template(spheres: Spheres) -> np.ndarray:
    array = np.array(spheres, float).reshape(-1, 4)
    if not len(array) or np.any(array[:, 3] <= 0) or not np.all(np.isfinite(array)):
        raise ValueError(f"a clump template needs spheres (x, y, z, r > 0), got {spheres!r}")
    return array


def mass_properties(
    spheres: Spheres, density: float, samples: int = SAMPLES, seed: int = 0
) -> MassProperties:
    """Mass properties of the union of ``spheres`` of ``density``.

    Monte Carlo over the spheres one by one: ``samples`` points in all, shared by volume,
    uniform in each sphere and weighted by one over the number of spheres holding them, so
    that a region several spheres share counts once. Spheres that do not overlap are exact
    (every weight is 1), and the noise is that of the overlaps only: about 0.1 % of a
    mass or a principal moment with the default samples. The same template, density, samples
    and seed give the same bits (results are cached).
    """
    template = _template(spheres)
    return _mass_properties(tuple(map(tuple, template.tolist())), float(density), int(samples), int(seed))


@functools.lru_cache(maxsize=64)
def _mass_properties(
    spheres: tuple[tuple[float, ...], ...], density: float, samples: int, seed: int
) -> MassProperties:
    template = np.array(spheres)
    centres, radii = template[:, :3], template[:, 3]
    volumes = 4.0 / 3.0 * np.pi * radii**3
    counts = np.maximum(np.round(samples * volumes / volumes.sum()).astype(int), 1000)
    reach = np.linalg.norm(centres[:, None] - centres[None], axis=-1) < radii[:, None] + radii[None]
    rng = np.random.default_rng(seed)
    volume, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
    for k, count in enumerate(counts):
        direction = rng.normal(size=(count, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        points = centres[k] + direction * (radii[k] * rng.uniform(size=(count, 1)) ** (1 / 3))
        holders = np.zeros(count)
        for j in np.flatnonzero(reach[k]):
            holders += np.sum((points - centres[j]) ** 2, axis=1) < radii[j] ** 2
        holders[holders == 0] = 1.0  # the sphere's own surface, at rounding
        weight = volumes[k] / count / holders
        volume += weight.sum()
        first += weight @ points
        second += (points * weight[:, None]).T @ points
    mass = density * volume
    centre = first / volume
    spread = density * (second - volume * np.outer(centre, centre))  # sum of m d d^T about the centre
    inertia = np.eye(3) * np.trace(spread) - spread
    inertia = 0.5 * (inertia + inertia.T)
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    for array in (centre, inertia, moments, axes):
        array.flags.writeable = False
    return MassProperties(float(mass), centre, inertia, moments, axes)


def bounding_sphere(spheres: Spheres) -> tuple[np.ndarray, float]:
    """Centre (template frame) and radius of a sphere holding every sphere of the template, found
    as LIGGGHTS' ``particletemplate/multisphere`` finds its bounding sphere (by which it places
    a clump and counts it in a region): starting from one sphere, grown one sphere at a time
    (moved towards and enlarged just enough to hold each sphere it does not hold yet), the
    smallest over orders of the spheres (every order of up to :data:`ALL_ORDERS` spheres, else
    720 seeded random ones; LIGGGHTS tries 200 random ones). For spheres on one line (tablets,
    rods) every order gives the smallest enclosing sphere, so the centre is LIGGGHTS' own; for
    others LIGGGHTS may settle on another order's sphere, a fraction of a radius apart."""
    template = _template(spheres)
    centre, radius = _bounding_sphere(tuple(map(tuple, template.tolist())))
    return centre.copy(), radius


@functools.lru_cache(maxsize=64)
def _bounding_sphere(spheres: tuple[tuple[float, ...], ...]) -> tuple[np.ndarray, float]:
    template = np.array(spheres)
    centres, radii = template[:, :3], template[:, 3]
    n = len(template)
    if n <= ALL_ORDERS:
        orders = np.array(list(itertools.permutations(range(n))))
    else:
        rng = np.random.default_rng(0)
        orders = np.array([rng.permutation(n) for _ in range(720)])
    centre, radius = centres[orders[:, 0]], radii[orders[:, 0]]
    for k in orders[:, 1:].T:  # the k-th sphere of each order
        d = centres[k] - centre
        dist = np.linalg.norm(d, axis=1)
        short = np.maximum(dist + radii[k] - radius, 0.0)  # how far the sphere sticks out
        with np.errstate(divide="ignore", invalid="ignore"):
            shift = d * np.where(dist > 0, short / (2 * dist), 0.0)[:, None]
        centre = centre + shift
        radius = np.where(dist > 0, radius + np.linalg.norm(shift, axis=1), np.maximum(radius, radii[k]))
    best = int(np.argmin(radius))
    return centre[best], float(radius[best])


@functools.lru_cache(maxsize=64)
def _bounding_weights(spheres: tuple[tuple[float, ...], ...]) -> np.ndarray:
    """Weights ``w`` (summing to 1) with ``sum_k w_k x_k`` the centre of the bounding sphere for
    any placement ``x_k`` of the template's sphere centres (the centre lies in their affine hull)."""
    template = np.array(spheres)
    centre, _ = _bounding_sphere(spheres)
    system = np.vstack([template[:, :3].T, np.ones(len(template))])
    weights, *_ = np.linalg.lstsq(system, np.append(centre, 1.0), rcond=None)
    return weights


def bounding_centres(
    positions: np.ndarray, bodies: np.ndarray, types: np.ndarray, templates: Mapping[int, Spheres]
) -> tuple[np.ndarray, np.ndarray]:
    """Each clump's first sphere and the centre of its bounding sphere (:func:`bounding_sphere`)
    in the world, from the positions of its spheres.

    ``positions``, ``bodies`` (each sphere's clump; negative: a single sphere) and ``types`` are
    per sphere, ordered by id, so that a clump's spheres come in its template's order;
    ``templates`` gives each multisphere type's template. Returns ``(first, centres)``: for the
    clumps in the order of their first spheres, that sphere's index and the centre.
    """
    positions = np.asarray(positions, float).reshape(-1, 3)
    bodies = np.asarray(bodies)
    members = np.flatnonzero(bodies >= 0)
    members = members[np.argsort(bodies[members], kind="stable")]
    _, start, counts = np.unique(bodies[members], return_index=True, return_counts=True)
    first = members[start]
    by_first = np.argsort(first, kind="stable")
    first, start, counts = first[by_first], start[by_first], counts[by_first]
    kinds = np.asarray(types)[first]
    centres = np.empty((len(first), 3))
    for kind in np.unique(kinds):
        template = _template(templates[int(kind)])
        chosen = np.flatnonzero(kinds == kind)
        if np.any(counts[chosen] != len(template)):
            raise ValueError(f"clumps of type {kind} with other than its template's {len(template)} spheres")
        spheres = members[start[chosen][:, None] + np.arange(len(template))]
        weights = _bounding_weights(tuple(map(tuple, template.tolist())))
        centres[chosen] = np.einsum("k,nkd->nd", weights, positions[spheres])
    return first, centres


def orientations(orientation: str | Sequence[float], count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` unit quaternions ``(w, x, y, z)`` as an insertion's ``orientation`` says:
    ``'random'`` (uniform, from ``rng``), ``'template'`` (the template's own) or a quaternion."""
    if orientation == "random":
        return random_orientations(count, rng)
    q = np.array([1.0, 0.0, 0.0, 0.0] if orientation == "template" else orientation, float)
    return np.tile(q / np.linalg.norm(q), (count, 1))


def random_orientations(count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` unit quaternions ``(w, x, y, z)`` uniform over rotations (normalised
    Gaussian 4-vectors), from ``rng``."""
    q = rng.normal(size=(count, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` ``(w, x, y, z)``."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def quaternion_of(matrix: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` (``w >= 0``) of rotation matrices ``(..., 3, 3)``."""
    m = np.asarray(matrix, float)
    trace = np.trace(m, axis1=-2, axis2=-1)
    # the largest of 4 w^2, 4 x^2, 4 y^2, 4 z^2 gives the best-conditioned formula
    squares = np.stack(
        [1 + trace, 1 + 2 * m[..., 0, 0] - trace, 1 + 2 * m[..., 1, 1] - trace, 1 + 2 * m[..., 2, 2] - trace],
        -1,
    )
    best = np.argmax(squares, axis=-1)
    big = 0.5 * np.sqrt(np.take_along_axis(squares, best[..., None], -1)[..., 0])
    off = {
        "wx": m[..., 2, 1] - m[..., 1, 2],
        "wy": m[..., 0, 2] - m[..., 2, 0],
        "wz": m[..., 1, 0] - m[..., 0, 1],
        "xy": m[..., 0, 1] + m[..., 1, 0],
        "xz": m[..., 0, 2] + m[..., 2, 0],
        "yz": m[..., 1, 2] + m[..., 2, 1],
    }
    q = np.empty(m.shape[:-2] + (4,))
    quarter = 0.25 / big
    rows = {
        0: (big, off["wx"] * quarter, off["wy"] * quarter, off["wz"] * quarter),
        1: (off["wx"] * quarter, big, off["xy"] * quarter, off["xz"] * quarter),
        2: (off["wy"] * quarter, off["xy"] * quarter, big, off["yz"] * quarter),
        3: (off["wz"] * quarter, off["xz"] * quarter, off["yz"] * quarter, big),
    }
    for k, row in rows.items():
        chosen = best == k
        q[chosen] = np.stack(row, -1)[chosen]
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)
