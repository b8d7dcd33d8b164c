"""The time-step check every engine makes before each ``run`` (after LIGGGHTS' ``check/timestep/gran``).

Two times bound the time step ``dt``:

- the **Rayleigh time** ``T_R = pi r sqrt(rho / G) / (0.1631 nu + 0.8766)``, ``G = E / (2 (1 + nu))``,
  the time a Rayleigh wave takes to cross a particle, for the smallest particle of each species;
- the **contact time** ``T_c`` of a particle-particle impact for every pair of species present
  and of a particle-wall impact for every species and wall material, at the characteristic
  velocity ``V``: the simulation's contact model's own ``contactTime`` (the Hertz time
  ``2.868 (m*^2 / (R* E*^2 V))^(1/5)`` for HertzMindlin and ThorntonNing, ``pi / omega`` of the
  damped spring for SpringDashpot). ``V`` is the largest ``characteristicVelocity`` of the
  materials (engines use one for all), else :data:`DEFAULT_SPEED`.

The smallest of each is compared with ``dt``:

==========================================  ==================================================
``dt`` above                                 outcome
==========================================  ==================================================
:data:`RAYLEIGH_FRACTION` (20 %) of T_R or   a :class:`~pygran_core.errors.TimeStepWarning`
:data:`CONTACT_FRACTION` (10 %) of T_c       (and a line in ``pygran.log``) naming both times
                                             and a safe ``dt``
T_c / :data:`MIN_STEPS_PER_CONTACT` (3)      :class:`~pygran_core.errors.ConfigError`, unless
                                             ``run(..., check_dt=False)``
==========================================  ==================================================

20 % of the Rayleigh time is the usual bound for dense beds (LIGGGHTS leaves both fractions
to the user; its documentation's example uses 10 %, EDEM recommends 20 % for coordination
numbers of 4 and more, 40 % below); 10 % of the contact time gives the ten steps per contact
of the rule of thumb. Below three steps a contact cannot be resolved at all: the explicit
(velocity Verlet) integration of a single linear contact is unstable above ``2 / omega``
(0.64 contact times), and a particle pressed by four such contacts above 0.32 contact times,
so particles gain energy in every collision and fly apart.

Unlike LIGGGHTS, which takes the largest particle speed now present and, for a pair of
like particles, the mass of one particle, the contact time here uses the pair's effective
mass and the characteristic velocity, so that it does not change from one run to the next.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from pygran_core.simulation.models import ContactModel

#: Above this fraction of the Rayleigh time, a warning.
RAYLEIGH_FRACTION = 0.2
#: Above this fraction of the contact time, a warning.
CONTACT_FRACTION = 0.1
#: Fewer steps than this per contact (``dt > T_c / 3``) is an error.
MIN_STEPS_PER_CONTACT = 3
#: Impact speed (m/s) when no material gives ``characteristicVelocity``.
DEFAULT_SPEED = 1.0


@dataclass(frozen=True)
class Body:
    """One side of a contact: particles of a species (``radius`` their smallest, ``density``)
    or a wall (``radius`` None), named for messages (``"species 1"``, ``"mesh 'hopper'"``)."""

    name: str
    material: Mapping[str, float]
    radius: float | None = None
    density: float | None = None

    @property
    def is_wall(self) -> bool:
        return self.radius is None

    def as_material(self, speed: float) -> dict[str, float]:
        """The material a contact model takes, at the characteristic velocity ``speed``."""
        extra: dict[str, float] = {}
        if self.radius is not None and self.density is not None:
            extra = {"radius": self.radius, "density": self.density}
        return {**self.material, **extra, "characteristicVelocity": speed}


def rayleigh_time(radius: float, density: float, youngs_modulus: float, poisson_ratio: float) -> float:
    """``pi r sqrt(rho / G) / (0.1631 nu + 0.8766)`` with ``G = E / (2 (1 + nu))``."""
    shear = youngs_modulus / (2 * (1 + poisson_ratio))
    return math.pi * radius * math.sqrt(density / shear) / (0.1631 * poisson_ratio + 0.8766)


def contact_time(model: type[ContactModel], particle: Body, other: Body, speed: float) -> float:
    """Duration of an impact of ``particle`` on ``other`` (a particle or a wall) at ``speed``."""
    impact = model(material=particle.as_material(speed), partner=other.as_material(speed))
    return impact.contactTime(speed)


def characteristic_speed(materials: Iterable[Mapping[str, float]]) -> float:
    """The largest ``characteristicVelocity`` of ``materials``, else :data:`DEFAULT_SPEED`."""
    return max(
        (m["characteristicVelocity"] for m in materials if "characteristicVelocity" in m),
        default=DEFAULT_SPEED,
    )


def _round_down(value: float) -> float:
    """``value`` rounded down to two significant digits."""
    exponent = math.floor(math.log10(value)) - 1
    return float(f"{math.floor(value / 10.0**exponent * (1 + 1e-12))}e{exponent}")


def _share(fraction: float) -> str:
    """``"8.0 times"`` or ``"35 % of"``: how much of a time ``fraction`` of it is."""
    if fraction < 1:
        return f"{100 * fraction:.2g} % of"
    return f"{fraction:.1f} times" if fraction < 10 else f"{fraction:.0f} times"


@dataclass(frozen=True)
class Limits:
    """The shortest Rayleigh and contact times of a simulation's contacts, and what gives them."""

    rayleigh: float
    rayleigh_of: str
    contact: float
    contact_of: str
    speed: float
    model: str

    @property
    def safe_dt(self) -> float:
        """The largest ``dt`` (two digits) within both warning fractions."""
        return _round_down(min(RAYLEIGH_FRACTION * self.rayleigh, CONTACT_FRACTION * self.contact))

    def assess(self, dt: float) -> Assessment:
        return Assessment(dt, self)


