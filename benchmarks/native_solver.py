"""The settle scenario of shared/benchmarks/settle.md run directly on the native Solver.

Prints particle-steps/s of the settling (8,000 steps) and dense-bed (4,000 steps) phases
for 1 thread and for ``--threads`` threads (each in a fresh process so the peak RSS is
its own), the speed-up, the coordination number and peak RSS per particle.

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

SIZES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10)}


def scenario(n: int, threads: int, seed: int = 12345):
    from pygran_native.solver import Solver

    nx, ny, nz = SIZES[n]
    r, a = 1e-3, 1.1 * 2e-3
    box = [[0, 0, 0], [nx * a, ny * a, (nz + 3) * a]]
    solver = Solver(box=box, periodic=(True, True, False), gravity=(0, 0, -9.81), skin=4e-4, threads=threads)
    solver.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
    solver.add_plane((0, 0, 0), (0, 0, 1), 0)
    grid = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    x = (grid + 0.5) * a + rng.uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * r)
    solver.add_particles(x, r, densities=2500)
    return solver


def measure(n: int, threads: int) -> dict:
    solver = scenario(n, threads)
    dt = 1e-5
    solver.run(0, dt)
    t0 = time.perf_counter()
    solver.run(8000, dt)
    t1 = time.perf_counter()
    solver.run(4000, dt)
    t2 = time.perf_counter()
    contacts = len(solver.contacts()[0])
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return {"N": solver.n, "threads": threads, "settle_pss": n * 8000 / (t1 - t0), "bed_pss": n * 4000 / (t2 - t1),
            "coordination": 2 * contacts / solver.n, "lost": solver.lost, "rebuilds": solver.rebuilds,
            "solver_bytes_per_particle": solver.memory_bytes / n, "peak_rss_mb": rss / 2**20}


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
        out = subprocess.run([sys.executable, __file__, "--one", "--n", str(args.n), "--threads", str(threads)],
                             capture_output=True, text=True, check=True)
        results.append(json.loads(out.stdout.strip().splitlines()[-1]))
    # baseline RSS of the interpreter with numpy and the solver imported, to isolate the solver's share
    base = subprocess.run([sys.executable, "-c", "import resource, numpy, pygran_native.solver;"
                           "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"],
                          capture_output=True, text=True, check=True)
    base_mb = int(base.stdout) / 1024
    for res in results:
        res["rss_bytes_per_particle"] = (res["peak_rss_mb"] - base_mb) * 2**20 / args.n
        print(f"N={res['N']} threads={res['threads']}: settle {res['settle_pss'] / 1e6:.2f} M particle-steps/s, "
              f"dense bed {res['bed_pss'] / 1e6:.2f} M, coordination {res['coordination']:.2f}, "
              f"{res['rebuilds']} rebuilds, peak RSS {res['peak_rss_mb']:.0f} MB "
              f"({res['rss_bytes_per_particle']:.0f} B/particle above the interpreter), "
              f"solver arrays {res['solver_bytes_per_particle']:.0f} B/particle")
    if len(results) == 2:
        print(f"speed-up {results[1]['threads']}/1 threads: settle {results[1]['settle_pss'] / results[0]['settle_pss']:.2f}x, "
              f"dense bed {results[1]['bed_pss'] / results[0]['bed_pss']:.2f}x")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
