"""The three cases of Dosta et al. (2024), "Comparing open-source DEM frameworks for simulations
of common bulk processes", Comput. Phys. Commun. 296, 109066, set up through ``simulation.DEM``.

Materials and pair values are the paper's (as YADE's scripts for it in
``examples/DEM2020Benchmark`` give them): M1 E = 1 GPa, nu = 0.2, 2500 kg/m^3; M2 E = 0.5 GPa,
nu = 0.2, 2000 kg/m^3; steel E = 210 GPa, nu = 0.2, 7200 kg/m^3; restitution / friction
M1-M1 0.5 / 0.3, M2-M2 0.4 / 0.4, M1-M2 0.45 / 0.2, particle-steel 0.4 / 0.2, steel-steel
0.6 / 0.5; Hertz-Mindlin, no rolling resistance, gravity 9.81 m/s^2 along -z.

- ``penetration``: the bed of 25k or 50k beads (r = 1 mm, M1) from the published file; a steel
  ball of r = 10 mm starts at (0, 0, 0.06) m at 5 m/s downwards (the bed file's last line,
  ``5 0.01 0.01 0 0 0.06``, read as speed, radius, radius, x, y, z); dt = 5e-7 s; the ball's
  z every 1 ms.
- ``drum``: the published mixture (30,000 of r = 1 mm M1, 8,000 of r = 2 mm M2) in the closed
  drum of radius 0.1 m turning at 2 rad/s about -y through the origin (MercuryDPM's angular
  velocity (0, -2, 0): the wall rises at x > 0); counts of small and large particles in zone 1
  (x > 0, z > 0) and zone 2 (x < 0, z < 0) every 0.1 s. ``stiff``: the
  paper's moduli at dt = 8e-7 s. ``soft``: M1 and M2 moduli divided by 500, at dt = 1e-5 s, not
  MercuryDPM's 1e-4 s: a contact of soft beads lasts about 6e-4 s at 0.1 m/s and under 3e-4 s
  at the drum's 1 m/s, so 1e-4 s gives about 3 steps per contact, which PyGran's time-step
  check refuses (no contact is resolved at that step); 1e-5 s gives about 30.
- ``silo``: the closed silo (small or large orifice) filled with 100,000 spheres of r = 2 mm
  of M1 or M2, poured in waves with a fixed seed on the native engine and kept as a file of
  ``radius x y z`` rows for every engine; the orifice (a plane wall at its level) is then
  removed; particles above the orifice every 0.1 s; dt = 1.5e-6 s (M1), 2e-6 s (M2).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core import simulation
from pygran_core.formats.tables import read_spheres, read_triangles

DATA = Path(__file__).parent / "data"
G = 9.81
M1 = {"youngsModulus": 1e9, "poissonsRatio": 0.2, "density": 2500.0, "coefficientRestitution": 0.5,
      "coefficientFriction": 0.3}  # fmt: skip
M2 = {"youngsModulus": 0.5e9, "poissonsRatio": 0.2, "density": 2000.0, "coefficientRestitution": 0.4,
      "coefficientFriction": 0.4}  # fmt: skip
#: Steel's own values are the steel-steel pair's (the ball on the penetration box's floor).
STEEL = {"youngsModulus": 210e9, "poissonsRatio": 0.2, "density": 7200.0, "coefficientRestitution": 0.6,
         "coefficientFriction": 0.5}  # fmt: skip
PARTICLE_STEEL = {"coefficientRestitution": 0.4, "coefficientFriction": 0.2}
M1_M2 = {"coefficientRestitution": 0.45, "coefficientFriction": 0.2}
BALL = {"radius": 0.01, "centre": (0.0, 0.0, 0.06), "speed": 5.0}
#: The orifice plane's depth below the silo's cylinder (m), per orifice.
ORIFICE_DEPTH = {"small": 0.0593008, "large": 0.0554222}
SILO_FILL = 100_000
SILO_RADIUS = 2e-3


@dataclass
class Case:
    """One case: ``keywords`` of ``DEM``, ``setup`` creating particles and motions, ``observe``
    returning the row of ``columns`` recorded every ``interval`` seconds."""

    name: str
    interval: float
    columns: tuple[str, ...]
    keywords: dict[str, Any]
    setup: Callable[[Any], None]
    observe: Callable[[Any], list[float]]
    particles: int
    settings: dict[str, Any] = field(default_factory=dict)


def soft(material: dict[str, float], factor: float = 500.0) -> dict[str, float]:
    return dict(material, youngsModulus=material["youngsModulus"] / factor)


def jittered(rows: np.ndarray, jitter: float, seed: int = 1) -> np.ndarray:
    """``rows`` (``radius x y z``) with each coordinate moved by up to ``jitter`` metres
    (uniform, seeded): run twice on one engine, once jittered by far less than any overlap,
    a case shows how far its own chaos carries two runs apart."""
    if not jitter:
        return rows
    moved = np.array(rows, dtype=float)
    moved[:, 1:] += np.random.default_rng(seed).uniform(-jitter, jitter, moved[:, 1:].shape)
    return moved


def bed(size: str) -> np.ndarray:
    """The penetration bed ``(N, 4)`` rows ``radius x y z`` (its malformed last line skipped)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the ball's line: see the module docstring
        table = read_spheres(DATA / f"penetration_{size}_particles.txt.gz", strict=False)
    return np.column_stack([table.radius, table.positions])


