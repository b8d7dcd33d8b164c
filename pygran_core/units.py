"""Unit systems ``si``, ``cgs``, ``micro`` and ``nano`` (as in LIGGGHTS), as pure functions.

Each system fixes its units of length, mass and time as powers of ten of the SI units:

========  ==========  ===========  ===========
system    length      mass         time
========  ==========  ===========  ===========
si        m           kg           s
cgs       cm          g            s
micro     micrometre  picogram     microsecond
nano      nanometre   attogram     nanosecond
========  ==========  ===========  ===========

A quantity's dimension is a named combination of length (L), mass (M) and time (T).
Because every factor is a power of ten, conversions multiply or divide by an exactly
representable integer power of ten, which keeps the rounding error to one operation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from pygran_core.errors import unknown_key

#: system -> decimal exponents of its (length, mass, time) units in SI
SYSTEMS: dict[str, tuple[int, int, int]] = {
    "si": (0, 0, 0),
    "cgs": (-2, -3, 0),
    "micro": (-6, -15, -6),
    "nano": (-9, -21, -9),
}

#: dimension -> exponents of (length, mass, time)
DIMENSIONS: dict[str, tuple[int, int, int]] = {
    "dimensionless": (0, 0, 0),
    "length": (1, 0, 0),
    "area": (2, 0, 0),
    "volume": (3, 0, 0),
    "mass": (0, 1, 0),
    "time": (0, 0, 1),
    "frequency": (0, 0, -1),
    "angular_velocity": (0, 0, -1),
    "velocity": (1, 0, -1),
    "acceleration": (1, 0, -2),
    "force": (1, 1, -2),
    "torque": (2, 1, -2),
    "energy": (2, 1, -2),
    "pressure": (-1, 1, -2),
    "density": (-3, 1, 0),
    "surface_energy": (0, 1, -2),
    "moment_of_inertia": (2, 1, 0),
    "mass_flow_rate": (0, 1, -1),
}

ArrayT = TypeVar("ArrayT", float, np.ndarray)


def _system(name: str) -> tuple[int, int, int]:
    if not isinstance(name, str) or name not in SYSTEMS:
        raise unknown_key("unit system", str(name), SYSTEMS)
    return SYSTEMS[name]


def exponent(dimension: str, source: str, target: str) -> int:
    """The power of ten ``k`` with ``value_in_target = value_in_source * 10**k``."""
    try:
        dims = DIMENSIONS[dimension]
    except KeyError:
        raise unknown_key("dimension", dimension, DIMENSIONS) from None
    src, dst = _system(source), _system(target)
    return sum(d * (s - t) for d, s, t in zip(dims, src, dst))


def factor(dimension: str, source: str, target: str) -> float:
    """The multiplicative factor from ``source`` to ``target`` units for ``dimension``."""
    return 10.0 ** exponent(dimension, source, target)


def convert(value: ArrayT, dimension: str, source: str, target: str) -> ArrayT:
    """``value`` (a number or array) of ``dimension`` expressed in ``source`` units, in ``target``.

    Multiplies by ``10**k`` for ``k >= 0`` and divides by ``10**-k`` otherwise, so each
    conversion is a single correctly rounded operation.
    """
    k = exponent(dimension, source, target)
    if k == 0:
        return value
    return value * 10.0**k if k > 0 else value / 10.0 ** (-k)


class UnitName(str):
    """The name of a unit system (a ``str``) that converts its owner when called.

    ``System.units`` and ``SubSystem.units`` return one: compare or print it as a string
    (``system.units == "si"``), or call it as the original PyGran's method,
    ``system.units("micro")`` to convert and ``system.units()`` for the name.
    """

    _convert: Callable[[str], Any]

    def __new__(cls, name: str, convert: Callable[[str], Any]) -> UnitName:
        new = super().__new__(cls, name)
        new._convert = convert
        return new

    def __call__(self, units: str | None = None) -> str:
        """Convert the owner to ``units`` (si, cgs, micro, nano) and return it; no argument: the name."""
        if units is None:
            return str(self)
        _system(units)
        self._convert(units)
        return units

    def __reduce__(self) -> tuple[type[str], tuple[str]]:
        return str, (str(self),)  # pickles and copies as the plain name
