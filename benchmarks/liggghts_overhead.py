"""PyGran's LIGGGHTS engine against the bare ``liggghts`` binary on the settle scenario.

    .venv/bin/python benchmarks/liggghts_overhead.py [--n 20000] [--nprocs 1] [--repeat 3]

Runs the settle scenario of benchmarks/README.md (N spheres created one by one,
8,000 settling + 4,000 dense-bed steps, no output) as a PyGran script in a fresh Python
process, and the same simulation with the bare binary: the commands PyGran generated
(``in.pygran``) with its run chunks replaced by the script's two runs (``run 8000``,
``run 4000``), as a LIGGGHTS user would write it, so the chunking counts as overhead. Both
are timed as whole processes (start to exit: Python imports, worker start-up, round trips
and MPI start-up all count), alternately, ``--repeat`` times; the best of each gives the
ratio PyGran / bare. Each side's time inside LIGGGHTS' run loops (``Loop time`` in its
screen log) is reported too: the time outside the loops is the fixed cost, which a noisy
machine disturbs less than the ratio. ``--worker-mpi`` runs the bare binary with the MPI
settings PyGran's worker job starts with (``pygran_liggghts.session.WORKER_MPI``: Open MPI
without its cm PML, which saves both about 0.2 s of MPI start-up), to tell PyGran's own
overhead from that gain. Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from scenario import SIZES, STEPS, bare_command, bare_input, loop_times


def settle(n: int, nprocs: int, output: str) -> None:
    """The settle scenario as a PyGran script (run in its own process)."""
    from pygran_core.testing.validation import settle_setup

    with settle_setup("liggghts", Path(output), SIZES[n], nprocs=nprocs, progress=False) as sim:
        for steps in STEPS:
            sim.run(steps)


def timed(command: list[str], log: Path, env: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall seconds of ``command`` as a whole process, and its loop time from ``log``."""
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - start, sum(seconds for _, seconds in loop_times(log))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000, choices=sorted(SIZES))
    parser.add_argument("--nprocs", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=3, help="alternating runs of each; the best counts")
    parser.add_argument(
        "--worker-mpi", action="store_true", help="the bare binary with the MPI settings of PyGran's worker"
    )
    parser.add_argument("--one", metavar="OUTPUT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        settle(args.n, args.nprocs, args.one)
        return
    from pygran_liggghts.session import worker_env

    work = Path(tempfile.mkdtemp(prefix="liggghts-overhead-"))
    output = work / "settle"
    script = [sys.executable, __file__, "--n", str(args.n), "--nprocs", str(args.nprocs), "--one"]
    bare_log = work / "bare.log"
    load = [os.getloadavg()[0]]
    pygran, bare = [], []
    for _ in range(args.repeat):
        pygran.append(timed([*script, str(output)], output / "liggghts.log"))
        if not bare:
            bare_input(output / "in.pygran", work / "in.bare")
        bare.append(
            timed(
                bare_command(work / "in.bare", bare_log, args.nprocs),
                bare_log,
                worker_env() if args.worker_mpi else None,
            )
        )
        load.append(os.getloadavg()[0])
    shutil.rmtree(work)
    (p_wall, p_loop), (b_wall, b_loop) = min(pygran), min(bare)
    result = {
        "scenario": "settle",
        "N": args.n,
        "nprocs": args.nprocs,
        "bare_with_worker_mpi": args.worker_mpi,
        "repeat": args.repeat,
        "pygran_s": round(p_wall, 3),
        "bare_s": round(b_wall, 3),
        "ratio": round(p_wall / b_wall, 4),
        "pygran_outside_loops_s": round(p_wall - p_loop, 3),
        "bare_outside_loops_s": round(b_wall - b_loop, 3),
        "pygran_runs_s": [round(w, 3) for w, _ in pygran],
        "bare_runs_s": [round(w, 3) for w, _ in bare],
        "loadavg_1min": [round(v, 2) for v in load],
    }
    bare_mpi = " (worker's MPI settings)" if args.worker_mpi else ""
    print(
        f"settle N={args.n} on {args.nprocs} rank(s), best of {args.repeat}: PyGran {p_wall:.2f} s "
        f"({p_wall - p_loop:.2f} s outside run loops), bare liggghts{bare_mpi} {b_wall:.2f} s "
        f"({b_wall - b_loop:.2f} s outside), ratio {p_wall / b_wall:.3f}; "
        f"1-min load average {min(load):.2f}-{max(load):.2f}"
    )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
