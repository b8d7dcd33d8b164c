"""PyGran's LIGGGHTS engine against the bare ``liggghts`` binary on the settle scenario.

Runs shared/benchmarks/settle.md (8,000 settling + 4,000 dense-bed steps, no output)
through ``simulation.DEM(engine='liggghts')`` in a fresh Python process, then the input
PyGran generated (``in.pygran``) with ``liggghts -in``, and prints the wall-time ratio
PyGran / bare (process start to exit for both, so PyGran's imports, worker start-up and
per-call round trips all count).

    .venv/bin/python benchmarks/liggghts_overhead.py --n 5000 --nprocs 1
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SIZES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10)}
R = 1e-3
MATERIAL = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.45,
    "coefficientRestitution": 0.3,
    "coefficientFriction": 0.5,
    "density": 2500.0,
}


def settle(n: int, nprocs: int, output: str, seed: int = 12345) -> None:
    """The settle scenario through PyGran."""
    from pygran_core import simulation

    nx, ny, nz = SIZES[n]
    a = 1.1 * 2 * R
    grid = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(
        -1, 3
    )
    x = (grid + 0.5) * a + np.random.default_rng(seed).uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * R)
    with simulation.DEM(
        engine="liggghts",
        model=simulation.models.HertzMindlin,
        nprocs=nprocs,
        box=(0, nx * a, 0, ny * a, 0, (nz + 3) * a),
        boundary=("p", "p", "f"),
        gravity=(9.81, 0, 0, -1),
        dt=1e-5,
        nns_skin=4e-4,
        output=output,
        species=({"material": MATERIAL, "radius": R},),
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        for position in x:
            sim.createParticles(1, "single", *position)
        sim.run(8000)
        sim.run(4000)


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5000, choices=sorted(SIZES))
    parser.add_argument("--nprocs", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=2, help="alternating runs of each; the best counts")
    parser.add_argument("--one", metavar="OUTPUT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        settle(args.n, args.nprocs, args.one)
        return
    from pygran_liggghts.session import mpirun_prefix

    work = Path(tempfile.mkdtemp(prefix="liggghts-overhead-"))
    output = work / "settle"
    launcher = mpirun_prefix(args.nprocs) if args.nprocs > 1 else []
    binary = shutil.which("liggghts") or "/usr/bin/liggghts"
    pygran, bare = [], []
    for _ in range(args.repeat):
        pygran.append(
            timed(
                [
                    sys.executable,
                    __file__,
                    "--n",
                    str(args.n),
                    "--nprocs",
                    str(args.nprocs),
                    "--one",
                    str(output),
                ]
            )
        )
        bare.append(
            timed(
                [
                    *launcher,
                    binary,
                    "-in",
                    str(output / "in.pygran"),
                    "-screen",
                    str(work / "bare.log"),
                    "-log",
                    "none",
                ]
            )
        )
    print(
        f"settle N={args.n} on {args.nprocs} rank(s): PyGran {min(pygran):.2f} s, bare liggghts "
        f"{min(bare):.2f} s, ratio {min(pygran) / min(bare):.3f} (all runs: {pygran} / {bare})"
    )
    shutil.rmtree(work)


if __name__ == "__main__":
    main()
