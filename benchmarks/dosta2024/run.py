"""Run a case of Dosta et al. (2024) on one engine, or compare the engines' results.

    python benchmarks/dosta2024/run.py penetration --engine liggghts --size 25k --until 0.1 --out results/
    python benchmarks/dosta2024/run.py drum --engine native --size soft --until 5 --out results/ --resume
    python benchmarks/dosta2024/run.py silo --engine native --size small-M1 --until 5 --out results/
    python benchmarks/dosta2024/run.py compare results/

Sizes: penetration ``25k``, ``50k``; drum ``stiff``, ``soft``; silo ``small-M1``, ``small-M2``,
``large-M1``, ``large-M2`` (the cases are in ``cases.py``). A run writes into ``OUT``:
``<case>-<engine>.csv`` (``time,<columns>``: the paper's observable at the paper's interval,
written as it goes), ``<case>-<engine>.json`` (set-up time, the runs' wall time and particle-
steps per second, the engine's settings) and the simulation's own folder ``<case>-<engine>/``
(``pygran.log`` with progress lines, checkpoints every 10,000 steps or ``--checkpoint`` seconds
of simulated time on the engines with restart, every engine here; ``--resume`` continues from
the newest, within a recording interval too).
The silo's fill is made once, by pouring on the native engine with a fixed seed, and kept as
``OUT/silo-<orifice>-<material>-fill.txt`` for every engine (``--fill N`` pours N spheres
instead of 100,000, for a quick try). ``--jitter 1e-9`` moves every particle by up to 1e-9 m
at the start (seeded) and writes ``<engine>+jitter``: against the unjittered run of the same
engine it shows how far the case's own chaos carries two runs apart, the floor under any
agreement of two engines.
``compare`` overlays the engines' CSVs, one PNG per case, and prints the agreement table: per
case and column the largest difference of each engine from the first engine's values (a
jittered run: from its own engine's) at the common times.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

import cases
import gates

from pygran_core import registry, simulation

#: Steps between checkpoints: at most about an hour of YADE's slowest case (the 100,000
#: spheres of the silo) is run again after a stop.
CHECKPOINT_STEPS = 10_000
SIZES = {
    "penetration": ("25k", "50k"),
    "drum": ("stiff", "soft"),
    "silo": ("small-M1", "small-M2", "large-M1", "large-M2"),
}


def build(case: str, size: str, out: Path, fill: int, jitter: float) -> cases.Case:
    if size not in SIZES[case]:
        raise SystemExit(f"{case} sizes: {', '.join(SIZES[case])}; got {size!r}")
    if case == "penetration":
        return cases.penetration(size, jitter=jitter)
    if case == "drum":
        return cases.drum(size, jitter)
    orifice, material = size.split("-")
    suffix = "" if fill == cases.SILO_FILL else f"-{fill}"
    return cases.silo(orifice, material, out / f"silo-{size}{suffix}-fill.txt", fill, jitter)


def run(args: argparse.Namespace) -> None:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = build(args.case, args.size, out, args.fill, args.jitter)
    label = f"{case.name}-{args.size}" if args.case == "penetration" else case.name
    name = f"{label}-{args.engine}" + ("+jitter" if args.jitter else "")
    dt = case.keywords["dt"]
    steps = round(case.interval / dt)
    total = round(args.until / dt)  # the last piece is shorter when --until is not a whole interval
    restart = None
    if "restart" in registry.get_engine(args.engine).capabilities:
        every = max(1, round(args.checkpoint / dt)) if args.checkpoint else CHECKPOINT_STEPS
        restart = {"freq": every, "fname": "restart.*.h5",
                   "resume": args.resume}  # fmt: skip
    elif args.resume:
        raise SystemExit(f"the {args.engine} engine has no restart: run without --resume")
    keywords = dict(case.keywords, engine=args.engine, output=str(out / name), traj={"pfile": None})
    if args.threads:
        keywords["threads" if args.engine != "liggghts" else "nprocs"] = args.threads
    table = out / f"{name}.csv"
    rows: dict[str, list[str]] = {}
    if args.resume and table.is_file():
        with table.open() as handle:
            rows = {r[0]: r for r in list(csv.reader(handle))[1:]}
    # the steps before the checkpoint a resumed run continues from were run by another process
    resumed_at = newest_checkpoint(out / name / "restart") if args.resume else 0
    particle_steps, start = 0, time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # particles leaving the silo are lost by design
        with simulation.DEM(restart=restart, progress={"steps": total}, **keywords) as sim:
            case.setup(sim)
            setup, start = time.perf_counter() - start, time.perf_counter()
            if not sim.engine.replaying:
                rows["0"] = ["0", *map(repr, case.observe(sim))]
            done = 0
            while done < total:
                piece = min(steps, total - done)
                sim.run(piece)
                done += piece
                if sim.engine.replaying:  # this interval's row is in the CSV already
                    continue
                particle_steps += len(sim.extractIds()) * (done - max(done - piece, resumed_at))
                now = f"{done * dt:.6g}"
                rows[now] = [now, *map(repr, case.observe(sim))]
                write_csv(table, case.columns, rows)
            settings = {
                "engine": args.engine,
                "dt": dt,
                "skin": sim.spec.skin,
                "nns_type": sim.spec.nns_type,
                "threads": sim.spec.threads,
                "nprocs": sim.spec.nprocs,
                "particles": case.particles,
                "jitter": args.jitter,
            }
    wall = time.perf_counter() - start
    write_csv(table, case.columns, rows)
    report = {
        "case": label,
        "until": args.until,
        "setup_s": setup,
        "wall_time_s": wall,
        "particle_steps_per_s": particle_steps / wall if wall else None,
        "settings": settings,
    }
    (out / f"{name}.json").write_text(json.dumps(report, indent=1))
    print(json.dumps(report))


def newest_checkpoint(folder: Path) -> int:
    """The step of the newest checkpoint ``restart.<step>.h5`` in ``folder`` (0 if none)."""
    steps = [int(p.name.split(".")[1]) for p in folder.glob("restart.*.h5") if p.name.split(".")[1].isdigit()]
    return max(steps, default=0)


def write_csv(path: Path, columns: tuple[str, ...], rows: dict[str, list[str]]) -> None:
    ordered = sorted(rows.values(), key=lambda r: float(r[0]))
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", *columns])
        writer.writerows(ordered)


def compare(folder: Path) -> None:
    """One PNG per case, its engines overlaid (top) and each one's difference from its reference
    (bottom), and the agreement table on stdout."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs: dict[str, dict[str, np.ndarray]] = {}
    names: dict[str, tuple[str, ...]] = {}
    for table in sorted(folder.glob("*.csv")):
        label, _, engine = table.stem.rpartition("-")
        with table.open() as handle:
            header = next(csv.reader(handle))
        data = np.atleast_2d(np.loadtxt(table, delimiter=",", skiprows=1))
        runs.setdefault(label, {})[engine] = data
        names[label] = tuple(header)
    print(f"{'case':<24} {'column':<14} {'engine':<14} {'max |diff|':>12} {'relative':>10}  vs")
    for label, engines in runs.items():
        ncolumns = len(names[label]) - 1
        figure, axes = plt.subplots(2, ncolumns, figsize=(5 * ncolumns, 7), squeeze=False, sharex="col")
        plain = sorted(e for e in engines if "+" not in e)
        first = gates.REFERENCE if gates.REFERENCE in plain else plain[0]
        for column in range(1, ncolumns + 1):
            top, bottom = axes[0][column - 1], axes[1][column - 1]
            for index, (engine, data) in enumerate(sorted(engines.items())):
                top.plot(data[:, 0], data[:, column], label=engine, color=f"C{index}")
                # a jittered run against its own engine (the case's spread), the others against the first
                reference_engine = engine.partition("+")[0] if "+" in engine else first
                reference = engines.get(reference_engine)
                common = 0 if reference is None else min(len(data), len(reference))
                if engine == reference_engine or not common:
                    continue
                gap = np.abs(data[:common, column] - reference[:common, column])
                bottom.plot(data[:common, 0], gap, label=f"{engine} - {reference_engine}", color=f"C{index}")
                scale = np.abs(reference[:common, column]).max() or 1.0
                print(f"{label:<24} {names[label][column]:<14} {engine:<14} {gap.max():>12.4g} "
                      f"{gap.max() / scale:>10.3g}  {reference_engine}")  # fmt: skip
            top.set_ylabel(names[label][column])
            top.legend()
            bottom.set_xlabel("time (s)")
            bottom.set_ylabel(f"|difference| of {names[label][column]}")
            if bottom.lines:
                bottom.legend()
        figure.suptitle(label)
        figure.tight_layout()
        figure.savefig(folder / f"{label}.png", dpi=110)
        plt.close(figure)
    print("\ngates (see gates.py):")
    for label, engines in runs.items():
        for verdict in gates.verdicts(label, engines):
            print(verdict.line())
        if label.startswith("silo-"):
            orifice = label.split("-")[1]
            for engine, data in sorted(engines.items()):
                rate, beverloo = gates.steady_rate(data), gates.beverloo_rate(orifice)
                print(
                    f"{label:<22} {engine:<16} steady rate {rate:8.0f} particles/s from 0.2 s; Beverloo "
                    f"{beverloo:.0f} (flat bottom): {rate / beverloo:.2f}x"
                )


def positive_seconds(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text}")
    return value


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["compare"]:
        if len(argv) != 2:
            raise SystemExit("usage: run.py compare DIR")
        compare(Path(argv[1]))
        return
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("case", choices=sorted(SIZES))
    parser.add_argument("--engine", default="native")
    parser.add_argument("--size", required=True)
    parser.add_argument("--until", type=float, required=True, help="simulated seconds")
    parser.add_argument("--out", required=True)
    parser.add_argument("--resume", action="store_true")
    parser.add_argument(
        "--checkpoint",
        type=positive_seconds,
        help=f"simulated seconds between checkpoints (default {CHECKPOINT_STEPS} steps)",
    )
    parser.add_argument(
        "--threads", type=int, default=None, help="threads (native, YADE) or MPI ranks (LIGGGHTS)"
    )
    parser.add_argument("--fill", type=int, default=cases.SILO_FILL, help="silo: spheres poured for its fill")
    parser.add_argument(
        "--jitter",
        type=float,
        default=0.0,
        help="move the particles by up to this (m) at the start; writes <engine>+jitter",
    )
    run(parser.parse_args(argv))


if __name__ == "__main__":
    main()
