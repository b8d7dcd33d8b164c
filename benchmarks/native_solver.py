"""The settle scenario of benchmarks/README.md run directly on the native Solver.

Prints particle-steps/s of the settling (8,000 steps) and dense-bed (4,000 steps) phases
for 1 thread and for ``--threads`` threads (each in a fresh process), the speed-up, the
coordination number, the peak RSS growth per particle from creating and running the
solver (inputs are built before the baseline is taken), the load average, and per phase the
solver's timers (:attr:`Solver.timings`: wall seconds per phase, and each thread's CPU
seconds in the pair and particle loops, which show the load balance even on a busy
machine; with the busiest thread's sum, ``forces_span``, they estimate the run's time on
idle cores, from below: waits are not CPU time). ``--chunk 80`` calls ``Solver.run`` with at
most 80 steps, as ``simulation.DEM`` does (100 calls per run). ``--repeats 3`` alternates the
thread counts three times and keeps the fastest run of each: on a shared host identical runs
vary by 15 %.

    .venv/bin/python benchmarks/native_solver.py --n 20000 --threads 2 --repeats 3

``--variants`` compares variants instead, each ``THREADS[@BUILD]``: a thread count and a
build (a directory put first on ``PYTHONPATH``, holding ``pygran_native`` compiled from other
sources; default: the installed one). For each ``--n`` (several may be given), on the machine as it is
and while a busy loop holds a core (``--busy``), every case runs in a fresh process, the
variants taking turns (their order alternating per round) so that a drifting host slows each
alike. Its phases are short: ``--settle-steps`` from the lattice, and ``--bed-steps`` on a
dense bed, the 20,000-particle lattice after the 8,000 settling steps (made once and kept in
``--bed``) tiled along x and y to N (its contact histories start afresh); with
``--rolling-friction`` (cdt) the pair loop takes its per-contact path instead of batches.
Prints each round, then per case the median particle-steps/s of each variant and its ratio to
the first, then one JSON line.

    .venv/bin/python benchmarks/native_solver.py --variants 2 1 --n 20000 1000000 --busy
    .venv/bin/python benchmarks/native_solver.py --variants 2 2@/tmp/old/src --n 20000
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pygran_native.solver import Solver
from scenario import SIZES, STEPS, busy_loop

RADIUS, SPACING, DT = 1e-3, 2.2e-3, 1e-5


def lattice(n: int, seed: int = 12345) -> tuple[np.ndarray, np.ndarray]:
    """Box and perturbed simple-cubic lattice positions of the scenario."""
    nx, ny, nz = SIZES[n]
    box = np.array([[0, 0, 0], [nx * SPACING, ny * SPACING, (nz + 3) * SPACING]])
    grid = np.indices((nx, ny, nz)).reshape(3, -1).T
    rng = np.random.default_rng(seed)
    x = (grid + 0.5) * SPACING + rng.uniform(-1, 1, grid.shape) * 0.45 * (SPACING - 2 * RADIUS)
    return box, x


def scenario(box: np.ndarray, x: np.ndarray, threads: int, v=None, w=None, rolling: float = 0.0):
    """The solver of the scenario: Hertz-Mindlin with history, periodic x and y, a floor; with
    ``rolling`` friction (cdt) the pair loop takes the per-contact path instead of batches."""
    solver = Solver(
        box=box,
        periodic=(True, True, False),
        gravity=(0, 0, -9.81),
        skin=4e-4,
        threads=threads,
    )
    solver.set_contact_model(
        "hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5, rolling_friction=rolling
    )
    solver.add_plane((0, 0, 0), (0, 0, 1), 0)
    solver.add_particles(x, RADIUS, densities=2500, velocities=v, omegas=w)
    return solver


def settled_bed(path: Path) -> dict[str, np.ndarray]:
    """The 20,000-particle lattice after the settling phase: positions, velocities, angular
    velocities (made with 2 threads and kept in ``path`` on first use)."""
    if not path.exists():
        solver = scenario(*lattice(20000), threads=2)
        solver.run(STEPS[0], DT)
        np.savez(path, x=solver.positions, v=solver.velocities, w=solver.omegas)
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def tiled_bed(n: int, bed: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Box and state of N particles: the settled bed repeated along the periodic x and y."""
    tile = np.array(SIZES[20000][:2])
    reps = np.array(SIZES[n][:2]) // tile
    if SIZES[n][2] != SIZES[20000][2] or not np.array_equal(reps * tile, SIZES[n][:2]):
        raise SystemExit(f"N = {n} is not a tiling of the 20,000-particle bed")
    box, _ = lattice(n)
    shifts = [
        np.array([i, j, 0]) * SPACING
        for i in range(0, reps[0] * tile[0], tile[0])
        for j in range(0, reps[1] * tile[1], tile[1])
    ]
    return box, {
        "x": np.concatenate([bed["x"] + shift for shift in shifts]),
        "v": np.tile(bed["v"], (len(shifts), 1)),
        "w": np.tile(bed["w"], (len(shifts), 1)),
    }


