"""Memory per particle and the time of each step of the settle scenario on the native engine,
through ``simulation.DEM`` as a user runs it (issue 45, items 1-2).

    .venv/bin/python benchmarks/native_memory.py --n 100000 --threads 2
    .venv/bin/python benchmarks/native_memory.py --start bed --n 1000000 10000000 --threads 2

Each N runs in a fresh process. Its baseline is the resident memory (RSS) once the same steps
have run on 200 particles (so what they import is loaded), before the simulation exists; each
step's peak is the process's high-water mark during that step (reset before it through
``/proc/self/clear_refs``) less the baseline. The steps: ``create`` (``DEM(...)`` and the
floor), ``insert`` (the start's positions made and given to ``createParticles``: they are the
script's, counted), ``settle`` (``--settle-steps``) and ``bed`` (``--bed-steps`` more),
``output`` (one H5MD frame of the trajectory's default columns, made from the extracts and
written with ``pygran_core.io.open_writer``) and ``extract`` (positions, velocities, angular
velocities, forces, radii and ids once each).

``--start lattice`` (default) is the settle scenario of README.md: the lattice, 8,000 settling
steps and 4,000 of the dense bed. ``--start bed`` starts from the dense bed: the 20,000
particles of the scenario after both phases (run once with 2 threads and kept in ``--bed``),
repeated along the periodic x and y to N and created at rest 0.3 mm above the floor (see
tiled_bed), then runs ``--bed-steps`` (1000): it falls onto the floor and rebuilds its lists on
the way (with the bed's previous lists held, as the settle's rebuilds hold them), at a fraction
of the settle's time.

Prints per N the seconds and peak bytes per particle of each step, the solver's allocations
(capacity) by part after the last run, the listed pairs, contacts and wall entries per
particle, then one JSON line per N. Times are wall seconds, indicative on a shared machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scenario import SIZES

from pygran_core.io import Frame, open_writer
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.validation import (
    GRAVITY,
    RADIUS,
    SETTLE_SPACING,
    SOFT,
    one_species,
    settle_positions,
)

#: The lattices (NX, NY, NZ) of each N: the settle scenario's, and 10^7.
SHAPES = {**SIZES, 10_000_000: (1000, 1000, 10)}
STEPS = ("create", "insert", "settle", "bed", "output", "extract")
#: The dense bed that ``--start bed`` repeats: the scenario's N.
TILE = 20_000


def status_kib(field: str) -> int:
    """A ``/proc/self/status`` figure (``VmRSS``, ``VmHWM``) in KiB."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise SystemExit(f"no {field} in /proc/self/status: this script needs Linux")


def reset_peak() -> None:
    """Make the high-water mark the current RSS (Linux 4.0 and later)."""
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")


class Steps:
    """Each step's wall seconds and peak RSS over the baseline (bytes)."""

    def __init__(self) -> None:
        self.baseline = status_kib("VmRSS") * 1024
        self.seconds: dict[str, float] = {}
        self.peak: dict[str, int] = {}

    def __call__(self, name: str, action: Callable[[], Any]) -> Any:
        reset_peak()
        start = time.perf_counter()
        result = action()
        self.seconds[name] = time.perf_counter() - start
        self.peak[name] = status_kib("VmHWM") * 1024 - self.baseline
        return result


def create(output: Path, shape: tuple[int, int, int], threads: int):
    """``validation.settle_setup`` for an ``NX x NY x NZ = shape`` lattice, without its particles."""
    nx, ny, nz = shape
    sim = one_species(
        "native",
        output,
        SOFT,
        RADIUS,
        model=HertzMindlin,
        box=(0.0, nx * SETTLE_SPACING, 0.0, ny * SETTLE_SPACING, 0.0, (nz + 3) * SETTLE_SPACING),
        boundary=("p", "p", "f"),
        gravity=GRAVITY,
        dt=1e-5,
        nns_skin=4e-4,
        threads=threads,
    )
    sim.setupWall(species=1, plane="zplane", peq=0.0)
    return sim


