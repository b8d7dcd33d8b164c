"""Small plots of analysis results, with units on the axes: a quantity over time
(:func:`time_series`), a radial distribution function (:func:`rdf`) and the distribution of
coordination numbers (:func:`coordination`).

Each draws on ``ax`` (a matplotlib Axes; a new figure when omitted) and returns the Axes, so a
script saves it with ``ax.figure.savefig('rdf.png')``. matplotlib is needed only here
(``pip install matplotlib``, or the ``plot`` extra).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pygran_core import units as _units
from pygran_core.errors import ConfigError, UnsupportedFeature

__all__ = ["coordination", "rdf", "time_series"]

#: The symbols of each unit system's length and time units.
SYMBOLS = {"si": ("m", "s"), "cgs": ("cm", "s"), "micro": ("µm", "µs"), "nano": ("nm", "ns")}


def _axes(ax: Any) -> Any:
    if ax is not None:
        return ax
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise UnsupportedFeature("analysis.plot draws with matplotlib: pip install matplotlib") from None
    return Figure(figsize=(5, 3.5), layout="constrained").add_subplot()


def _symbols(units: str) -> tuple[str, str]:
    _units.exponent("length", units, "si")  # an unknown unit system is a ConfigError
    return SYMBOLS[units]


def time_series(series: Any, label: str = "value", unit: str = "", units: str = "si", ax: Any = None) -> Any:
    """Plot a :class:`~pygran_core.analysis.dynamics.TimeSeries` (or any ``(time, value)`` pair)
    against time: x "time (s)", y ``label`` with ``unit`` in brackets (none: dimensionless).
    A value with several columns per frame draws one line per column."""
    time, value = series
    values = np.asarray(value, dtype=float)
    if values.ndim not in (1, 2) or len(values) != len(time):
        raise ConfigError(
            f"time_series: one number or one vector per frame is needed, got shape {values.shape}"
        )
    ax = _axes(ax)
    ax.plot(np.asarray(time, dtype=float), values, marker="o", markersize=3)
    ax.set_xlabel(f"time ({_symbols(units)[1]})")
    ax.set_ylabel(f"{label} ({unit})" if unit else label)
    return ax


def rdf(result: Any, units: str = "si", diameter: float | None = None, ax: Any = None) -> Any:
    """Plot a radial distribution function (what ``Particles.computeRDF`` returns, or
    ``(g, r)``): g(r) against r in the length unit of ``units``, or in particle diameters when
    ``diameter`` is given."""
    g, r = np.asarray(result[0], dtype=float), np.asarray(result[1], dtype=float)
    ax = _axes(ax)
    if diameter is not None:
        ax.plot(r / diameter, g)
        ax.set_xlabel("r / d (particle diameters)")
    else:
        ax.plot(r, g)
        ax.set_xlabel(f"r ({_symbols(units)[0]})")
    ax.axhline(1.0, color="grey", linewidth=0.8, linestyle="--")
    ax.set_ylabel("g(r)")
    return ax


def coordination(counts: Sequence[int] | np.ndarray, ax: Any = None) -> Any:
    """Bar chart of the fraction of particles with each coordination number (the per-particle
    counts of ``Neighbors(particles).coon``); the mean in the legend."""
    numbers = np.asarray(counts)
    if numbers.ndim != 1 or len(numbers) == 0 or np.any(numbers < 0):
        raise ConfigError("coordination: give one non-negative count per particle")
    share = np.bincount(numbers.astype(int)) / len(numbers)
    ax = _axes(ax)
    ax.bar(np.arange(len(share)), share, label=f"mean {numbers.mean():.2f}")
    ax.set_xlabel("coordination number (contacts per particle)")
    ax.set_ylabel("fraction of particles")
    ax.legend()
    return ax
