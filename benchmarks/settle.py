"""The settle scenario of ``benchmarks/README.md`` through ``simulation.DEM`` on any engine.

    python benchmarks/settle.py --engine native --n 20000 --threads 1
    python benchmarks/settle.py --engine liggghts --n 20000
    python benchmarks/settle.py --engine native --against liggghts --n 20000 --threads 1 --repeats 3
    python benchmarks/settle.py --engine native --against liggghts-bare --n 20000 --threads 1 --repeats 3

Prints particle-steps per second (N x steps / wall seconds of the loop) for the settling
phase (8,000 steps from the lattice) and the dense-bed phase (4,000 more), the peak memory
and the mean coordination number (not for ``liggghts-bare``), then one JSON line:
``{"engine", "N", "threads", "settle_pss", "bed_pss", "peak_rss_mb", "coordination"}``.

With ``--against``, the two engines run alternately, each run in a fresh process with the
same ``--threads`` (threads, or MPI ranks for LIGGGHTS), ``--repeats`` rounds; it prints
each round's ratios ``--engine`` / ``--against`` per phase (the host's speed drifts between
rounds, not within one), their median and the ratio of each engine's best, then one JSON
line. ``liggghts`` runs LIGGGHTS through PyGran. ``liggghts-bare`` runs the bare ``liggghts``
binary (``mpirun`` for more ranks) on the commands PyGran generated for the scenario, with its
two runs as a LIGGGHTS user writes them (``run 8000``, ``run 4000``), and takes each phase's
time from LIGGGHTS' own ``Loop time`` line: what the binary spends stepping, without start-up,
particle creation or the set-up of a run.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scenario import SIZES, STEPS, bare_command, bare_input, loop_times

from pygran_core.analysis import Particles
from pygran_core.analysis.equilibrium import Neighbors
from pygran_core.testing.validation import settle_setup

BARE = "liggghts-bare"


def run(engine: str, n: int, threads: int | None) -> dict:
    if engine == BARE:
        return run_bare(n, threads or 1)
    # threads=None: the engine's default (settle_setup's own default is one thread)
    parallel = {"nprocs": threads} if engine == "liggghts" else {"threads": threads}
    with tempfile.TemporaryDirectory() as output:
        start = time.perf_counter()
        with settle_setup(engine, Path(output), SIZES[n], **parallel) as sim:
            created = time.perf_counter() - start
            assert len(sim.extractIds()) == n
            workers = sim.engine._facts().get("threads", threads or 1)
            timings = []
            for steps in STEPS:
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


def run_bare(n: int, ranks: int) -> dict:
    """The scenario on the bare ``liggghts`` binary (scenario.bare_input: the commands
    PyGran's LIGGGHTS engine generates for it, then its two runs); each phase's particle-steps
    per second from its ``Loop time`` line."""
    with tempfile.TemporaryDirectory() as output:
        work = Path(output)
        with settle_setup("liggghts", work / "pygran", SIZES[n], nprocs=ranks):
            pass  # closing writes the last queued commands
        bare_input(work / "pygran" / "in.pygran", work / "in.bare")
        log = work / "bare.log"
        subprocess.run(bare_command(work / "in.bare", log, ranks), check=True, stdout=subprocess.DEVNULL)
        loops = loop_times(log)
    if [steps for steps, _ in loops] != list(STEPS):
        raise SystemExit(f"expected loop times of runs {STEPS} in LIGGGHTS' log, found {loops}")
    settle, bed = (n * steps / seconds for steps, seconds in loops)
    return {
        "engine": BARE,
        "N": n,
        "threads": ranks,
        "settle_pss": settle,
        "bed_pss": bed,
        "peak_rss_mb": None,
        "coordination": None,
        "create_s": None,
    }


PHASES = ("settle", "bed")


def in_own_process(engine: str, n: int, threads: int | None) -> dict:
    """:func:`run` in a fresh Python process (its JSON line)."""
    command = [sys.executable, __file__, "--engine", engine, "--n", str(n)]
    if threads is not None:
        command += ["--threads", str(threads)]
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    return json.loads(done.stdout.splitlines()[-1])


def compare(engine: str, against: str, n: int, threads: int | None, repeats: int) -> dict:
    """``engine`` against ``against``, alternately in their own processes: each round's
    ratios per phase, their median, and the ratio of each engine's best."""
    rounds = []
    for r in range(repeats):
        pair = {name: in_own_process(name, n, threads) for name in (engine, against)}
        ratios = {p: pair[engine][f"{p}_pss"] / pair[against][f"{p}_pss"] for p in PHASES}
        rounds.append({"runs": pair, "ratios": ratios})
        print(
            f"round {r + 1}: "
            + "; ".join(
                f"{p} {pair[engine][f'{p}_pss'] / 1e6:.2f} / {pair[against][f'{p}_pss'] / 1e6:.2f} M "
                f"particle-steps/s = {ratios[p]:.2f}"
                for p in PHASES
            )
        )
    best = {
        name: {p: max(r["runs"][name][f"{p}_pss"] for r in rounds) for p in PHASES}
        for name in (engine, against)
    }
    return {
        "engine": engine,
        "against": against,
        "N": n,
        "threads": threads,
        "repeats": repeats,
        "round_ratios": [{p: round(r["ratios"][p], 3) for p in PHASES} for r in rounds],
        "median_ratio": {p: round(statistics.median(r["ratios"][p] for r in rounds), 3) for p in PHASES},
        "best_ratio": {p: round(best[engine][p] / best[against][p], 3) for p in PHASES},
        "best_pss": best,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default="native")
    parser.add_argument("--against", help="a second engine: run both alternately and print the ratios")
    parser.add_argument("--repeats", type=int, default=3, help="rounds with --against")
    parser.add_argument("--n", type=int, default=5000, choices=sorted(SIZES))
    parser.add_argument("--threads", type=int, help="threads (native, yade) or MPI ranks (liggghts)")
    args = parser.parse_args()
    if args.against:
        result = compare(args.engine, args.against, args.n, args.threads, args.repeats)
        print(
            f"{args.engine} / {args.against}, N = {args.n}, threads/ranks = {args.threads or 'default'}, "
            f"{args.repeats} rounds: median "
            + ", ".join(f"{p} {result['median_ratio'][p]:.2f}" for p in PHASES)
            + "; best of each "
            + ", ".join(f"{p} {result['best_ratio'][p]:.2f}" for p in PHASES)
        )
        print(json.dumps(result))
        return
    result = run(args.engine, args.n, args.threads)
    print(f"{args.engine}: N = {args.n}, threads/ranks = {result['threads']}")
    print(f"  settle    {result['settle_pss'] / 1e6:6.2f} M particle-steps/s")
    print(f"  dense bed {result['bed_pss'] / 1e6:6.2f} M particle-steps/s")
    if result["engine"] != BARE:
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
