"""Rotating drums: the dynamic angle of repose of the bed, from particle positions.

The bed of a drum partly filled and turning in the rolling regime fills a circular segment of
the drum's cross-section: its free surface is the segment's chord. A segment is mirror
symmetric about the drum radius across its chord, so the second moments of the bed's
cross-section have the chord and that radius as principal axes, and the chord is the major one
(a half-full drum has variances ``R^2 / 4`` along the chord and ``0.07 R^2`` across it; they
differ less as the drum fills: by a factor 2 when three quarters full). :func:`repose_angle`
takes the angle of that major axis with the horizontal: it needs no choice of a top layer, no
bins and no drum centre, and the few particles in flight above the bed or carried up by the
wall move it little; of a cascading bed's S-shaped surface it gives the mean slope. The
cross-section is the projection along the drum's axis: give the particles of the drum's
cylindrical part (its conical or flat ends hold a bed of another shape).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from pygran_core.errors import ConfigError

__all__ = ["ELONGATION", "repose_angle"]

#: The most the minor variance of the cross-section may be of its major one (a segment three
#: quarters of the drum's cross-section): above, the surface direction is not clear enough.
ELONGATION = 0.5


def _unit(vector: Sequence[float], name: str) -> np.ndarray:
    v = np.asarray(vector, dtype=float)
    norm = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if not np.isfinite(norm) or norm == 0:
        raise ConfigError(f"{name} must be a non-zero 3-vector, got {vector!r}")
    return v / norm


def repose_angle(
    positions: ArrayLike, axis: Sequence[float] = (0.0, 1.0, 0.0), up: Sequence[float] = (0.0, 0.0, 1.0)
) -> float:
    """The dynamic angle of repose (degrees) of the bed at ``positions`` ``(N, 3)`` in a drum
    turning about ``axis``, ``up`` against gravity: the angle with the horizontal of the major
    principal axis of the bed's cross-section (see the module). Positive when the surface rises
    on the side a drum turning right-handed about ``axis`` carries the bed up, the side
    ``-(axis x up)``; negative for a drum turning the other way.
    """
    points = np.asarray(positions, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 3:
        raise ConfigError(f"positions must be an (N, 3) array of N >= 3 points, got shape {points.shape}")
    along = _unit(axis, "axis")
    height = _unit(up, "up") - along * float(np.dot(_unit(up, "up"), along))
    if np.linalg.norm(height) < 1e-6:
        raise ConfigError(f"up {up!r} is along the drum's axis {axis!r}: give the direction against gravity")
    height /= np.linalg.norm(height)
    across = np.cross(along, height)  # horizontal in the cross-section
    section = points @ np.column_stack((across, height))
    variances, directions = np.linalg.eigh(np.cov(section, rowvar=False))
    if not variances[1] > 0 or variances[0] > ELONGATION * variances[1]:
        raise ConfigError(
            f"the bed's cross-section has no clear surface direction (variances {variances[0]:.3g} and "
            f"{variances[1]:.3g}): give the positions of a partly filled drum's bed, at most about "
            "three quarters full, in its cylindrical part"
        )
    du, dv = directions[:, 1]
    return float(np.degrees(np.arctan(-dv / du))) if du != 0 else 90.0
