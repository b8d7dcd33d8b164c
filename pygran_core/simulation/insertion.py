"""Placing new spheres without overlaps: engine-neutral, reproducible from a seed.

Engines that insert particles themselves (as LIGGGHTS does) need none of this; the others
(native, YADE) call :func:`place_spheres` so that the same request gives the same packing
on every engine. Candidates are drawn in batches and checked with k-d trees, never one
Python iteration per particle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from pygran_core.simulation.calls import Region


@dataclass(frozen=True)
class Obstacles:
    """What new spheres must not overlap besides other spheres: planes through ``points``
    with unit ``normals`` (acting on both sides, as primitive walls do) and triangles
    (``(T, 3, 3)`` corner coordinates)."""

    plane_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    plane_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))

    def clear(self, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Which spheres overlap no plane and no triangle."""
        ok = np.ones(len(centres), bool)
        for point, normal in zip(self.plane_points, self.plane_normals):
            ok &= np.abs((centres - point) @ normal) >= radii
        if len(self.triangles) and len(centres):
            ok &= triangle_distance(centres, self.triangles) >= radii
        return ok


def triangle_distance(points: np.ndarray, triangles: np.ndarray, batch: int = 256) -> np.ndarray:
    """Distance from each point (P, 3) to the nearest of the triangles (T, 3, 3)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, ac = b - a, c - a
    best = np.full(len(points), np.inf)
    for start in range(0, len(points), batch):
        p = points[start : start + batch, None, :]
        ap = p - a
        d1, d2 = np.einsum("ptk,tk->pt", ap, ab), np.einsum("ptk,tk->pt", ap, ac)
        bp, cp = p - b, p - c
        d3, d4 = np.einsum("ptk,tk->pt", bp, ab), np.einsum("ptk,tk->pt", bp, ac)
        d5, d6 = np.einsum("ptk,tk->pt", cp, ab), np.einsum("ptk,tk->pt", cp, ac)
        va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
        with np.errstate(divide="ignore", invalid="ignore"):
            denom = va + vb + vc
            v, w = vb / denom, vc / denom  # interior barycentric coordinates
            s_ab = np.clip(d1 / (d1 - d3), 0, 1)
            s_ac = np.clip(d2 / (d2 - d6), 0, 1)
            s_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
        inside = (va >= 0) & (vb >= 0) & (vc >= 0) & (denom > 0)
        candidates = [
            np.where(inside[..., None], a + v[..., None] * ab + w[..., None] * ac, np.nan),
            a + np.nan_to_num(s_ab)[..., None] * ab,
            a + np.nan_to_num(s_ac)[..., None] * ac,
            b + np.nan_to_num(s_bc)[..., None] * (c - b),
        ]
        distances = np.stack([np.linalg.norm(p - q, axis=-1) for q in candidates])
        best[start : start + batch] = np.nanmin(distances, axis=(0, 2))
    return best


def place_spheres(
    region: Region,
    radii: np.ndarray,
    rng: np.random.Generator,
    existing: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 3)), np.zeros(0)),
    obstacles: Obstacles | None = None,
    all_in: bool = True,
    attempts: int = 50,
) -> tuple[np.ndarray, np.ndarray]:
    """Place spheres of ``radii`` in ``region`` overlapping neither each other, the
    ``existing`` (positions, radii) spheres nor the ``obstacles``.

    Random sequential addition in batches, largest spheres first: candidates uniform in
    the region (whole spheres inside it when ``all_in``) are kept when they clear all
    placed spheres and every earlier candidate of their batch. Returns ``(index, centres)``:
    the centres of ``radii[index]``, for as many as fit within ``attempts`` batches (the
    caller compares the count with what it asked for).
    """
    radii = np.asarray(radii, float)
    bounds = region.bounds()
    pending = np.argsort(-radii, kind="stable")
    placed_index: list[np.ndarray] = []
    centres_placed, radii_placed = existing[0].reshape(-1, 3), existing[1].reshape(-1)
    n_existing = len(centres_placed)
    for _ in range(attempts):
        if len(pending) == 0:
            break
        slots = np.resize(np.arange(len(pending)), max(4 * len(pending), 64))
        r = radii[pending[slots]]
        centres = rng.uniform(bounds[:, 0], bounds[:, 1], (len(slots), 3))
        ok = region.contains(centres, r if all_in else 0.0)
        if obstacles is not None:
            ok[ok] &= obstacles.clear(centres[ok], r[ok])
        ok[ok] &= ~_clashes(centres[ok], r[ok], centres_placed, radii_placed)
        keep = np.flatnonzero(ok)
        keep = keep[_clear_of_earlier(centres[keep], r[keep])]
        _, first = np.unique(slots[keep], return_index=True)
        keep = keep[np.sort(first)]
        centres_placed = np.vstack([centres_placed, centres[keep]])
        radii_placed = np.append(radii_placed, r[keep])
        placed_index.append(pending[slots[keep]])
        pending = np.delete(pending, slots[keep])
    index = np.concatenate(placed_index) if placed_index else np.zeros(0, int)
    return index, centres_placed[n_existing:]


def _clashes(
    centres: np.ndarray, radii: np.ndarray, others: np.ndarray, others_radii: np.ndarray
) -> np.ndarray:
    """Which candidate spheres overlap any of the ``others``."""
    clash = np.zeros(len(centres), bool)
    if len(centres) == 0 or len(others) == 0:
        return clash
    reach = float(radii.max() + others_radii.max())
    pairs = cKDTree(centres).sparse_distance_matrix(cKDTree(others), reach, output_type="ndarray")
    bad = pairs["v"] < radii[pairs["i"]] + others_radii[pairs["j"]]
    clash[pairs["i"][bad]] = True
    return clash


def _clear_of_earlier(centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Indices of the candidates that overlap no earlier candidate of the same batch."""
    if len(centres) == 0:
        return np.zeros(0, int)
    pairs = cKDTree(centres).query_pairs(2 * float(radii.max()), output_type="ndarray")
    dropped = np.zeros(len(centres), bool)
    if len(pairs):
        gap = np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1)
        dropped[pairs[:, 1][gap < radii[pairs[:, 0]] + radii[pairs[:, 1]]]] = True
    return np.flatnonzero(~dropped)