def penetration(
    size: str = "25k",
    rows: np.ndarray | None = None,
    box: tuple[float, ...] | None = None,
    jitter: float = 0.0,
) -> Case:
    """The penetration case with the bed of ``size`` (or ``rows``, a part of it, in ``box``,
    without the walls), its beads moved by up to ``jitter`` (see :func:`jittered`)."""
    walls = box is None
    rows = jittered(bed(size) if rows is None else rows, jitter)
    keywords: dict[str, Any] = {
        "model": simulation.models.HertzMindlin,
        "box": box or (-0.052, 0.052, -0.033, 0.033, -0.093, 0.109),
        "species": ({"material": M1, "radius": 1e-3}, {"material": STEEL, "radius": BALL["radius"]}),
        "gravity": (G, 0, 0, -1),
        "dt": 5e-7,
        "pairs": {(1, 2): PARTICLE_STEEL},
    }
    if walls:
        keywords["mesh"] = {"walls": {"file": str(DATA / "penetration_walls.txt.gz"), "material": STEEL}}
        keywords["pairs"][(1, "walls")] = PARTICLE_STEEL

    def setup(sim: Any) -> None:
        sim.createParticles(1, "single", rows)
        sim.createParticles(2, "single", *BALL["centre"], vel=(0.0, 0.0, -BALL["speed"]))

    def observe(sim: Any) -> list[float]:
        return [float(sim.extractCoords()[-1, 2])]  # the ball, created last

    return Case("penetration", 1e-3, ("z",), keywords, setup, observe, len(rows) + 1)


