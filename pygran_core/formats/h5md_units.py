"""H5MD ``unit`` strings (the H5MD units module) read as a factor to SI and a dimension, so that
a file in nm and ps (MDAnalysis, GROMACS) or Angstrom reads in PyGran's SI units, and a unit
that is not what its element needs is refused rather than believed.

A unit string is a sequence of factors separated by spaces: at most one number first (``60``,
``10+3`` for 10^3), then unit symbols, each with an SI prefix and an optional power
(``nm+3``, ``um+2 s-1``, ``kJ mol-1 nm-1``). Dimensions are exponents of (length, mass,
time); ``mol`` counts particles (1 mol is N_A of them), as molecular codes write energies.
"""

from __future__ import annotations

import math
import re

Dimension = tuple[int, int, int]

#: symbol -> (SI factor as mantissa and decimal exponent, dimension); powers of ten are kept
#: apart so that nm ps-1 is exactly 1e3 m s-1.
SYMBOLS: dict[str, tuple[float, int, Dimension]] = {
    "m": (1.0, 0, (1, 0, 0)),
    "Ang": (1.0, -10, (1, 0, 0)),
    "Angstrom": (1.0, -10, (1, 0, 0)),  # MDAnalysis' spelling
    "angstrom": (1.0, -10, (1, 0, 0)),
    "L": (1.0, -3, (3, 0, 0)),
    "s": (1.0, 0, (0, 0, 1)),
    "Hz": (1.0, 0, (0, 0, -1)),
    "g": (1.0, -3, (0, 1, 0)),
    "u": (1.66053906660, -27, (0, 1, 0)),
    "N": (1.0, 0, (1, 1, -2)),
    "dyn": (1.0, -5, (1, 1, -2)),
    "Pa": (1.0, 0, (-1, 1, -2)),
    "bar": (1.0, 5, (-1, 1, -2)),
    "atm": (101325.0, 0, (-1, 1, -2)),
    "J": (1.0, 0, (2, 1, -2)),
    "erg": (1.0, -7, (2, 1, -2)),
    "cal": (4.1868, 0, (2, 1, -2)),
    "eV": (1.602176634, -19, (2, 1, -2)),
    "W": (1.0, 0, (2, 1, -3)),
    "rad": (1.0, 0, (0, 0, 0)),
    "degree": (math.pi / 180, 0, (0, 0, 0)),
    "mol": (6.02214076, 23, (0, 0, 0)),  # particles: kJ mol-1 is 1e3 / N_A J per particle
}
PREFIXES = {
    "E": 18, "P": 15, "T": 12, "G": 9, "M": 6, "k": 3, "h": 2, "da": 1,
    "d": -1, "c": -2, "m": -3, "u": -6, "n": -9, "p": -12, "f": -15, "a": -18,
}  # fmt: skip
#: The dimension each standard element must have.
DIMENSIONS: dict[str, Dimension] = {
    **dict.fromkeys(("position", "radius", "diameter", "edges", "pygran_bounds", "pygran_tilt"), (1, 0, 0)),
    **dict.fromkeys(("point", "branch"), (1, 0, 0)),
    "velocity": (1, 0, -1),
    "force": (1, 1, -2),
    "torque": (2, 1, -2),
    "angular_velocity": (0, 0, -1),
    "mass": (0, 1, 0),
    "density": (-3, 1, 0),
    "time": (0, 0, 1),
}
_NUMBER = re.compile(r"^(\d+(?:\.\d*)?)([+-]\d+)?$")
_SYMBOL = re.compile(r"^([A-Za-z]+)([+-]?\d+)?$")


def _symbol(name: str) -> tuple[float, int, Dimension]:
    if name in SYMBOLS:
        return SYMBOLS[name]
    for prefix, exponent in PREFIXES.items():
        if name.startswith(prefix) and name[len(prefix) :] in SYMBOLS:
            mantissa, own, dimension = SYMBOLS[name[len(prefix) :]]
            return mantissa, own + exponent, dimension
    raise ValueError(f"unknown unit symbol {name!r}")


def parse(text: str) -> tuple[float, Dimension]:
    """The SI factor and dimension of the unit string ``text``; ValueError if it is not one."""
    mantissa, exponent, dimension = 1.0, 0, (0, 0, 0)
    for position, token in enumerate(text.split()):
        number = _NUMBER.match(token)
        if number and position == 0:
            power = int(number[2] or 1)
            if number[1] == "10":
                exponent += power if number[2] else 1
            else:
                mantissa *= float(number[1]) ** power
            continue
        symbol = _SYMBOL.match(token)
        if symbol is None:
            raise ValueError(f"{token!r} is not a unit factor")
        power = int(symbol[2]) if symbol[2] else 1
        if power == 0:
            raise ValueError(f"{token!r}: a power of zero")
        scale, own, units = _symbol(symbol[1])
        mantissa *= scale**power
        exponent += own * power
        dimension = (
            dimension[0] + power * units[0],
            dimension[1] + power * units[1],
            dimension[2] + power * units[2],
        )
    return mantissa * 10.0**exponent, dimension


def to_si(element: str, text: str) -> float:
    """The factor that turns values of ``element`` in unit ``text`` into SI; ValueError naming
    the problem if the unit is unknown or not what the element needs."""
    factor, dimension = parse(text)
    expected = DIMENSIONS.get(element)
    if expected is not None and dimension != expected:
        raise ValueError(
            f"unit {text!r} of {element} has dimension (length, mass, time) {dimension}, not {expected}"
        )
    return factor
