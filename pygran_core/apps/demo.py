"""The hopper discharge study behind ``pygran demo`` and the README's main command.

A conical hopper (generated as an STL file) is filled by insertion onto a stopper plane
across its outlet, the particles settle, the stopper is removed and the hopper discharges.
The trajectory is written as H5MD (with its XDMF sidecar) and the walls as a VTK series
indexed by ``walls.pvd`` (the hopper, standing still, is one file); the analysis measures the
discharge rate (beside the Beverloo prediction), the settled packing fraction,
coordination numbers and the radial distribution function, and saves PNG plots and a
summary in the output directory. Any engine with mesh walls runs it.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from pygran_core import analysis, registry, simulation
from pygran_core.errors import ConfigError

GRAVITY = 9.81
#: Beverloo's constants for spheres (Beverloo, Leniger & van de Velde 1961; Nedderman 1992).
BEVERLOO_C, BEVERLOO_K = 0.58, 1.5


@dataclass(frozen=True)
class HopperStudy:
    """Geometry, material and schedule of the study (SI units).

    The material is soft (as in the settle benchmark) so that a 10 microsecond time step
    resolves every contact; the hopper is a cone of half-angle ``half_angle`` (degrees from
    the vertical) from the outlet at z = 0, topped by a cylinder.
    """

    particles: int = 3000
    radius: float = 1e-3
    density: float = 2500.0
    youngs_modulus: float = 5e6
    poisson_ratio: float = 0.45
    restitution: float = 0.3
    friction: float = 0.5
    outlet_diameter: float = 12e-3
    half_angle: float = 30.0
    cone_height: float = 45e-3
    cylinder_height: float = 45e-3
    dt: float = 1e-5
    settle_time: float = 0.3
    discharge_time: float = 1.5
    frame_interval: float = 0.02
    seed: int = 20261122

    @property
    def top_radius(self) -> float:
        return self.outlet_diameter / 2 + self.cone_height * math.tan(math.radians(self.half_angle))

    @property
    def height(self) -> float:
        return self.cone_height + self.cylinder_height

    def radius_at(self, z: float) -> float:
        """Inner radius of the hopper at height ``z``."""
        return min(self.outlet_diameter / 2 + z * math.tan(math.radians(self.half_angle)), self.top_radius)

    @property
    def material(self) -> dict[str, float]:
        return {
            "youngsModulus": self.youngs_modulus,
            "poissonsRatio": self.poisson_ratio,
            "coefficientRestitution": self.restitution,
            "coefficientFriction": self.friction,
            "density": self.density,
        }


def hopper_triangles(study: HopperStudy, segments: int = 64) -> np.ndarray:
    """The hopper's surface: cone then cylinder, open at the outlet and the top, (T, 3, 3)."""
    angles = np.linspace(0, 2 * math.pi, segments + 1)
    rings = [
        (0.0, study.outlet_diameter / 2),
        (study.cone_height, study.top_radius),
        (study.height, study.top_radius),
    ]
    triangles = []
    for (z0, r0), (z1, r1) in zip(rings[:-1], rings[1:]):
        a0, a1 = angles[:-1], angles[1:]
        low0 = np.column_stack([r0 * np.cos(a0), r0 * np.sin(a0), np.full(segments, z0)])
        low1 = np.column_stack([r0 * np.cos(a1), r0 * np.sin(a1), np.full(segments, z0)])
        up0 = np.column_stack([r1 * np.cos(a0), r1 * np.sin(a0), np.full(segments, z1)])
        up1 = np.column_stack([r1 * np.cos(a1), r1 * np.sin(a1), np.full(segments, z1)])
        triangles += [np.stack([low0, low1, up1], axis=1), np.stack([low0, up1, up0], axis=1)]
    return np.concatenate(triangles)


def write_stl(path: Path, triangles: np.ndarray, name: str = "hopper") -> Path:
    """Write triangles (T, 3, 3) as an ASCII STL file."""
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    facet = "facet normal %r %r %r\n outer loop\n" + "  vertex %r %r %r\n" * 3 + " endloop\nendfacet\n"
    rows = np.column_stack([normals, triangles.reshape(-1, 9)]).tolist()
    path.write_text(f"solid {name}\n" + "".join(facet % tuple(row) for row in rows) + f"endsolid {name}\n")
    return path


def beverloo(study: HopperStudy, packing_fraction: float) -> float:
    """Beverloo's mass discharge rate (kg/s) for the study's outlet, particles and bulk density."""
    effective = study.outlet_diameter - BEVERLOO_K * 2 * study.radius
    return BEVERLOO_C * packing_fraction * study.density * math.sqrt(GRAVITY) * effective**2.5


