"""Instructions and L1 data-cache misses per particle-step of the native solver, counted by
Valgrind's cachegrind: a measure of the solver's cost that does not depend on what else the
host runs. On a shared VM the same build timed against itself differs by 10 % in the median
of several rounds (see ``results.md``), so a 2 % change in speed cannot be timed there; counted
instructions and simulated cache misses are the same on every run, which makes them the way
to compare two builds within a few per cent.

Each build runs the variant phases of ``native_solver.py`` on one thread (the 20,000-particle
settle from the lattice, then the dense bed) under cachegrind twice: with ``--settle-steps``
and ``--bed-steps`` steps and with one step of each; the difference is the cost of the steps
alone (start-up, lattice and bed set-up cancel). Builds are given as in ``native_solver.py``:
a directory put first on ``PYTHONPATH`` holding ``pygran_native`` compiled from other sources,
``-`` for the installed one. Prints per build and phase the instructions and D1 misses per
particle-step, and the ratio to the first build; then one JSON line.

    .venv/bin/python benchmarks/native_instructions.py - /tmp/old/plugins/pygran-native/src

Each build takes a few minutes (cachegrind runs the solver about 50 times slower); the
counts do not depend on the load, so it can run beside other work.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from native_solver import settled_bed

HERE = Path(__file__).resolve().parent
N = 20000
BED = Path(tempfile.gettempdir()) / "pygran_settled_bed_20000.npz"
#: cachegrind's summary lines, e.g. ``==12== I   refs:      8,613,687,866``.
COUNT = {"Ir": re.compile(r"I\s+refs:\s+([\d,]+)"), "D1miss": re.compile(r"D1\s+misses:\s+([\d,]+)")}


def counts(build: str, settle: int, bed: int, folder: Path) -> dict[str, int]:
    """Cachegrind's totals for one run of ``native_solver.py``'s phases on ``build`` (from the
    settled bed in ``BED``, made beforehand)."""
    env = dict(os.environ)
    if build != "-":
        env["PYTHONPATH"] = os.pathsep.join(filter(None, (build, env.get("PYTHONPATH"))))
    command = ["valgrind", "--tool=cachegrind", "--cache-sim=yes", f"--cachegrind-out-file={folder}/cg.out"]
    command += [sys.executable, str(HERE / "native_solver.py"), "--one-variant", "--threads", "1"]
    command += ["--n", str(N), "--settle-steps", str(settle), "--bed-steps", str(bed), "--bed", str(BED)]
    done = subprocess.run(command, capture_output=True, text=True, env=env, cwd=HERE)
    found = {name: pattern.findall(done.stderr) for name, pattern in COUNT.items()}
    if done.returncode or not all(found.values()):
        raise SystemExit(f"cachegrind on {build} failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return {name: int(values[-1].replace(",", "")) for name, values in found.items()}


def per_step(build: str, settle: int, bed: int) -> dict[str, dict[str, float]]:
    """Per particle-step counts of each phase on ``build``."""
    with tempfile.TemporaryDirectory() as folder:
        base = counts(build, 1, 1, Path(folder))
        runs = {
            "settle": (counts(build, settle, 1, Path(folder)), settle - 1),
            "bed": (counts(build, 1, bed, Path(folder)), bed - 1),
        }
    return {
        phase: {name: (total[name] - base[name]) / (N * steps) for name in COUNT}
        for phase, (total, steps) in runs.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("builds", nargs="+", help="pygran_native build directories; - for the installed one")
    parser.add_argument("--settle-steps", type=int, default=400)
    parser.add_argument("--bed-steps", type=int, default=300)
    args = parser.parse_args()
    if shutil.which("valgrind") is None:
        raise SystemExit("valgrind is not installed (Debian: apt-get install -y valgrind)")
    settled_bed(BED)  # made once, outside the counts
    table = {build: per_step(build, args.settle_steps, args.bed_steps) for build in args.builds}
    first = table[args.builds[0]]
    print(f"per particle-step, N = {N}, 1 thread; ratio to {args.builds[0]}:")
    for build, phases in table.items():
        for phase, values in phases.items():
            ratios = "  ".join(f"{name} {values[name] / first[phase][name]:.4f}" for name in COUNT)
            figures = "  ".join(f"{name} {values[name]:8.1f}" for name in COUNT)
            print(f"  {build:50s} {phase:6s} {figures}   {ratios}")
    print(json.dumps(table))


if __name__ == "__main__":
    main()
