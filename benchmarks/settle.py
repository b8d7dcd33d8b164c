"""The settle scenario of ``shared/benchmarks/settle.md`` through ``simulation.DEM`` on any engine.

    python benchmarks/settle.py --engine native --n 20000 --threads 1
    python benchmarks/settle.py --engine liggghts --n 20000

Prints particle-steps per second (N x steps / wall seconds of the loop) for the settling
phase (8,000 steps from the lattice) and the dense-bed phase (4,000 more), the peak memory
and the mean coordination number, then one JSON line:
``{"engine", "N", "threads", "settle_pss", "bed_pss", "peak_rss_mb", "coordination"}``.
Compare engines in the same run of this machine: absolute figures drift between machines.
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time

import numpy as np

from pygran_core import simulation
from pygran_core.analysis import Particles
from pygran_core.analysis.equilibrium import Neighbors

SHAPES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10)}
RADIUS, SPACING = 1e-3, 1.1 * 2e-3
MATERIAL = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.45,
    "coefficientRestitution": 0.3,
    "coefficientFriction": 0.5,
    "coefficientRollingFriction": 0.0,
    "density": 2500.0,
}


def lattice(shape: tuple[int, int, int], seed: int = 12345) -> np.ndarray:
    """Cell centres (i + 0.5) a, each displaced uniformly by up to 0.45 (a - 2r) per axis."""
    cells = np.stack(np.meshgrid(*(np.arange(n) for n in shape), indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    return (cells + 0.5) * SPACING + rng.uniform(-1, 1, cells.shape) * 0.45 * (SPACING - 2 * RADIUS)


def run(engine: str, n: int, threads: int | None) -> dict:
    shape = SHAPES[n]
    nx, ny, nz = shape
    with tempfile.TemporaryDirectory() as output:
        params = {
            "engine": engine,
            "model": simulation.models.HertzMindlin,
            "output": output,
            "box": (0, nx * SPACING, 0, ny * SPACING, 0, (nz + 3) * SPACING),
            "boundary": ("p", "p", "f"),
            "gravity": (9.81, 0, 0, -1),
            "dt": 1e-5,
            "nns_skin": 4e-4,
            "progress": False,
            "species": ({"material": MATERIAL, "radius": RADIUS},),
            "traj": {"pfile": None},
        }
        if threads is not None:
            params["threads" if engine != "liggghts" else "nprocs"] = threads
        with simulation.DEM(**params) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            start = time.perf_counter()
            for centre in lattice(shape):
                sim.createParticles(1, "single", *centre)
            created = time.perf_counter() - start
            assert len(sim.extractIds()) == n
            timings = []
            for steps in (8000, 4000):
                start = time.perf_counter()
                sim.run(steps)
                timings.append(n * steps / (time.perf_counter() - start))
            bed = Particles(
                x=sim.extractCoords()[:, 0],
                y=sim.extractCoords()[:, 1],
                z=sim.extractCoords()[:, 2],
                radius=sim.extractRadii(),
                box=np.array(params["box"]).reshape(3, 2),
                boundary=("pp", "pp", "ff"),
            )
    return {
        "engine": engine,
        "N": n,
        "threads": threads or 1,
        "settle_pss": timings[0],
        "bed_pss": timings[1],
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "coordination": float(Neighbors(bed).coon.mean()),
        "create_s": created,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default="native")
    parser.add_argument("--n", type=int, default=5000, choices=sorted(SHAPES))
    parser.add_argument("--threads", type=int, help="threads (native, yade) or MPI ranks (liggghts)")
    args = parser.parse_args()
    result = run(args.engine, args.n, args.threads)
    print(f"{args.engine}: N = {args.n}, threads/ranks = {result['threads']}")
    print(f"  settle    {result['settle_pss'] / 1e6:6.2f} M particle-steps/s")
    print(f"  dense bed {result['bed_pss'] / 1e6:6.2f} M particle-steps/s")
    print(
        f"  peak RSS  {result['peak_rss_mb']:.0f} MB of this process; "
        f"coordination {result['coordination']:.2f}"
    )
    print(
        json.dumps(
            {
                k: result[k]
                for k in ("engine", "N", "threads", "settle_pss", "bed_pss", "peak_rss_mb", "coordination")
            }
        )
    )


if __name__ == "__main__":
    main()
