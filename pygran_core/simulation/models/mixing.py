"""Pair (mixing) rules for a contact between two bodies 1 and 2, and the damping ratio of a
restitution coefficient: the one place they live.

Every function takes scalars or numpy arrays and broadcasts, so a per-type-pair table is
built with :func:`pair_table`, e.g. ``pair_table(effective_modulus, E, nu)[i, j]`` is E*
between types i and j. The material table (:mod:`pygran_core.simulation.materials`) mixes the
pairs that ``DEM(pairs=...)`` does not give with these rules.
A wall is a body of infinite radius and mass: pass ``numpy.inf`` (the default for the
second body of :func:`effective_radius` and :func:`effective_mass`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "damping_ratio",
    "effective_mass",
    "effective_modulus",
    "effective_radius",
    "effective_shear_modulus",
    "pair_cohesion",
    "pair_friction",
    "pair_restitution",
    "pair_table",
    "pair_yield_pressure",
    "shear_modulus",
]

Real = float | NDArray[np.floating]


def effective_modulus(E1: ArrayLike, nu1: ArrayLike, E2: ArrayLike, nu2: ArrayLike) -> Real:
    """Hertz contact modulus: ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2``."""
    return 1.0 / ((1 - np.square(nu1)) / np.asarray(E1, float) + (1 - np.square(nu2)) / np.asarray(E2, float))


def shear_modulus(E: ArrayLike, nu: ArrayLike) -> Real:
    """Isotropic shear modulus ``G = E / (2 (1 + nu))``."""
    return np.asarray(E, float) / (2 * (1 + np.asarray(nu, float)))


def effective_shear_modulus(E1: ArrayLike, nu1: ArrayLike, E2: ArrayLike, nu2: ArrayLike) -> Real:
    """Mindlin contact shear modulus: ``1/G* = (2 - nu1)/G1 + (2 - nu2)/G2`` (as LIGGGHTS)."""
    return 1.0 / (
        (2 - np.asarray(nu1, float)) / shear_modulus(E1, nu1)
        + (2 - np.asarray(nu2, float)) / shear_modulus(E2, nu2)
    )


def effective_radius(R1: ArrayLike, R2: ArrayLike = np.inf) -> Real:
    """``R* = R1 R2 / (R1 + R2)``; ``R2 = inf`` (a flat wall) gives ``R1``."""
    return 1.0 / (1.0 / np.asarray(R1, float) + 1.0 / np.asarray(R2, float))


def effective_mass(m1: ArrayLike, m2: ArrayLike = np.inf) -> Real:
    """``m* = m1 m2 / (m1 + m2)``; ``m2 = inf`` (a fixed wall) gives ``m1``."""
    return 1.0 / (1.0 / np.asarray(m1, float) + 1.0 / np.asarray(m2, float))


def pair_friction(mu1: ArrayLike, mu2: ArrayLike) -> Real:
    """Sliding (or rolling) friction of a pair: the smaller one, as Yade's ``FrictMat``."""
    return np.minimum(np.asarray(mu1, float), mu2)


def pair_restitution(e1: ArrayLike, e2: ArrayLike) -> Real:
    """Restitution of a pair: the geometric mean ``sqrt(e1 e2)`` (exact for like materials)."""
    return np.sqrt(np.multiply(e1, e2, dtype=float))


def damping_ratio(e: ArrayLike) -> Real:
    """Damping ratio ``zeta = -ln e / sqrt(ln^2 e + pi^2)`` of the linear dashpot whose impact has
    restitution ``e`` (``0 < e <= 1``): 0 for ``e = 1``, towards 1 as ``e -> 0``. LIGGGHTS' damping
    parameter ``beta`` of its visco-elastic models is ``-zeta``; YADE's ``betan`` is ``zeta``."""
    log_e = np.log(np.asarray(e, float))
    return -log_e / np.hypot(log_e, np.pi)


def pair_cohesion(g1: ArrayLike, g2: ArrayLike) -> Real:
    """Surface (cohesion) energy of a pair: Berthelot's geometric mean ``sqrt(g1 g2)``."""
    return np.sqrt(np.multiply(g1, g2, dtype=float))


def pair_yield_pressure(p1: ArrayLike, p2: ArrayLike) -> Real:
    """Limiting contact pressure of a pair: the softer body yields first, ``min(p1, p2)``."""
    return np.minimum(np.asarray(p1, float), p2)


def pair_table(rule: Callable[..., Real], *per_type: ArrayLike) -> NDArray[np.floating]:
    """Table ``T[i, j] = rule(*props_i, *props_j)`` over types, one array per property.

    ``pair_table(effective_modulus, E, nu)`` calls ``effective_modulus(E_i, nu_i, E_j, nu_j)``.
    """
    columns = [np.asarray(p, float).reshape(-1) for p in per_type]
    return np.asarray(rule(*(c[:, None] for c in columns), *(c[None, :] for c in columns)), float)
