"""Rigid clumps of overlapping spheres (multisphere species): their mass properties and
orientations, shared by the engines that integrate clumps themselves and by their tests.

A clump's template is a sequence of spheres ``(x, y, z, r)`` in its own frame. Its mass,
centre and inertia are those of the union of the spheres (overlaps counted once), integrated
by Monte Carlo with a fixed seed (:func:`mass_properties`). Orientations are unit
quaternions ``(w, x, y, z)`` turning the template frame into the world frame.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: A template: rows ``(x, y, z, r)`` of the spheres in the body's frame.
Spheres = Sequence[Sequence[float]] | np.ndarray

__all__ = [
    "MassProperties",
    "enclosing_radius",
    "mass_properties",
    "quaternion_of",
    "random_orientations",
    "rotation_matrix",
]

#: Monte Carlo samples of :func:`mass_properties` (about 0.1 % noise on a mass or moment).
SAMPLES = 500_000


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


def enclosing_radius(spheres: Spheres) -> float:
    """Radius of the smallest sphere about the template's origin holding every sphere: a
    clump placed with its origin at a point clears whatever that sphere clears, turned any way."""
    template = _template(spheres)
    return float(np.max(np.linalg.norm(template[:, :3], axis=1) + template[:, 3]))


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