@dataclass(frozen=True)
class Assessment:
    """A time step against :class:`Limits`: :attr:`level` is ``"ok"``, ``"warn"`` or ``"error"``."""

    dt: float
    limits: Limits

    @property
    def rayleigh_fraction(self) -> float:
        return self.dt / self.limits.rayleigh

    @property
    def contact_fraction(self) -> float:
        return self.dt / self.limits.contact

    @property
    def level(self) -> str:
        if self.contact_fraction * MIN_STEPS_PER_CONTACT > 1:
            return "error"
        if self.rayleigh_fraction > RAYLEIGH_FRACTION or self.contact_fraction > CONTACT_FRACTION:
            return "warn"
        return "ok"

    def times(self) -> str:
        """``dt`` as a share of both times, and what gives them."""
        lim = self.limits
        return (
            f"dt = {self.dt:.3g} s is {_share(self.contact_fraction)} the contact time "
            f"{lim.contact:.3g} s ({lim.contact_of}, {lim.model} at {lim.speed:g} m/s) and "
            f"{_share(self.rayleigh_fraction)} the Rayleigh time {lim.rayleigh:.3g} s ({lim.rayleigh_of})"
        )

    def message(self) -> str:
        safe = f"use dt <= {self.limits.safe_dt:.2g} s"
        if self.level == "error":
            return (
                f"{self.times()}: a contact lasts fewer than {MIN_STEPS_PER_CONTACT} steps, so none "
                f"can be resolved and particles fly apart. {safe[0].upper()}{safe[1:]} "
                f"({100 * CONTACT_FRACTION:g} % of the contact time, at most {100 * RAYLEIGH_FRACTION:g} % "
                "of the Rayleigh time)."
            )
        return (
            f"{self.times()}: above {100 * RAYLEIGH_FRACTION:g} % of the Rayleigh time or "
            f"{100 * CONTACT_FRACTION:g} % of the contact time, contacts are poorly resolved; {safe}."
        )


def limits(model: type[ContactModel], pairs: Iterable[tuple[Body, Body]], speed: float) -> Limits | None:
    """The shortest times over ``pairs`` (a particle body, then a particle or wall body) at the
    characteristic velocity ``speed``; ``None`` without pairs (no contact can happen)."""
    pairs = list(pairs)
    if not pairs:
        return None
    particles = {
        b.name: (b.radius, b.density, b.material)
        for pair in pairs
        for b in pair
        if b.radius is not None and b.density is not None
    }
    rayleigh, rayleigh_of = min(
        (
            rayleigh_time(radius, density, material["youngsModulus"], material["poissonsRatio"]),
            f"{name}, radius {radius:.3g} m",
        )
        for name, (radius, density, material) in particles.items()
    )
    contact, contact_of = min((contact_time(model, a, b, speed), f"{a.name} on {b.name}") for a, b in pairs)
    return Limits(rayleigh, rayleigh_of, contact, contact_of, speed, model.__name__)
