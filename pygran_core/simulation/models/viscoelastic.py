"""Visco-elastic models with simplified-JKR cohesion: :class:`SpringDashpot`, :class:`HertzMindlin`.

Both share the normal law ``F_n = k_n delta + gamma_n ddelta/dt - k A`` for ``delta > 0``
(zero otherwise; positive repulsive, overlap rate positive while approaching), where:

- cohesion is LIGGGHTS' ``cohesion sjkr`` (simplified JKR), on when
  ``cohesionEnergyDensity`` k > 0: ``A = pi delta (2 R* - delta)`` is the area of the lens
  cut by the overlap (LIGGGHTS' sphere-wall area, equal to its sphere-sphere area to first
  order). k is LIGGGHTS' cohesion energy density in J/m^3, not the JKR surface energy in
  J/m^2 that :class:`~pygran_core.simulation.models.ThorntonNing` reads from the same key;
- the visco-elastic part is not clamped by default (LIGGGHTS ``limitForce off``): near the
  end of a contact the damping makes it attractive and the contact lasts until the overlap
  returns to zero, which is what makes the realised restitution equal the requested one.
  With ``limitForce=True`` it is clamped at ``>= 0`` (before cohesion is added), the
  particle leaves with the speed it had when that force vanished, and the realised
  restitution is higher than requested.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from pygran_core.errors import ConfigError
from pygran_core.simulation.models import mixing
from pygran_core.simulation.models.base import Array, ContactModel, Impact

__all__ = ["HertzMindlin", "SpringDashpot"]


class _Viscoelastic(ContactModel):
    """The normal law, SJKR cohesion and clamping shared by the visco-elastic models (see module)."""

    required = (*ContactModel.required, "coefficientRestitution")
    restitution_coefficient: float  # required: never None here

    def __init__(
        self,
        material: Mapping[str, float],
        *,
        partner: Mapping[str, float] | None = None,
        limitForce: bool | None = None,
        rolling: str | None = None,
    ) -> None:
        super().__init__(material, partner=partner, limitForce=limitForce, rolling=rolling)
        #: LIGGGHTS' damping parameter: ``beta = ln e / sqrt(ln^2 e + pi^2)`` (<= 0), minus
        #: :func:`~pygran_core.simulation.models.mixing.damping_ratio`.
        self.beta = -float(mixing.damping_ratio(self.restitution_coefficient))

    @abc.abstractmethod
    def _normal_coefficients(self, overlap: Array) -> tuple[Array, Array]:
        """Normal ``k_n`` and ``gamma_n`` at the given (positive) overlap."""

    def normal_force(
        self, overlap: ArrayLike, overlap_rate: ArrayLike, max_overlap: ArrayLike | None = None
    ) -> Array:
        """Normal force; ``max_overlap`` is unused (no normal history)."""
        overlap = np.asarray(overlap, float)
        contact = overlap > 0
        delta = np.where(contact, overlap, 0.0)
        kn, gamman = self._normal_coefficients(delta)
        force = kn * delta + gamman * np.asarray(overlap_rate, float)
        if self.limit_force:
            force = np.maximum(force, 0.0)
        force = force - self.cohesion * np.pi * delta * (2 * self.effective_radius - delta)
        return np.where(contact, force, 0.0)


class SpringDashpot(_Viscoelastic):
    """Linear spring-dashpot (LIGGGHTS ``pair_style gran model hooke``).

    ``F_n = k_n delta + gamma_n ddelta/dt`` (positive repulsive), with (LIGGGHTS docs,
    gran model hooke; Cundall & Strack, Geotechnique 29 (1979) 47):

    - ``k_n = 16/15 sqrt(R*) E* (15 m* V^2 / (16 sqrt(R*) E*))^(1/5)``, V the
      ``characteristicVelocity``: the undamped spring reaches the Hertzian maximum overlap
      of an impact at V;
    - ``gamma_n = sqrt(4 m* k_n / (1 + (pi / ln e)^2))``, giving restitution e exactly;
    - ``k_t = k_n``, ``gamma_t = gamma_n`` (tangential history, Coulomb limit ``mu |F_n|``).

    Contact time ``pi / sqrt(k_n/m* - (gamma_n / 2m*)^2)``, independent of velocity.

    Cohesion (``cohesionEnergyDensity`` k > 0, J/m^3): SJKR, ``F_n -= k pi delta (2 R* - delta)``.
    Not clamped unless ``limitForce=True``; see the module docstring for both conventions.
    """

    kernel = "spring-dashpot"

    required = (*_Viscoelastic.required, "characteristicVelocity")

    def __init__(
        self,
        material: Mapping[str, float],
        *,
        partner: Mapping[str, float] | None = None,
        limitForce: bool | None = None,
        rolling: str | None = None,
    ) -> None:
        super().__init__(material, partner=partner, limitForce=limitForce, rolling=rolling)
        R, E, m = self.effective_radius, self.effective_modulus, self.effective_mass
        V = self.material["characteristicVelocity"]
        self.kn = 16 / 15 * math.sqrt(R) * E * (15 * m * V**2 / (16 * math.sqrt(R) * E)) ** 0.2
        # sqrt(4 m k / (1 + (pi/ln e)^2)) written so that e = 1 gives 0
        self.gamman = -self.beta * math.sqrt(4 * m * self.kn)
        self.kt, self.gammat = self.kn, self.gamman

    def _model_coefficients(self) -> dict[str, float]:
        return {"kn": self.kn, "gamman": self.gamman, "kt": self.kt, "gammat": self.gammat}

    def _normal_coefficients(self, overlap: Array) -> tuple[Array, Array]:
        return np.full_like(overlap, self.kn), np.full_like(overlap, self.gamman)

    def _tangential_coefficients(self, overlap: Array, max_overlap: ArrayLike | None) -> tuple[Array, Array]:
        return np.full_like(overlap, self.kt), np.full_like(overlap, self.gammat)

    def contactTime(self, velocity: float | None = None) -> float:
        m = self.effective_mass
        return math.pi / math.sqrt(self.kn / m - (self.gamman / (2 * m)) ** 2)

    def displacementAnalytical(self, dt: float | None = None, *, velocity: float | None = None) -> Impact:
        """The impact of :meth:`displacement` from the closed form of the damped oscillator.

        With ``alpha = gamma_n / 2m*``, ``omega = sqrt(k_n/m* - alpha^2)`` and ``v`` the
        impact velocity (default ``characteristicVelocity``), the overlap is
        ``delta = v/omega exp(-alpha t) sin(omega t)`` until it returns to 0 at
        ``t = pi/omega``, where the overlap rate is ``-e v``. With ``limitForce=True`` the
        force ``k_n delta + gamma_n ddelta/dt`` vanishes first, at
        ``omega t* = atan2(-gamma_n omega, k_n - gamma_n alpha) + pi``; the particle then
        moves at constant speed until the overlap is 0, as in :meth:`displacement`.
        Sampled every ``dt`` (default 1 % of the contact time, as the original) and at
        the end. Unpacks as ``time, soln, force``. SJKR cohesion has no closed form: a
        cohesive material is refused.
        """
        if self.cohesion > 0:
            raise ConfigError(
                "displacementAnalytical: the closed form has no cohesion; use displacement() for "
                f"cohesionEnergyDensity = {self.cohesion:g}"
            )
        v = self._velocity(velocity)
        m, k, gamma = self.effective_mass, self.kn, self.gamman
        alpha = gamma / (2 * m)
        omega = math.sqrt(k / m - alpha**2)
        t_force = (math.atan2(-gamma * omega, k - gamma * alpha) + math.pi) / omega
        t_force = min(t_force, math.pi / omega) if self.limit_force else math.pi / omega

        def state(t: Array) -> tuple[Array, Array]:
            decay = np.exp(-alpha * t)
            return (
                v / omega * decay * np.sin(omega * t),
                v * decay * (np.cos(omega * t) - alpha / omega * np.sin(omega * t)),
            )

        d_end, v_end = (float(x) for x in state(np.asarray(t_force, float)))
        t_end = t_force + (d_end / -v_end if d_end > 0 else 0.0)
        step = 0.01 * self.contactTime() if dt is None else float(dt)
        if not step > 0:
            raise ConfigError(f"displacementAnalytical: dt must be > 0, got {dt!r}")
        time = np.append(np.arange(0.0, t_end, step), t_end)
        delta, rate = state(np.minimum(time, t_force))
        free = time > t_force
        delta = np.where(free, d_end + v_end * (time - t_force), delta)
        rate = np.where(free, v_end, rate)
        delta[-1] = 0.0
        soln = np.column_stack((delta, rate))
        return Impact(time, soln, self.normal_force(delta, rate), captured=False)


class HertzMindlin(_Viscoelastic):
    """Hertz normal, Mindlin tangential, with viscous damping (LIGGGHTS ``gran model hertz``).

    With ``a = sqrt(R* delta)`` (LIGGGHTS docs, gran model hertz; Hertz 1882; Mindlin 1949;
    damping after Tsuji et al., Powder Technol. 71 (1992) 239):

    - ``F_n = k_n delta + gamma_n ddelta/dt`` (positive repulsive), ``k_n = 4/3 E* a``;
    - ``gamma_n = -2 sqrt(5/6) beta sqrt(S_n m*)``, ``S_n = 2 E* a``,
      ``beta = ln e / sqrt(ln^2 e + pi^2)``; this damping (proportional to ``delta^(1/4)``)
      gives a restitution independent of the impact velocity and equal to e when the
      force is not clamped;
    - ``F_t = -k_t xi - gamma_t v_t``, ``k_t = 8 G* a``,
      ``gamma_t = -2 sqrt(5/6) beta sqrt(k_t m*)``, Coulomb limit ``mu |F_n|``.

    :meth:`contactTime` is the undamped Hertz value ``2.868 (m*^2 / (R* E*^2 v))^(1/5)``;
    damping lengthens the contact slightly.

    Cohesion (``cohesionEnergyDensity`` k > 0, J/m^3): SJKR, ``F_n -= k pi delta (2 R* - delta)``.
    Not clamped unless ``limitForce=True``; see the module docstring for both conventions.
    """

    kernel = "hertz-mindlin"

    def _model_coefficients(self) -> dict[str, float]:
        return {"beta": self.beta}

    def _damping(self, stiffness: Array) -> Array:
        return -2 * math.sqrt(5 / 6) * self.beta * np.sqrt(stiffness * self.effective_mass)

    def _normal_coefficients(self, overlap: Array) -> tuple[Array, Array]:
        a = np.sqrt(self.effective_radius * overlap)
        return 4 / 3 * self.effective_modulus * a, self._damping(2 * self.effective_modulus * a)

    def _tangential_coefficients(self, overlap: Array, max_overlap: ArrayLike | None) -> tuple[Array, Array]:
        kt = 8 * self.effective_shear_modulus * np.sqrt(self.effective_radius * np.maximum(overlap, 0.0))
        return kt, self._damping(kt)

    def contactTime(self, velocity: float | None = None) -> float:
        v = self._velocity(velocity)
        m, R, E = self.effective_mass, self.effective_radius, self.effective_modulus
        return 2.868 * (m**2 / (R * E**2 * v)) ** 0.2
