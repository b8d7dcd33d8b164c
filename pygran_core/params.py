"""Material dictionaries (S.I. units) and their validation.

``glass``, ``organic``, ``stearicAcid``, ``cohesionless``, ``cohesive`` and ``steel`` are the
original PyGran's materials, value for value (``stearicAcid`` is the manual's Listing 3.1);
``sodaLimeGlass``, ``bearingSteel``, ``microcrystallineCellulose``, ``cohesivePowder`` and
``quartzSand`` are realistic values from the literature (sources below). Each access
(``params.glass``, ``from pygran_core.params import glass``) gives a new plain ``dict`` that
a script may change in place (``glass['radius'] = 1e-3``) without changing the material
for anyone else; :data:`MATERIALS` holds the read-only originals.

==================================  ===============================================  ========
key                                 meaning                                          unit
==================================  ===============================================  ========
youngsModulus                       Young's modulus E                                Pa
poissonsRatio                       Poisson's ratio nu, in (-1, 0.5)                 --
coefficientFriction                 Coulomb sliding friction mu                      --
coefficientRollingFriction          rolling friction mu_r (LIGGGHTS ``cdt``)         --
cohesionEnergyDensity               Thornton-Ning JKR: surface energy Gamma of       J/m^2
                                    each surface (work of adhesion is 2 Gamma);
                                    SJKR (SpringDashpot, HertzMindlin): the          J/m^3
                                    LIGGGHTS ``cohesion sjkr`` energy density k
coefficientRestitution              normal restitution e, in (0, 1]                  --
coefficientRollingViscousDamping    rolling viscous damping (LIGGGHTS ``epsd``)      --
yieldPress                          limiting contact pressure p_y (Thornton-Ning)    Pa
characteristicVelocity              impact velocity (hooke stiffness, impacts)       m/s
density                             true (particle) density                          kg/m^3
==================================  ===============================================  ========
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Iterable, Mapping
from types import MappingProxyType

from pygran_core.errors import ConfigError, unknown_key

_positive = (lambda x: x > 0, "must be > 0")
_non_negative = (lambda x: x >= 0, "must be >= 0")

#: Valid range of every known key: (predicate, description of the range).
_RANGES: dict[str, tuple[Callable[[float], bool], str]] = {
    "youngsModulus": _positive,
    "poissonsRatio": (lambda x: -1 < x < 0.5, "must lie in (-1, 0.5)"),
    "coefficientFriction": _non_negative,
    "coefficientRollingFriction": _non_negative,
    "cohesionEnergyDensity": _non_negative,
    "coefficientRestitution": (lambda x: 0 < x <= 1, "must lie in (0, 1]"),
    "coefficientRollingViscousDamping": _non_negative,
    "yieldPress": _positive,
    "characteristicVelocity": _positive,
    "density": _positive,
    "radius": _positive,
    "mass": _positive,
}

#: The material keys of the manual (chapter 3); ``radius`` and ``mass`` are extra keys
#: accepted only where a caller allows them (the contact models do).
KEYS = frozenset(_RANGES) - {"radius", "mass"}


def validate(material: Mapping[str, object], *, allow: Iterable[str] = ()) -> dict[str, float]:
    """Check a material and return a new ``dict`` of its values as floats.

    ``allow`` names extra keys accepted besides :data:`KEYS` (``"radius"``, ``"mass"``).
    Raises :class:`~pygran_core.errors.ConfigError` for an unknown key (suggesting the
    closest known one), a value that is not a real number (bools included), or a value
    outside its physical range (naming key and value). Ints and floats are both accepted.
    """
    known = KEYS | (frozenset(allow) & _RANGES.keys())
    if not isinstance(material, Mapping):
        raise ConfigError(f"A material must be a mapping of keys to numbers, not {type(material).__name__}.")
    clean: dict[str, float] = {}
    for key, value in material.items():
        if key not in known:
            raise unknown_key("material key", str(key), known)
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ConfigError(f"Material key {key!r} must be a real number, got {value!r}.")
        number = float(value)
        check, expected = _RANGES[key]
        if not math.isfinite(number) or not check(number):
            raise ConfigError(f"Material key {key!r} {expected}, got {value!r}.")
        clean[key] = number
    return clean


def _material(**values: float) -> Mapping[str, float]:
    return MappingProxyType(validate(values))


#: The columns of the material tables below (see the module docstring); ``None``: no such key.
_COLUMNS = (
    "youngsModulus",
    "poissonsRatio",
    "coefficientFriction",
    "coefficientRollingFriction",
    "cohesionEnergyDensity",
    "coefficientRestitution",
    "coefficientRollingViscousDamping",
    "yieldPress",
    "characteristicVelocity",
    "density",
)


def _table(rows: Mapping[str, tuple[float | None, ...]]) -> dict[str, Mapping[str, float]]:
    """Materials from rows of :data:`_COLUMNS` values."""
    return {
        name: _material(**{key: value for key, value in zip(_COLUMNS, row, strict=True) if value is not None})
        for name, row in rows.items()
    }


#: The original PyGran's materials (PyGran 1.x ``params``), value for value: scripts written
#: for it depend on them (``organic``'s soft modulus sets their time step).
# fmt: off
_ORIGINAL = _table({
    #                                   E     nu     mu   mu_r  Gamma     e  eta_r     p_y   v_c      rho
    "glass":                     (   63e9,  0.24,   0.5,   0.0,  0.05,  0.9,   0.1,   62e9,  0.1,  2500.0),
    # the manual's Listing 3.1
    "stearicAcid":               ( 4.15e7,  0.25,   0.5,   0.0, 0.033,  0.9,   0.1,  2.2e6,  0.1, 997.164),
    "organic":                   (    1e7,  0.25,   0.5,   0.0,   0.0,  0.9,   0.1,  2.2e6,  0.1,  1000.0),
    "cohesionless":              (    1e7,  0.25,   0.5,   0.0,  None,  0.9,   0.1,  2.2e6,  0.1,  1000.0),
    "cohesive":                  (    1e7,  0.25,   0.5,   0.0,   2e5,  0.9,   0.1,  2.2e6,  0.1,  1000.0),
    "steel":                     (   2e11,   0.3,   0.5,   0.0,   0.0,  0.9,   0.1,   2e10,  0.1,  8050.0),
})
# fmt: on

# Representative literature values. Sources:
# - sodaLimeGlass: E, nu, density from standard soda-lime glass data (E ~ 63-72 GPa,
#   nu ~ 0.22-0.24); restitution 0.97 and friction 0.092 measured for glass spheres by
#   Foerster, Louge, Chang & Allia, Phys. Fluids 6 (1994) 1108; yieldPress ~ Vickers hardness.
# - bearingSteel (AISI 52100 balls): E 210 GPa, nu 0.3, density 7810 kg/m^3 (ASM Handbook
#   vol. 1); restitution ~0.9 at ~1 m/s (Goldsmith, Impact, 1960); yieldPress ~ hardness.
# - microcrystallineCellulose (granules): E ~ 8 GPa and nu ~ 0.3 (Roberts, Rowe & York,
#   Int. J. Pharm. 105 (1994) 177), true density 1560 kg/m^3, Heckel mean yield pressure
#   ~ 50-90 MPa.
# - cohesivePowder: the manual's cohesive organic powder (Listing 3.4), surface energy
#   0.04 J/m^2, typical of organic crystals such as lactose (~0.04-0.05 J/m^2).
# - quartzSand (dry): bulk modulus 37 GPa and shear modulus 44 GPa of quartz (Mavko, Mukerji
#   & Dvorkin, The Rock Physics Handbook) give E = 94.5 GPa, nu = 0.074; density 2650 kg/m^3;
#   interparticle friction ~0.5; yieldPress ~ hardness of quartz.
# Rolling friction coefficients are typical calibrated values for the cdt model (1e-3 to
# 1e-2; Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269).
# fmt: off
_REALISTIC = _table({
    #                                   E     nu     mu   mu_r  Gamma     e  eta_r     p_y   v_c      rho
    "sodaLimeGlass":             ( 6.3e10,  0.23, 0.092, 0.002,   0.0, 0.97,   0.0,  5.5e9,  1.0,  2500.0),
    "bearingSteel":              ( 2.1e11,   0.3,   0.2, 0.002,   0.0,  0.9,   0.0,  7.0e9,  1.0,  7810.0),
    "microcrystallineCellulose": (  8.0e9,   0.3,   0.5, 0.005,   0.0, 0.75,   0.0,  7.0e7,  0.1,  1560.0),
    "cohesivePowder":            (  6.0e9,  0.25,   0.5,  0.01,  0.04,  0.5,   0.0,  4.0e7, 0.04,  1500.0),
    "quartzSand":                (9.45e10, 0.074,   0.5, 0.005,   0.0,  0.8,   0.0, 1.1e10,  1.0,  2650.0),
})
# fmt: on

#: Every material by name, read-only: the reference the module attributes are copied from.
MATERIALS: Mapping[str, Mapping[str, float]] = MappingProxyType(_ORIGINAL | _REALISTIC)

__all__ = ["KEYS", "MATERIALS", "validate", *MATERIALS]


def __getattr__(name: str) -> dict[str, float]:
    """``params.glass`` (or ``from params import glass``): a new ``dict`` copy each time, so a
    script may change its copy in place without changing what another import gets."""
    if name in MATERIALS:
        return dict(MATERIALS[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *MATERIALS])
