"""The agreement gates of the Dosta et al. (2024) cases, applied to the engines' CSVs, and
Beverloo's discharge rate for the silo.

- penetration: the ball's z of each engine within 1 mm of native's at every ms (YADE's
  within 2 mm);
- drum: each zone count of each engine within 5 % of the engines' mean at every 0.1 s;
- silo: the number discharged by each 0.1 s, from 0.2 s on, within 10 % of native's; the
  steady rate (a straight line through the counts from 0.2 s on) against Beverloo's.

A jittered run (``<engine>+jitter``) is held to the same gate against its own engine: how
far the case's own chaos carries two runs of one engine apart, the floor under any agreement
of two engines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cases
import numpy as np

#: Beverloo's constants as the paper compares with them: discharge coefficient, empty
#: annulus (in particle diameters) and the bed's packing fraction.
BEVERLOO_C, BEVERLOO_K, PACKING = 0.58, 1.5, 0.6
#: Orifice diameters (m).
ORIFICE_DIAMETER = {"small": 0.04, "large": 0.06}
#: The engine every other is compared with.
REFERENCE = "native"


@dataclass(frozen=True)
class Verdict:
    """One engine's agreement with its reference on one case: the worst difference (in the
    gate's unit), the gate, and the last time up to which every sample held (``None``: none did)."""

    case: str
    engine: str
    reference: str
    worst: float
    gate: float
    unit: str
    held_until: float | None
    end: float

    @property
    def holds(self) -> bool:
        return self.worst <= self.gate

    def line(self) -> str:
        until = (
            "throughout"
            if self.holds
            else f"to {self.held_until:g} s"
            if self.held_until is not None
            else "never"
        )
        verdict = "holds" if self.holds else "fails"
        return (
            f"{self.case:<22} {self.engine:<16} vs {self.reference:<10} worst {self.worst:10.4g} "
            f"{self.unit:<8} gate {self.gate:g}: {verdict} ({until}, run to {self.end:g} s)"
        )


def beverloo_rate(
    orifice: str, c: float = BEVERLOO_C, k: float = BEVERLOO_K, packing: float = PACKING
) -> float:
    """Particles per second through a flat-bottomed silo's ``orifice``: Beverloo's mass rate
    ``C rho_b sqrt(g) (D - k d)^(5/2)`` over one sphere's mass, with ``rho_b`` the packing
    fraction times the spheres' density (which cancels)."""
    diameter = 2 * cases.SILO_RADIUS
    opening = ORIFICE_DIAMETER[orifice] - k * diameter
    return c * packing * math.sqrt(cases.G) * opening**2.5 / (math.pi * diameter**3 / 6)


def steady_rate(table: np.ndarray, start: float = 0.2) -> float:
    """Particles per second leaving the silo: minus the slope of a straight line through
    the counts above the orifice from ``start`` on (``nan`` with fewer than 3 samples)."""
    later = table[table[:, 0] >= start - 1e-9]
    if len(later) < 3:
        return math.nan
    return -float(np.polyfit(later[:, 0], later[:, 1], 1)[0])


def _held_until(times: np.ndarray, good: np.ndarray) -> float | None:
    """The last time up to which every sample is good."""
    bad = np.flatnonzero(~good)
    if not len(bad):
        return float(times[-1])
    return float(times[bad[0] - 1]) if bad[0] > 0 else None


def _aligned(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows of ``a`` and ``b`` at the times both have."""
    times, ia, ib = np.intersect1d(np.round(a[:, 0], 9), np.round(b[:, 0], 9), return_indices=True)
    return times, a[ia], b[ib]


def _verdict(
    label: str, engine: str, reference: str, times: np.ndarray, gap: np.ndarray, gate: float, unit: str
) -> Verdict:
    good = gap <= gate
    return Verdict(
        label, engine, reference, float(gap.max()), gate, unit, _held_until(times, good), float(times[-1])
    )


def _drum_off(tables: list[np.ndarray]) -> np.ndarray:
    """Per time (row) and table, the largest relative distance of a zone count from the
    tables' mean (a zone every table leaves empty agrees)."""
    counts = np.stack([t[:, 1:] for t in tables])
    mean = counts.mean(axis=0)
    return (np.abs(counts - mean) / np.where(mean > 0, mean, 1.0)).max(axis=2)


def verdicts(label: str, runs: dict[str, np.ndarray]) -> list[Verdict]:
    """The gate of case ``label`` (``penetration-25k``, ``drum-soft``, ``silo-small-M1``, ...)
    for each engine of ``runs`` (engine -> CSV rows ``time, columns...``): against native, or
    on the drum against the mean of every engine (a jittered run: against its own engine)."""
    kind = label.split("-")[0]
    found = []
    engines = sorted(e for e in runs if "+" not in e)
    if kind == "drum" and len(engines) > 1:
        times = runs[engines[0]][:, 0]
        for engine in engines[1:]:
            times = np.intersect1d(np.round(times, 9), np.round(runs[engine][:, 0], 9))
        tables = [runs[e][np.isin(np.round(runs[e][:, 0], 9), times)] for e in engines]
        if len(times):
            for engine, gap in zip(engines, _drum_off(tables)):
                found.append(_verdict(label, engine, "mean", times, gap, 0.05, "of mean"))
    for engine, table in sorted(runs.items()):
        own = engine.partition("+")[0]
        reference = own if "+" in engine else REFERENCE
        if engine == reference or reference not in runs or (kind == "drum" and "+" not in engine):
            continue
        times, mine, theirs = _aligned(table, runs[reference])
        if kind == "silo":  # the number discharged, from 0.2 s on
            keep = times >= 0.2 - 1e-9
            times, mine, theirs = times[keep], mine[keep], theirs[keep]
        if not len(times):
            continue
        if kind == "penetration":
            gap = np.abs(mine[:, 1] - theirs[:, 1]) * 1e3
            found.append(_verdict(label, engine, reference, times, gap, 2.0 if own == "yade" else 1.0, "mm"))
        elif kind == "drum":
            found.append(
                _verdict(label, engine, reference, times, _drum_off([mine, theirs])[0], 0.05, "of mean")
            )
        else:
            gone, theirs_gone = table[0, 1] - mine[:, 1], runs[reference][0, 1] - theirs[:, 1]
            gap = np.abs(gone - theirs_gone) / np.where(theirs_gone > 0, theirs_gone, 1.0)
            found.append(_verdict(label, engine, reference, times, gap, 0.10, "of gone"))
    return found