@dataclass(frozen=True)
class Summary:
    """What the study measured."""

    engine: str
    particles: int
    packing_fraction: float
    mean_coordination: float
    discharge_rate: float
    beverloo_rate: float
    rdf_first_peak: float
    discharged_fraction: float

    def text(self) -> str:
        ratio = self.discharge_rate / self.beverloo_rate if self.beverloo_rate else math.nan
        return (
            f"Hopper discharge study ({self.engine} engine, {self.particles} particles)\n"
            f"  settled packing fraction      {self.packing_fraction:.3f}\n"
            f"  mean coordination number      {self.mean_coordination:.2f}\n"
            f"  RDF first peak at             {self.rdf_first_peak:.3f} particle diameters\n"
            f"  discharge rate (measured)     {self.discharge_rate * 1e3:.2f} g/s\n"
            f"  discharge rate (Beverloo)     {self.beverloo_rate * 1e3:.2f} g/s"
            f"  (measured/Beverloo = {ratio:.2f})\n"
            f"  discharged by the end         {100 * self.discharged_fraction:.0f} %\n"
        )


def default_nprocs(engine: str) -> int:
    """MPI ranks for ``engine``: every core where it runs under MPI and ``mpirun`` exists, else 1."""
    if "mpi" in registry.get_engine(engine).capabilities and shutil.which("mpirun"):
        return os.cpu_count() or 1
    return 1


def simulate(
    study: HopperStudy,
    output: Path,
    engine: str,
    progress: bool | None,
    report: Callable[[str], None],
    nprocs: int = 1,
) -> int:
    """Fill, settle and discharge the hopper; returns the step at which the stopper was removed."""
    stl = write_stl(output / "hopper.stl", hopper_triangles(study))
    r_top = study.top_radius
    margin = 4 * study.radius
    frame_steps = max(1, round(study.frame_interval / study.dt))
    params = {
        "engine": engine,
        "model": simulation.models.HertzMindlin,
        "output": str(output),
        "box": (
            -r_top - margin,
            r_top + margin,
            -r_top - margin,
            r_top + margin,
            -study.height / 2,
            study.height + margin,
        ),
        "boundary": ("f", "f", "f"),
        "gravity": (GRAVITY, 0, 0, -1),
        "dt": study.dt,
        "seed": study.seed,
        "species": ({"material": study.material, "radius": study.radius},),
        "mesh": {"hopper": {"file": str(stl), "material": study.material}},
        "traj": {"pfile": "traj.h5md", "mfile": "walls*.vtk", "freq": frame_steps},
        "progress": progress,
    } | ({"nprocs": nprocs} if nprocs > 1 else {})
    with simulation.DEM(**params) as sim:
        sim.setupWall(wtype="mesh", species=1, mesh="hopper")
        stopper = sim.setupWall(species=1, plane="zplane", peq=0.0)
        fill = ("cylinder", "z", 0.0, 0.0, r_top - 2 * study.radius, study.cone_height, study.height)
        sim.insert(species=1, value=study.particles, region=fill)
        report(f"filling the hopper with {study.particles} particles; settling for {study.settle_time} s")
        sim.run(round(study.settle_time / study.dt / frame_steps) * frame_steps)
        inserted = len(sim.extractIds())  # after a run: some engines insert when it starts
        if inserted < study.particles:
            raise ConfigError(
                f"Only {inserted} of {study.particles} particles fit in the hopper; ask for fewer"
            )
        opened = sim.step
        sim.remove(stopper)
        sim.expect_outflow("z-")  # what leaves the outlet falls out of the box: logged, not warned
        report(f"stopper removed at t = {sim.time:.3f} s; discharging for {study.discharge_time} s")
        sim.run(round(study.discharge_time / study.dt / frame_steps) * frame_steps)
        return opened