def settled_bed(path: Path) -> np.ndarray:
    """The positions of the scenario's 20,000 particles after both phases (made with 2 threads
    and kept in ``path`` on first use)."""
    if not path.exists():
        with tempfile.TemporaryDirectory() as folder, create(Path(folder), SIZES[TILE], 2) as sim:
            sim.createParticles(1, "single", settle_positions(SIZES[TILE]))
            sim.run(8000)
            sim.run(4000)
            np.save(path, sim.extractCoords())
    return np.load(path)


def tiled_bed(n: int, path: Path) -> np.ndarray:
    """N positions: the settled bed repeated along the periodic x and y, its heights stretched by
    0.5 % (its deepest contacts overlap by just over what createParticles accepts, 1 % of the
    radius) and raised by 0.3 mm (it falls further than half the skin, so the lists are rebuilt
    with the bed's lists as the previous ones)."""
    tile, shape = np.array(SIZES[TILE][:2]), np.array(SHAPES[n][:2])
    if SHAPES[n][2] != SIZES[TILE][2] or np.any(shape % tile):
        raise SystemExit(f"N = {n} is not a tiling of the {TILE}-particle bed")
    bed = settled_bed(path)
    bed[:, :2] %= tile * SETTLE_SPACING  # into the tile: a run wraps positions at its rebuilds only
    bed[:, 2] = bed[:, 2] * 1.005 + 3e-4
    shifts = np.stack(np.meshgrid(*(np.arange(k) for k in shape // tile), indexing="ij"), -1).reshape(-1, 2)
    offsets = np.zeros((len(shifts), 1, 3))
    offsets[:, 0, :2] = shifts * tile * SETTLE_SPACING
    return (bed[None] + offsets).reshape(-1, 3)


def measure(n: int, args: argparse.Namespace) -> dict:
    """The steps at N = ``n`` in this process (see the module docstring), after the same steps
    on 200 particles, which load what the steps import."""
    with tempfile.TemporaryDirectory() as folder:
        run_steps(
            Path(folder), (10, 10, 2), lambda: settle_positions((10, 10, 2)), 2, 20, args.threads, Steps()
        )
    positions = (
        (lambda: tiled_bed(n, args.bed)) if args.start == "bed" else (lambda: settle_positions(SHAPES[n]))
    )
    steps = Steps()
    with tempfile.TemporaryDirectory() as folder:
        found = run_steps(
            Path(folder), SHAPES[n], positions, args.settle_steps, args.bed_steps, args.threads, steps
        )
    return {
        "N": n,
        "start": args.start,
        "threads": args.threads,
        "steps": [args.settle_steps, args.bed_steps],
        "baseline_mb": steps.baseline / 2**20,
        "seconds": steps.seconds,
        "peak_bytes_per_particle": {k: v / n for k, v in steps.peak.items()},
        "solver_bytes_per_particle": {k: v / n for k, v in found["memory"].items()},
        "listed_pairs_per_particle": found["pairs"] / n,
        "wall_entries_per_particle": found["walls"] / n,
        "contacts_per_particle": found["contacts"] / n,
        "rebuilds": found["rebuilds"],
        "particle_steps_per_second": {
            phase: n * count / steps.seconds[phase]
            for phase, count in (("settle", args.settle_steps), ("bed", args.bed_steps))
            if count
        },
    }


def run_steps(
    output: Path,
    shape: tuple[int, int, int],
    positions: Callable[[], np.ndarray],
    settle: int,
    bed: int,
    threads: int,
    steps: Steps,
) -> dict:
    """The steps on a box of the lattice ``shape``, each timed by ``steps``; the solver's
    allocations by part, its list entries and contacts after the last run."""
    sim = steps("create", lambda: create(output, shape, threads))
    try:
        steps("insert", lambda: sim.createParticles(1, "single", positions()))
        for name, count in (("settle", settle), ("bed", bed)):
            if count:
                steps(name, lambda count=count: sim.run(count))
        solver = sim.engine.solver
        pairs, walls = solver.list_entries
        found = {
            "memory": solver.memory,
            "pairs": pairs,
            "walls": walls,
            "contacts": len(solver.contacts()[0]),
            "rebuilds": solver.rebuilds,
        }
        steps("output", lambda: write_frame(sim, output / "frame.h5"))
        steps(
            "extract",
            lambda: [
                sim.extractCoords(),
                sim.extractVelocities(),
                sim.extractOmegas(),
                sim.extractForces(),
                sim.extractRadii(),
                sim.extractIds(),
            ],
        )
    finally:
        sim.close()
    return found


def write_frame(sim, path: Path) -> None:
    """One H5MD frame of the trajectory's default columns, as ``traj={'pfile': '....h5'}``
    writes them."""
    x, v, w, f = sim.extractCoords(), sim.extractVelocities(), sim.extractOmegas(), sim.extractForces()
    radius = sim.extractRadii()
    mass = sim.engine.extract("mass")
    columns = {"id": sim.extractIds(), "type": sim.engine.extract("type")}
    for names, values in (("x y z", x), ("vx vy vz", v), ("fx fy fz", f), ("omegax omegay omegaz", w)):
        columns.update(zip(names.split(), values.T))
    columns |= {"radius": radius, "mass": mass, "density": mass / (4 / 3 * np.pi * radius**3)}
    writer = open_writer(path)
    try:
        writer.write_frame(Frame(columns, timestep=sim.step, time=sim.time))
    finally:
        writer.close()


def in_own_process(n: int, args: argparse.Namespace) -> dict:
    command = [sys.executable, __file__, "--one", "--n", str(n), "--threads", str(args.threads)]
    command += ["--start", args.start, "--bed", str(args.bed)]
    command += ["--settle-steps", str(args.settle_steps), "--bed-steps", str(args.bed_steps)]
    done = subprocess.run(command, check=True, stdout=subprocess.PIPE, text=True)
    return json.loads(done.stdout.splitlines()[-1])


def report(result: dict) -> None:
    settle, bed = result["steps"]
    per_particle = {k: result[f"{k}_per_particle"] for k in ("listed_pairs", "contacts", "wall_entries")}
    print(
        f"N = {result['N']:,} from the {result['start']} ({settle} + {bed} steps, "
        f"{result['threads']} threads, {result['rebuilds']} rebuilds; "
        f"baseline {result['baseline_mb']:.0f} MB): per particle "
        + ", ".join(f"{value:.2f} {name.replace('_', ' ')}" for name, value in per_particle.items())
    )
    print(f"  {'step':8s} {'seconds':>9s} {'peak B/particle':>16s}")
    for name, seconds in result["seconds"].items():
        print(f"  {name:8s} {seconds:9.2f} {result['peak_bytes_per_particle'][name]:16.0f}")
    speeds = result["particle_steps_per_second"]
    print(
        "  " + ", ".join(f"{phase} {pss / 1e6:.2f}" for phase, pss in speeds.items()) + " M particle-steps/s"
    )
    parts = result["solver_bytes_per_particle"]
    print("  solver's allocations, B/particle: " + ", ".join(f"{k} {v:.0f}" for k, v in parts.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[100_000], choices=sorted(SHAPES))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--start", choices=("lattice", "bed"), default="lattice")
    parser.add_argument("--settle-steps", type=int, help="default 8000 from the lattice, 0 from the bed")
    parser.add_argument("--bed-steps", type=int, help="default 4000 from the lattice, 1000 from the bed")
    parser.add_argument("--bed", type=Path, default=Path(tempfile.gettempdir()) / "pygran_settled_bed.npy")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    lattice = args.start == "lattice"
    args.settle_steps = (8000 if lattice else 0) if args.settle_steps is None else args.settle_steps
    args.bed_steps = (4000 if lattice else 1000) if args.bed_steps is None else args.bed_steps
    if args.one:
        print(json.dumps(measure(args.n[0], args)))
        return
    if not lattice:
        settled_bed(args.bed)  # made once, before any measurement
    results = [in_own_process(n, args) for n in args.n]
    for result in results:
        report(result)
    for result in results:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
