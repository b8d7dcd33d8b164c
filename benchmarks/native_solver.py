"""The settle scenario of shared/benchmarks/settle.md run directly on the native Solver.

Prints particle-steps/s of the settling (8,000 steps) and dense-bed (4,000 steps) phases
for 1 thread and for ``--threads`` threads (each in a fresh process), the speed-up, the
coordination number, and the peak RSS growth per particle from creating and running the
solver (inputs are built before the baseline is taken).

    .venv/bin/python benchmarks/native_solver.py --n 20000 --threads 2
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np
from pygran_native.solver import Solver

SIZES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10)}
RADIUS, SPACING, DT = 1e-3, 2.2e-3, 1e-5


def lattice(n: int, seed: int = 12345) -> tuple[np.ndarray, np.ndarray]:
    """Box and perturbed simple-cubic lattice positions of the scenario."""
    nx, ny, nz = SIZES[n]
    box = np.array([[0, 0, 0], [nx * SPACING, ny * SPACING, (nz + 3) * SPACING]])
    grid = np.indices((nx, ny, nz)).reshape(3, -1).T
    rng = np.random.default_rng(seed)
    x = (grid + 0.5) * SPACING + rng.uniform(-1, 1, grid.shape) * 0.45 * (SPACING - 2 * RADIUS)
    return box, x


def scenario(box: np.ndarray, x: np.ndarray, threads: int):
    """The solver of the scenario: Hertz-Mindlin with history, periodic x and y, a floor."""
    solver = Solver(box=box, periodic=(True, True, False), gravity=(0, 0, -9.81), skin=4e-4, threads=threads)
    solver.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
    solver.add_plane((0, 0, 0), (0, 0, 1), 0)
    solver.add_particles(x, RADIUS, densities=2500)
    return solver


def rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def measure(n: int, threads: int) -> dict:
    box, x = lattice(n)
    baseline = rss_bytes()
    solver = scenario(box, x, threads)
    solver.run(0, DT)
    t0 = time.perf_counter()
    solver.run(8000, DT)
    t1 = time.perf_counter()
    solver.run(4000, DT)
    t2 = time.perf_counter()
    grown = rss_bytes() - baseline
    return {
        "N": solver.n,
        "threads": threads,
        "settle_pss": n * 8000 / (t1 - t0),
        "bed_pss": n * 4000 / (t2 - t1),
        "coordination": 2 * len(solver.contacts()[0]) / solver.n,
        "lost": solver.lost,
        "rebuilds": solver.rebuilds,
        "rss_bytes_per_particle": grown / n,
        "solver_bytes_per_particle": solver.memory_bytes / n,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000, choices=sorted(SIZES))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--one", action="store_true", help="run one measurement in this process")
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.n, args.threads)))
        return
    results = []
    for threads in sorted({1, args.threads}):
        command = [sys.executable, __file__, "--one", "--n", str(args.n), "--threads", str(threads)]
        out = subprocess.run(command, capture_output=True, text=True, check=True)
        res = json.loads(out.stdout.strip().splitlines()[-1])
        results.append(res)
        print(
            f"N={res['N']} threads={res['threads']}: "
            f"settle {res['settle_pss'] / 1e6:.2f} M particle-steps/s, "
            f"dense bed {res['bed_pss'] / 1e6:.2f} M, coordination {res['coordination']:.2f}, "
            f"{res['rebuilds']} rebuilds, "
            f"peak RSS growth {res['rss_bytes_per_particle']:.0f} B/particle "
            f"(solver allocation {res['solver_bytes_per_particle']:.0f} B/particle)"
        )
    if len(results) == 2:
        one, many = results
        print(
            f"speed-up {many['threads']}/1 threads: settle {many['settle_pss'] / one['settle_pss']:.2f}x, "
            f"dense bed {many['bed_pss'] / one['bed_pss']:.2f}x"
        )
    print(json.dumps(results))


if __name__ == "__main__":
    main()