def analyse(study: HopperStudy, output: Path, engine: str, opened: int) -> Summary:
    """Measure the study's trajectory and write plots and a summary into ``output``."""
    system = analysis.System(Particles=str(output / "traj.h5md"))
    steps = np.asarray(analysis.dynamics.Temporal(system).series("timestep"))
    settled_frame = int(np.searchsorted(steps, opened))
    system.goto(settled_frame)
    settled = cast(analysis.Particles, system.Particles)
    packing, z_hi = _packing_fraction(study, settled)
    coon = analysis.equilibrium.Neighbors(settled).coon
    bulk = (settled.z > 2 * study.radius) & (settled.z < max(z_hi, 4 * study.radius))
    reach = min(6 * study.radius, 0.4 * float(np.ptp(settled.positions, axis=0).min()))  # small beds
    rdf = settled.computeRDF(dr=0.05 * study.radius, rMax=reach)
    # computeRDF normalises by the particles' bounding box, which around a cone is partly empty:
    # renormalise by the bulk number density measured on the axis, so that g tends to 1
    box_density = (len(settled) - 1) / np.prod(np.ptp(settled.positions, axis=0))  # computeRDF's reference
    rdf = rdf._replace(g=rdf.g * box_density / (packing / (4 / 3 * math.pi * study.radius**3)))
    peak = float(rdf.r[np.argmax(rdf.g)] / (2 * study.radius))

    mass = study.density * 4 / 3 * math.pi * study.radius**3
    in_hopper = np.array([np.count_nonzero(system.Particles.z > 0) for _ in system.frames()], float) * mass
    times = (steps - opened) * study.dt
    after = times >= 0
    discharged = in_hopper[after][0] - in_hopper[after]
    total = in_hopper[after][0]
    steady = (discharged > 0.2 * total) & (discharged < 0.8 * total)
    rate = (
        float(np.polyfit(times[after][steady], discharged[steady], 1)[0]) if steady.sum() >= 2 else math.nan
    )
    summary = Summary(
        engine,
        len(settled),
        packing,
        float(coon[bulk].mean()),
        rate,
        beverloo(study, packing),
        peak,
        float(discharged[-1] / total),
    )
    _plots(output, study, times[after], discharged, summary, rdf, coon[bulk])
    (output / "summary.txt").write_text(summary.text())
    (output / "summary.json").write_text(
        json.dumps({"study": asdict(study), "results": asdict(summary)}, indent=2)
    )
    return summary


def _packing_fraction(study: HopperStudy, settled: Any) -> tuple[float, float]:
    """Solid fraction in a cylinder on the hopper's axis, 2 diameters clear of the walls, the
    outlet and the free surface; returns it and the top of the sampled cylinder."""
    d = 2 * study.radius
    z_lo = 2 * d
    r_sample = study.radius_at(z_lo) - 2 * d
    on_axis = np.hypot(settled.x, settled.y) < r_sample
    z_hi = float(settled.z[on_axis].max()) - 2 * d if on_axis.any() else z_lo
    if z_hi - z_lo < 2 * d:
        raise ConfigError(
            "The settled bed is too shallow to measure its packing fraction; use more particles"
        )
    inside = on_axis & (settled.z > z_lo) & (settled.z < z_hi)
    solid = (4 / 3 * math.pi * settled.radius[inside] ** 3).sum()
    return float(solid / (math.pi * r_sample**2 * (z_hi - z_lo))), z_hi


def _plots(
    output: Path,
    study: HopperStudy,
    times: np.ndarray,
    discharged: np.ndarray,
    summary: Summary,
    rdf: Any,
    coon: np.ndarray,
) -> None:
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise ConfigError(
            "The demo draws its plots with matplotlib: pip install 'pygran-core[plot]'"
        ) from None

    figure = Figure(figsize=(13, 4), layout="constrained")
    left, middle, right = figure.subplots(1, 3)
    left.plot(times, discharged * 1e3, "o-", ms=3, label=f"{summary.engine} engine")
    left.plot(
        times,
        np.clip(summary.beverloo_rate * times, 0, discharged.max()) * 1e3,
        "--",
        label=f"Beverloo, {summary.beverloo_rate * 1e3:.1f} g/s",
    )
    left.set(xlabel="time since the outlet opened (s)", ylabel="discharged mass (g)", title="Discharge")
    left.legend()
    middle.plot(rdf.r / (2 * study.radius), rdf.g)
    middle.set(
        xlabel="r / d",
        ylabel="g(r)",
        title=f"RDF of the settled bed (first peak {summary.rdf_first_peak:.2f} d)",
    )
    right.hist(coon, bins=np.arange(coon.max() + 2) - 0.5)
    right.set(
        xlabel="contacts per particle",
        ylabel="particles",
        title=f"Coordination (mean {summary.mean_coordination:.2f})",
    )
    figure.savefig(output / "hopper.png", dpi=110)


def run(
    output: str | Path,
    engine: str = "native",
    particles: int | None = None,
    progress: bool | None = None,
    report: Callable[[str], None] = lambda message: None,
    nprocs: int | None = None,
    **changes: Any,
) -> Summary:
    """Run the whole study into ``output``: simulation, then analysis. ``nprocs`` MPI ranks
    (default: :func:`default_nprocs`); ``changes`` override fields of :class:`HopperStudy`
    (e.g. ``discharge_time=0.5``)."""
    study = HopperStudy(**({"particles": particles} if particles else {}), **changes)
    output = Path(output).resolve()
    output.mkdir(parents=True, exist_ok=True)
    nprocs = default_nprocs(engine) if nprocs is None else nprocs
    ranks = f" on {nprocs} MPI ranks" if nprocs > 1 else ""
    report(f"hopper study on the {engine} engine{ranks} into {output}")
    opened = simulate(study, output, engine, progress, report, nprocs)
    report("analysing the trajectory")
    return analyse(study, output, engine, opened)
