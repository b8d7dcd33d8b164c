"""Mesh hopper: the original examples' silo (an STL mesh wall) filled, settled and discharged,
the same ``simulation.DEM`` script on native (one thread) and on LIGGGHTS (one MPI rank).

    python benchmarks/mesh_hopper.py [--particles 1000] [--repeats 1] [--engines native liggghts]

The hopper is ``tests/data/meshes/silo.stl`` (a cone from r = 0.3 mm at its outlet, z = 0, to
r = 1 mm at z = 3 mm, in mm: read with ``scale 1e-3``), with a plane stopper across the outlet.
Hertz-Mindlin spheres of radius 50 um (``params.cohesionless``, restitution 0.5), dt = 5e-7 s:

- fill: ``insert`` the particles at once into a cylinder on the axis (r 0.55 mm, z 1.4 to
  4.9 mm; the bed settles up to about 1.3 mm) and run 60,000 steps (30 ms) while they fall
  into the cone onto the stopper;
- settle: 20,000 more steps;
- discharge: remove the stopper and run 40,000 steps in 8 runs; what leaves the box is deleted.

Prints particle-steps per second for each phase (particles present x steps / wall seconds of
the runs; in the discharge, the mean of the counts before and after each run), the ratio
native / LIGGGHTS of each phase and of the whole, measured in the same run (best of
``--repeats``, the engines taking turns), and how many particles each engine discharged
(below the outlet at the end): they must agree within 20 %. Timings are only comparable
within one run of one machine: the load average is printed with them.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from pygran_core import params
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.validation import one_species

SILO = Path(__file__).resolve().parents[1] / "tests" / "data" / "meshes" / "silo.stl"
RADIUS = 5e-5
MATERIAL = dict(params.cohesionless, coefficientRestitution=0.5)
DT = 5e-7
FILL, SETTLE, DISCHARGE, CHUNKS = 60_000, 20_000, 40_000, 8
PHASES = ("fill", "settle", "discharge")
#: Insertion cylinder: on the axis, inside the cone above the settled bed (up to ~1.3 mm), and
#: tall enough that the particles fit at random (16 % of its volume).
REGION = ("cylinder", "z", 0.0, 0.0, 5.5e-4, 1.4e-3, 4.9e-3)


def run(engine: str, particles: int, seed: int) -> tuple[dict[str, tuple[float, float]], int]:
    """One hopper on ``engine``: (particle-steps, wall seconds) of each phase, and how many
    particles were discharged."""
    mesh = {"silo": {"file": str(SILO), "mtype": "mesh/surface", "args": ("scale 1e-3",)}}
    parallel = {"nprocs": 1} if engine == "liggghts" else {"threads": 1}
    with (
        tempfile.TemporaryDirectory() as output,
        one_species(
            engine,
            Path(output),
            MATERIAL,
            RADIUS,
            model=HertzMindlin,
            box=(-1.1e-3, 1.1e-3, -1.1e-3, 1.1e-3, -1e-3, 5e-3),
            mesh=mesh,
            dt=DT,
            gravity=(9.81, 0, 0, -1),
            seed=seed,
            **parallel,
        ) as sim,
    ):
        sim.setupWall(wtype="mesh", mesh="silo")
        stopper = sim.setupWall(plane="zplane", peq=0.0)
        sim.insert(species=1, value=particles, region=REGION)
        result: dict[str, tuple[float, float]] = {}
        for phase, steps in (("fill", FILL), ("settle", SETTLE)):
            start = time.perf_counter()
            sim.run(steps)
            seconds = time.perf_counter() - start
            present = len(sim.extractIds())
            assert present == particles, f"{engine}: {present} of {particles} particles inserted"
            result[phase] = (present * steps, seconds)
        assert sim.extractCoords()[:, 2].min() > 0, f"{engine}: a particle is below the stopper"
        sim.remove(stopper)
        sim.expect_outflow("z-")  # the outlet opens onto the bottom of the box
        work = seconds = 0.0
        present = particles
        for _ in range(CHUNKS):
            start = time.perf_counter()
            sim.run(DISCHARGE // CHUNKS)
            seconds += time.perf_counter() - start
            after = len(sim.extractIds())
            work += (present + after) / 2 * (DISCHARGE // CHUNKS)
            present = after
        result["discharge"] = (work, seconds)
        discharged = particles - int(np.count_nonzero(sim.extractCoords()[:, 2] > 0))
    return result, discharged


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--engines", nargs=2, default=["native", "liggghts"], metavar=("ENGINE", "REFERENCE"))
    parser.add_argument("--seed", type=int, default=20261124)
    args = parser.parse_args()
    # per engine and phase, the fastest of the repeats: (particle-steps, seconds)
    best: dict[str, dict[str, tuple[float, float]]] = {engine: {} for engine in args.engines}
    discharged: dict[str, int] = {}
    for _ in range(args.repeats):  # the engines take turns, so a busy machine slows both alike
        for engine in args.engines:
            result, discharged[engine] = run(engine, args.particles, args.seed)
            for phase, (work, seconds) in result.items():
                old = best[engine].get(phase)
                if old is None or work / seconds > old[0] / old[1]:
                    best[engine][phase] = (work, seconds)
    mine, reference = args.engines
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"mesh hopper, {args.particles} particles, 1 thread / 1 rank, best of {args.repeats}; load {load}")
    print(f"  {'phase':<10}" + "".join(f"{e + ' M p-steps/s':>24}" for e in args.engines) + f"{'ratio':>8}")
    for phase in (*PHASES, "whole"):
        rates = []
        for engine in args.engines:
            runs = best[engine].values() if phase == "whole" else [best[engine][phase]]
            rates.append(sum(w for w, _ in runs) / sum(s for _, s in runs))
        print(f"  {phase:<10}" + "".join(f"{r / 1e6:24.2f}" for r in rates) + f"{rates[0] / rates[1]:8.2f}")
    print(f"  discharged below the outlet: {mine} {discharged[mine]}, {reference} {discharged[reference]}")
    low, high = sorted(discharged.values())
    if high == 0 or low < 0.8 * high:
        raise SystemExit(f"the engines disagree on the discharge: {discharged}")


if __name__ == "__main__":
    main()