def drum(variant: str = "stiff", jitter: float = 0.0) -> Case:
    """The rotating drum, ``stiff`` or ``soft`` (see the module docstring), its particles moved
    by up to ``jitter`` (see :func:`jittered`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = read_spheres(DATA / "drum_particles.txt.gz", strict=False)
    rows = jittered(np.column_stack([table.radius, table.positions]), jitter)
    small, large = (M1, M2) if variant == "stiff" else (soft(M1), soft(M2))
    keywords = {
        "model": simulation.models.HertzMindlin,
        "box": (-0.103, 0.103, -0.033, 0.033, -0.103, 0.103),
        "species": ({"material": small, "radius": 1e-3}, {"material": large, "radius": 2e-3}),
        "mesh": {"drum": {"file": str(DATA / "drum_walls.txt.gz"), "material": STEEL}},
        "gravity": (G, 0, 0, -1),
        "dt": 8e-7 if variant == "stiff" else 1e-5,
        "pairs": {(1, 2): M1_M2, (1, "drum"): PARTICLE_STEEL, (2, "drum"): PARTICLE_STEEL},
    }

    def setup(sim: Any) -> None:
        sim.createParticles("all", "single", rows)
        sim.moveMesh("drum", rotate=("origin", 0.0, 0.0, 0.0), axis=(0.0, -1.0, 0.0), omega=2.0)

    def observe(sim: Any) -> list[float]:
        x, kind = sim.extractCoords(), sim.engine.extract("type")
        zone1, zone2 = (x[:, 0] > 0) & (x[:, 2] > 0), (x[:, 0] < 0) & (x[:, 2] < 0)
        return [float(np.count_nonzero(zone & (kind == k))) for zone in (zone1, zone2) for k in (1, 2)]

    columns = ("zone1_small", "zone1_large", "zone2_small", "zone2_large")
    return Case(f"drum-{variant}", 0.1, columns, keywords, setup, observe, len(rows))


def silo(orifice: str, material: str, fill: Path, count: int = SILO_FILL, jitter: float = 0.0) -> Case:
    """The silo of ``orifice`` ('small', 'large') with ``material`` ('M1', 'M2'), its fill of
    ``count`` spheres read from ``fill`` (made by :func:`make_silo_fill` when missing), moved
    by up to ``jitter`` (see :func:`jittered`)."""
    walls = read_triangles(DATA / f"silo_{orifice}_walls.txt.gz")
    depth = ORIFICE_DEPTH[orifice]
    keywords = silo_keywords(orifice, material)
    rows = jittered(
        np.loadtxt(fill) if fill.is_file() else make_silo_fill(orifice, material, fill, count), jitter
    )
    top = float(walls[..., 2].max())

    def setup(sim: Any) -> None:
        sim.createParticles(1, "single", rows)

    def observe(sim: Any) -> list[float]:
        return [float(np.count_nonzero(sim.extractCoords()[:, 2] > -depth))]

    case = Case(f"silo-{orifice}-{material}", 0.1, ("above_orifice",), keywords, setup, observe, len(rows))
    case.settings["silo_top"] = top
    return case


def silo_keywords(orifice: str, material: str) -> dict[str, Any]:
    grain = {"M1": M1, "M2": M2}[material]
    return {
        "model": simulation.models.HertzMindlin,
        "box": (-0.103, 0.103, -0.103, 0.103, -ORIFICE_DEPTH[orifice] - 0.05, 0.33),
        "species": ({"material": grain, "radius": SILO_RADIUS},),
        "mesh": {"silo": {"file": str(DATA / f"silo_{orifice}_walls.txt.gz"), "material": STEEL}},
        "gravity": (G, 0, 0, -1),
        "dt": 1.5e-6 if material == "M1" else 2e-6,
        "pairs": {(1, "silo"): PARTICLE_STEEL},
    }


#: Spheres poured per wave of a silo fill, and the seconds each wave settles.
FILL_WAVE, FILL_SETTLE = 12_500, 0.3


def make_silo_fill(
    orifice: str,
    material: str,
    path: Path,
    count: int,
    seed: int = 2024,
    wave_size: int = FILL_WAVE,
    settle: float = FILL_SETTLE,
) -> np.ndarray:
    """Pour ``count`` spheres into the silo closed by a plane at its orifice, in waves of at
    most ``wave_size`` into the cylinder above the spheres poured so far, each settled for
    ``settle`` s on the native engine; the rows ``radius x y z`` written to ``path`` and
    returned. Each wave is a simulation of its own, seeded ``seed`` plus its number, from the
    rows the wave before it left in ``<path stem>-pour/wave-<k>.txt``: a fill stopped between
    waves continues from its last finished wave and ends as it would have (the bed at rest,
    each wave only needs the positions of the last)."""
    keywords = silo_keywords(orifice, material)
    waves = max(1, math.ceil(count / wave_size))
    folder = path.parent / f"{path.stem}-pour"
    folder.mkdir(parents=True, exist_ok=True)
    rows = np.zeros((0, 4))
    for wave in range(1, waves + 1):
        kept = folder / f"wave-{wave}.txt"
        if kept.is_file():
            rows = np.loadtxt(kept, ndmin=2)
            continue
        with simulation.DEM(
            engine="native",
            output=str(folder / f"wave-{wave}"),
            seed=seed + wave,
            traj={"pfile": None},
            **keywords,
        ) as sim:
            sim.setupWall(species=1, plane="zplane", peq=-ORIFICE_DEPTH[orifice])
            if len(rows):
                sim.createParticles(1, "single", rows)
            bottom = float(rows[:, 3].max()) + 2 * SILO_RADIUS if len(rows) else 0.0
            region = ("cylinder", "z", 0.0, 0.0, 0.09, max(0.0, bottom), 0.31)
            sim.insert(species=1, value=count // waves + (wave <= count % waves), region=region)
            sim.run(round(settle / keywords["dt"]))
            rows = np.column_stack([sim.extractRadii(), sim.extractCoords()])
        np.savetxt(kept.with_suffix(".partial"), rows, fmt="%.17g", header="radius x y z")
        kept.with_suffix(".partial").replace(kept)
    np.savetxt(path, rows, fmt="%.17g", header="radius x y z")
    return rows
