"""createParticles(species, 'single', positions) of 10^5 and 10^6 positions (a cubic lattice
of touching-free spheres) on each engine, timed with the positions read back: seconds and
positions per second, and each size's time against the smaller's (linear: 10 times).

    .venv/bin/python benchmarks/dosta2024/create.py --engines native liggghts --sizes 100000 1000000
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

from pygran_core import params, simulation

SPACING = 2.2e-3


def create(engine: str, count: int, folder: Path) -> float:
    """Seconds to create ``count`` spheres of r = 1 mm at given positions and read them back."""
    side = int(np.ceil(count ** (1 / 3)))
    grid = (np.arange(side) + 0.5) * SPACING
    positions = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), -1).reshape(-1, 3)[:count]
    length = side * SPACING
    with simulation.DEM(
        engine=engine,
        model=simulation.models.HertzMindlin,
        box=(0, length, 0, length, 0, length),
        species=({"material": params.glass, "radius": 1e-3},),
        dt=1e-7,
        output=str(folder / f"{engine}-{count}"),
        progress=False,
        traj={"pfile": None},
    ) as sim:
        start = time.perf_counter()
        sim.createParticles(1, "single", positions)
        back = sim.extractCoords()
        elapsed = time.perf_counter() - start
    if not np.array_equal(back, positions):
        raise SystemExit(f"{engine}: the positions read back differ from those given")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--engines", nargs="+", default=["native", "liggghts"])
    parser.add_argument("--sizes", nargs="+", type=int, default=[100_000, 1_000_000])
    args = parser.parse_args()
    with TemporaryDirectory() as tmp:
        for engine in args.engines:
            times = [create(engine, n, Path(tmp)) for n in args.sizes]
            for n, seconds in zip(args.sizes, times):
                rate, ratio = n / seconds / 1e6, seconds / times[0]
                print(f"{engine:<9} {n:>9,} positions: {seconds:6.2f} s ({rate:.2f} M/s), x{ratio:.1f}")


if __name__ == "__main__":
    main()