def measure_variant(n: int, threads: int, steps: tuple[int, int], bed_path: Path, rolling: float) -> dict:
    """Particle-steps/s of ``steps[0]`` settling steps from the lattice and ``steps[1]`` steps
    of the tiled dense bed (each after a first call that builds the lists)."""
    solver = scenario(*lattice(n), threads=threads, rolling=rolling)
    solver.run(0, DT)
    settle = advance(solver, steps[0], steps[0])
    box, state = tiled_bed(n, settled_bed(bed_path))
    solver = scenario(box, state["x"], threads, state["v"], state["w"], rolling)
    solver.run(1, DT)
    bed = advance(solver, steps[1], steps[1])
    return {
        "N": n,
        "settle_pss": n * steps[0] / settle["wall"],
        "bed_pss": n * steps[1] / bed["wall"],
        "solo_steps": settle["solo_steps"] + bed["solo_steps"],
    }


def run_case(args: argparse.Namespace, n: int, variant: str) -> dict:
    """:func:`measure_variant` of ``variant`` (``THREADS[@BUILD]``) in a fresh process."""
    threads, _, build = variant.partition("@")
    command = [sys.executable, __file__, "--one-variant", "--n", str(n), "--threads", threads]
    command += ["--bed", str(args.bed)]
    command += ["--settle-steps", str(args.settle_steps), "--bed-steps", str(args.bed_steps)]
    command += ["--rolling-friction", str(args.rolling_friction)]
    env = dict(os.environ)
    if build:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, (build, env.get("PYTHONPATH"))))
    out = subprocess.run(command, capture_output=True, text=True, check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare_variants(args: argparse.Namespace) -> None:
    """Each variant in turn on each case (N, busy loop or not), ``--repeats`` rounds."""
    settled_bed(args.bed)  # made before any timing
    pss: dict[tuple[int, bool, str], dict[str, list[float]]] = {}
    print(f"threads {args.threads}; load average before: {os.getloadavg()[0]:.2f}", flush=True)
    loads = (False, True) if args.busy else (False,)
    for round_, n, busy in itertools.product(range(args.repeats), args.n, loads):
        order = args.variants if round_ % 2 == 0 else args.variants[::-1]
        loop = busy_loop() if busy else None
        try:
            time.sleep(0.5 if busy else 0)
            for variant in order:
                res = run_case(args, n, variant)
                case = pss.setdefault((n, busy, variant), {"settle": [], "bed": []})
                case["settle"].append(res["settle_pss"])
                case["bed"].append(res["bed_pss"])
                print(
                    f"  round {round_ + 1}, N={n}, {'busy' if busy else 'quiet'}, {variant}: settle "
                    f"{res['settle_pss'] / 1e6:.2f}, bed {res['bed_pss'] / 1e6:.2f} M particle-steps/s "
                    f"(steps alone: {res['solo_steps']}; load {os.getloadavg()[0]:.2f})",
                    flush=True,
                )
        finally:
            if loop is not None:
                loop.kill()
                loop.wait()
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(f"medians of {args.repeats} round(s), M particle-steps/s, ratio to {args.variants[0]}:")
    table = []
    for (n, busy, variant), phases in pss.items():
        for phase, values in phases.items():
            median = statistics.median(values)
            first = statistics.median(pss[n, busy, args.variants[0]][phase])
            row = {"variant": variant, "N": n, "scenario": phase, "busy": busy, "pss": median}
            table.append(row | {"ratio": median / first})
            print(
                f"  {variant:12s} N={n:<8d} {phase:7s} {'busy' if busy else 'quiet':6s} "
                f"{median / 1e6:7.3f} {median / first:6.3f}"
            )
    print(json.dumps(table))


def rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def advance(solver: Solver, steps: int, chunk: int) -> dict:
    """Run ``steps`` in calls of at most ``chunk`` steps; the solver's phase timings of it,
    and ``wall``, the seconds of the calls."""
    before = solver.timings
    start = time.perf_counter()
    for done in range(0, steps, chunk):
        solver.run(min(chunk, steps - done), DT)
    wall = time.perf_counter() - start
    timings = {
        k: (v - before[k]).tolist() if isinstance(v, np.ndarray) else v - before[k]
        for k, v in solver.timings.items()
    }
    return timings | {"wall": wall}


def measure(n: int, threads: int, chunk: int) -> dict:
    box, x = lattice(n)
    baseline = rss_bytes()
    solver = scenario(box, x, threads)
    solver.run(0, DT)
    settle, bed = (advance(solver, steps, chunk) for steps in STEPS)
    grown = rss_bytes() - baseline
    return {
        "N": solver.n,
        "threads": threads,
        "settle_pss": n * STEPS[0] / settle["wall"],
        "bed_pss": n * STEPS[1] / bed["wall"],
        "settle_timings": settle,
        "bed_timings": bed,
        "coordination": 2 * len(solver.contacts()[0]) / solver.n,
        "lost": solver.lost,
        "rebuilds": solver.rebuilds,
        "rss_bytes_per_particle": grown / n,
        "solver_bytes_per_particle": solver.memory_bytes / n,
    }


def idle_seconds(timings: dict) -> float:
    """The calls' estimated wall time on idle cores: the pair and particle loops taking their
    busiest thread's CPU time (``forces_span``, waits left out) instead of their wall time."""
    return timings["wall"] + timings["forces_span"] - timings["pairs"] - timings["particles"]


def breakdown(timings: dict) -> str:
    """One line of phase timings: seconds and share of the run, and :func:`idle_seconds`."""
    run = timings["run"]
    phases = ("pairs", "particles", "drift", "walls", "rebuild")
    parts = [f"{k} {timings[k]:.2f} s ({100 * timings[k] / run:.1f}%)" for k in phases]
    rebuild = [f"{k[8:]} {timings[k]:.3f}" for k in timings if k.startswith("rebuild_")]
    other = run - sum(timings[k] for k in phases)
    cpu = [f"{k} " + "/".join(f"{t:.2f}" for t in timings[f"{k}_cpu"]) for k in ("pairs", "particles")]
    cpu[-1] += f" (span of both {timings['forces_span']:.2f})"
    return (
        f"calls {timings['wall']:.2f} s, outside the solver's loop {timings['wall'] - run:.3f} s; "
        f"run {run:.2f} s (idle cores: {idle_seconds(timings):.2f} s): "
        + ", ".join(parts)
        + f", other {other:.3f} s; "
        f"rebuild parts: {', '.join(rebuild)}; CPU s per thread: {', '.join(cpu)}; "
        f"steps without the team {timings['solo_steps']}, moves off a teammate's CPU {timings['moves']}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=[20000], choices=sorted(SIZES), nargs="+")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--chunk", type=int, default=8000, help="most steps per Solver.run call")
    parser.add_argument("--one", action="store_true", help="run one measurement in this process")
    parser.add_argument("--repeats", type=int, default=1, help="alternating runs per thread count; best kept")
    parser.add_argument("--variants", nargs="+", help="compare THREADS[@BUILD] variants")
    parser.add_argument("--busy", action="store_true", help="with --variants: also under a busy loop")
    parser.add_argument("--settle-steps", type=int, default=2000, help="with --variants")
    parser.add_argument("--bed-steps", type=int, default=1000, help="with --variants")
    parser.add_argument("--rolling-friction", type=float, default=0.0, help="with --variants")
    parser.add_argument(
        "--bed", type=Path, default=Path(tempfile.gettempdir()) / "pygran_settled_bed_20000.npz"
    )
    parser.add_argument("--one-variant", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one_variant:
        steps = (args.settle_steps, args.bed_steps)
        variant = (args.threads, steps, args.bed, args.rolling_friction)
        print(json.dumps(measure_variant(args.n[0], *variant)))
        return
    if args.variants:
        compare_variants(args)
        return
    (args.n,) = args.n
    if args.one:
        print(json.dumps(measure(args.n, args.threads, args.chunk)))
        return
    # the thread counts take turns, so a host whose speed drifts slows both alike; per thread
    # count, the run with the fastest settling phase is kept
    best: dict[int, dict] = {}
    for _ in range(args.repeats):
        for threads in sorted({1, args.threads}):
            command = [sys.executable, __file__, "--one", "--n", str(args.n), "--threads", str(threads)]
            command += ["--chunk", str(args.chunk)]
            load = os.getloadavg()[0]
            out = subprocess.run(command, capture_output=True, text=True, check=True)
            res = json.loads(out.stdout.strip().splitlines()[-1])
            res["load"] = (load, os.getloadavg()[0])
            print(
                f"  threads={threads}: settle {res['settle_pss'] / 1e6:.2f}, "
                f"dense bed {res['bed_pss'] / 1e6:.2f} M particle-steps/s"
            )
            if threads not in best or res["settle_pss"] > best[threads]["settle_pss"]:
                best[threads] = res
    results = [best[threads] for threads in sorted(best)]
    for res in results:
        load = res["load"][0]
        print(
            f"N={res['N']} threads={res['threads']} (best of {args.repeats}; load average {load:.2f} -> "
            f"{res['load'][1]:.2f}): "
            f"settle {res['settle_pss'] / 1e6:.2f} M particle-steps/s, "
            f"dense bed {res['bed_pss'] / 1e6:.2f} M, coordination {res['coordination']:.2f}, "
            f"{res['rebuilds']} rebuilds, "
            f"peak RSS growth {res['rss_bytes_per_particle']:.0f} B/particle "
            f"(solver allocation {res['solver_bytes_per_particle']:.0f} B/particle)"
        )
        for phase in ("settle", "bed"):
            print(f"  {phase}: {breakdown(res[f'{phase}_timings'])}")
    if len(results) == 2:
        one, many = results
        idle = [
            idle_seconds(one[f"{phase}_timings"]) / idle_seconds(many[f"{phase}_timings"])
            for phase in ("settle", "bed")
        ]
        print(
            f"speed-up {many['threads']}/1 threads: settle {many['settle_pss'] / one['settle_pss']:.2f}x, "
            f"dense bed {many['bed_pss'] / one['bed_pss']:.2f}x; "
            f"estimated on idle cores: settle {idle[0]:.2f}x, dense bed {idle[1]:.2f}x"
        )
    print(json.dumps(results))


if __name__ == "__main__":
    main()
