"""The settle scenario of ``benchmarks/README.md`` through ``simulation.DEM`` on any engine.

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
from pathlib import Path

import numpy as np

from pygran_core.analysis import Particles
from pygran_core.analysis.equilibrium import Neighbors
from pygran_core.testing.validation import settle_setup

SHAPES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10)}


def run(engine: str, n: int, threads: int | None) -> dict:
    # threads=None: the engine's default (settle_setup's own default is one thread)
    parallel = {"nprocs": threads} if engine == "liggghts" else {"threads": threads}
    with tempfile.TemporaryDirectory() as output:
        start = time.perf_counter()
        with settle_setup(engine, Path(output), SHAPES[n], **parallel) as sim:
            created = time.perf_counter() - start
            assert len(sim.extractIds()) == n
            workers = sim.engine._facts().get("threads", threads or 1)
            timings = []
            for steps in (8000, 4000):
                start = time.perf_counter()
                sim.run(steps)
                timings.append(n * steps / (time.perf_counter() - start))
            x = sim.extractCoords()
            bed = Particles(
                x=x[:, 0],
                y=x[:, 1],
                z=x[:, 2],
                radius=sim.extractRadii(),
                box=np.array(sim.spec.domain.box),
                boundary=("pp", "pp", "ff"),
            )
    return {
        "engine": engine,
        "N": n,
        "threads": workers,
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
