"""Elastic-plastic adhesive contact after Thornton & Ning: :class:`ThorntonNing`."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pygran_core.errors import ConfigError
from pygran_core.simulation.models.base import Array, ContactModel

__all__ = ["ThorntonNing"]


class ThorntonNing(ContactModel):
    """Elastic-perfectly-plastic contact with JKR adhesion (Thornton & Ning 1998).

    Sources: C. Thornton, J. Appl. Mech. 64 (1997) 383 (elastic-plastic, no adhesion);
    C. Thornton & Z. Ning, Powder Technol. 99 (1998) 154 (with adhesion); K. L. Johnson,
    K. Kendall & A. D. Roberts, Proc. R. Soc. A 324 (1971) 301 (JKR).

    Adhesion convention: ``cohesionEnergyDensity`` is Gamma, the surface energy of *each*
    surface in J/m^2; the work of adhesion is ``2 Gamma`` and the JKR pull-off force
    ``F_c = 3 pi Gamma R*``. ``Gamma = 0`` recovers Thornton (1997).

    The state is the contact radius a, related to the overlap (positive repulsive forces,
    overlap positive in compression) by the JKR geometry with a curvature radius R:

    - ``delta = delta_p + a^2/R - 2 sqrt(pi Gamma a / E*)``,
    - ``F = 4 E* a^3 / (3 R) - 4 sqrt(pi Gamma E* a^3)``  (elastic part minus adhesion).

    Loading (``R = R*``, ``delta_p = 0``): elastic (JKR) until a reaches the yield radius
    ``a_y = pi p_y R* / (2 E*)`` (Hertzian pressure reaching p_y = ``yieldPress``), then
    perfectly plastic: the elastic part becomes ``F_1 = F_1y + pi p_y (a^2 - a_y^2)``
    (for Gamma = 0: ``F = F_y + pi p_y R* (delta - delta_y)``).

    Unloading and reloading below the largest contact radius a_m are elastic with the
    flattened curvature ``R_p = 4 E* a_m^3 / (3 F_1(a_m))`` (= R* if a_m <= a_y; Thornton's
    ``R_p = 4 E*/(3 F_m) ((2 F_m + F_y)/(2 pi p_y))^(3/2)`` for Gamma = 0) and the plastic
    offset ``delta_p = a_m^2 (1/R* - 1/R_p)``, which keep force and overlap continuous.
    Unloading reaches the pull-off force ``-3 pi Gamma R_p`` and the contact breaks when a
    falls to ``(pi Gamma R_p^2 / (4 E*))^(1/3)`` (the fixed-grips JKR instability), at
    the overlap returned by the separation; for Gamma = 0 at ``delta = delta_p``.
    A new contact forms at ``delta = 0`` (JKR snap-in). The model has no viscous damping:
    energy is lost by plasticity and adhesion hysteresis only, so
    ``coefficientRestitution`` is not used.

    Yield velocity (:attr:`yieldVel`): the impact speed at which the loading first reaches
    the yield radius, from ``m* V_y^2 / 2 = 8/15 E* R*^(1/2) delta_y^(5/2)`` with the
    adhesion-free ``delta_y = a_y^2 / R*``. For a sphere on a flat wall
    (``m* = 4/3 pi R*^3 rho``) this is Thornton's (1997, J. Appl. Mech. 64, 383)
    ``V_y = 1.56 sqrt(p_y^5 / (E*^4 rho))``: the exact constant is
    ``pi^2 / sqrt(40) = 1.5605``, which Thornton rounds to 1.56.

    ``limitForce=True`` (force never attractive) holds by construction without adhesion;
    with adhesion the attraction is the JKR force itself, so it is refused.

    Tangential: ``F_t = -k_t xi`` with ``k_t = 8 G* a`` and the Coulomb limit.
    :meth:`contactTime` is the Hertz value ``2.868 (m*^2 / (R* E*^2 v))^(1/5)``.
    ``max_overlap`` (the largest overlap of the contact so far) is the history of the
    normal and tangential forces; ``None`` means loading.
    """

    kernel = "thornton-ning"

    required = (*ContactModel.required, "yieldPress")
    yield_pressure: float  # required: never None here

    def __init__(
        self,
        material: Mapping[str, float],
        *,
        partner: Mapping[str, float] | None = None,
        limitForce: bool | None = None,
        rolling: str | None = None,
    ) -> None:
        super().__init__(material, partner=partner, limitForce=limitForce, rolling=rolling)
        if self.limit_force and self.cohesion > 0:
            raise ConfigError(
                "ThorntonNing: limitForce=True would remove the JKR adhesion (cohesionEnergyDensity "
                f"= {self.cohesion:g}), the model's only attraction; drop limitForce or the cohesion"
            )
        R, E = self.effective_radius, self.effective_modulus
        self.yield_radius = math.pi * self.yield_pressure * R / (2 * E)
        self.yield_overlap = float(self._overlap(self.yield_radius, R))
        self.yield_force = float(self._force(self.yield_radius, R))
        self.pull_off_force = 3 * math.pi * self.cohesion * R
        hertz_yield_overlap = self.yield_radius**2 / R
        self.yield_velocity = math.sqrt(
            16 / 15 * E * math.sqrt(R) * hertz_yield_overlap**2.5 / self.effective_mass
        )

    @property
    def yieldVel(self) -> float:
        """The yield velocity V_y (the original's property; see the class docstring)."""
        return self.yield_velocity

    def _model_coefficients(self) -> dict[str, float]:
        return {
            "yield_radius": self.yield_radius,
            "yield_overlap": self.yield_overlap,
            "yield_force": self.yield_force,
            "pull_off_force": self.pull_off_force,
            "yield_velocity": self.yield_velocity,
        }

    # --- JKR geometry ------------------------------------------------------------------
    def _overlap(self, a: ArrayLike, R: ArrayLike) -> Array:
        a = np.asarray(a, float)
        return a**2 / R - 2 * np.sqrt(np.pi * self.cohesion * a / self.effective_modulus)

    def _force(self, a: ArrayLike, R: ArrayLike) -> Array:
        a = np.asarray(a, float)
        E = self.effective_modulus
        return 4 * E * a**3 / (3 * np.asarray(R, float)) - 4 * np.sqrt(np.pi * self.cohesion * E * a**3)

    def _separation_radius(self, R: ArrayLike) -> Array:
        return np.cbrt(np.pi * self.cohesion * np.square(R) / (4 * self.effective_modulus))

    def _contact_radius(self, overlap: ArrayLike, R: ArrayLike) -> Array:
        """Stable-branch a of ``overlap = a^2/R - 2 sqrt(pi Gamma a / E*)``; NaN where none.

        With ``x = sqrt(a)``: ``x^4 - c x - R overlap = 0``, ``c = 2 R sqrt(pi Gamma / E*)``;
        Newton from above the largest root converges monotonically (the quartic is convex).
        """
        overlap, R = np.broadcast_arrays(np.asarray(overlap, float), np.asarray(R, float))
        valid = overlap >= self._overlap(self._separation_radius(R), R)
        q = np.where(valid, R * overlap, 0.0)
        if self.cohesion == 0:
            return np.where(valid, np.sqrt(np.maximum(q, 0.0)), np.nan)
        c = 2 * R * np.sqrt(np.pi * self.cohesion / self.effective_modulus)
        x_min = np.cbrt(c / 4)  # the quartic's minimum: the separation point
        x = np.maximum(np.cbrt(2 * c), np.sqrt(np.sqrt(2 * np.maximum(q, 0.0))))
        for _ in range(200):
            slope = 4 * x**3 - c
            step = np.divide(x**4 - c * x - q, slope, out=np.zeros_like(x), where=slope > 0)
            new = np.maximum(x - step, x_min)
            converged = np.all(np.abs(new - x) <= 1e-15 * x)
            x = new
            if converged:
                break
        return np.where(valid, x**2, np.nan)

    # --- history -----------------------------------------------------------------------
    def _elastic_part(self, a: Array) -> Array:
        """The elastic (Hertzian) load F_1 on the loading curve at contact radius a."""
        E, R, ay = self.effective_modulus, self.effective_radius, self.yield_radius
        plastic = 4 * E * ay**3 / (3 * R) + np.pi * self.yield_pressure * (a**2 - ay**2)
        return np.where(a > ay, plastic, 4 * E * a**3 / (3 * R))

    def _unloading(self, overlap: Array, max_overlap: ArrayLike | None) -> tuple[Array, Array]:
        """Unloading curvature radius R_p and plastic offset delta_p for this history."""
        R, E = self.effective_radius, self.effective_modulus
        history = overlap if max_overlap is None else np.maximum(overlap, np.asarray(max_overlap, float))
        a_m = np.nan_to_num(self._contact_radius(history, R))
        plastic = a_m > self.yield_radius
        F1 = self._elastic_part(a_m)
        R_p = np.where(plastic, 4 * E * a_m**3 / (3 * np.where(plastic, F1, 1.0)), R)
        return R_p, a_m**2 * (1 / R - 1 / R_p)

    def _state(self, overlap: Array, max_overlap: ArrayLike | None) -> tuple[Array, Array]:
        """Current contact radius a (NaN out of contact) and curvature radius R_p."""
        R_p, delta_p = self._unloading(overlap, max_overlap)
        a = self._contact_radius(overlap - delta_p, R_p)
        return (a if max_overlap is not None else np.where(overlap > 0, a, np.nan)), R_p

    def _in_contact(self, overlap: Array, max_overlap: ArrayLike | None) -> NDArray[np.bool_]:
        return np.isfinite(self._state(overlap, max_overlap)[0])

    def _separation_overlap(self, max_overlap: float) -> float:
        R_p, delta_p = self._unloading(np.asarray(max_overlap, float), None)
        return float(delta_p + self._overlap(self._separation_radius(R_p), R_p))

    # --- forces ------------------------------------------------------------------------
    def normal_force(
        self, overlap: ArrayLike, overlap_rate: ArrayLike, max_overlap: ArrayLike | None = None
    ) -> Array:
        """Normal force; ``overlap_rate`` does not enter (no viscous damping)."""
        overlap, _ = np.broadcast_arrays(np.asarray(overlap, float), np.asarray(overlap_rate, float))
        a, R_p = self._state(overlap, max_overlap)
        return np.where(np.isfinite(a), self._force(np.nan_to_num(a), R_p), 0.0)

    def _tangential_coefficients(self, overlap: Array, max_overlap: ArrayLike | None) -> tuple[Array, Array]:
        kt = 8 * self.effective_shear_modulus * np.nan_to_num(self._state(overlap, max_overlap)[0])
        return kt, np.zeros_like(kt)

    def contactTime(self, velocity: float | None = None) -> float:
        v = self._velocity(velocity)
        m, R, E = self.effective_mass, self.effective_radius, self.effective_modulus
        return 2.868 * (m**2 / (R * E**2 * v)) ** 0.2
