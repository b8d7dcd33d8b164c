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

SIZES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10)}


def settle(n: int, nprocs: int, output: str) -> None:
    """The settle scenario through PyGran."""
    from pygran_core.validation import settle_setup

    with settle_setup("liggghts", Path(output), SIZES[n], nprocs=nprocs) as sim:
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
