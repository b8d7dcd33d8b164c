"""The settle scenario's sizes and phases (see README.md), and the bare ``liggghts`` binary on it.

Shared by ``settle.py``, ``native_solver.py``, ``threads_under_load.py`` and
``liggghts_overhead.py``; standard library only, so that importing it adds nothing to a timed
process.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

#: N: the lattice's particles along x, y and z.
SIZES = {5000: (25, 20, 10), 20000: (50, 40, 10), 100000: (100, 100, 10), 1000000: (500, 200, 10)}
#: Steps of the settling phase and of the dense-bed phase.
STEPS = (8000, 4000)


def bare_input(generated: Path, target: Path) -> None:
    """``target``: PyGran's generated commands ``generated`` (``in.pygran``) without their
    ``run`` lines, then the scenario's two runs as a LIGGGHTS user writes them."""
    lines = [line for line in generated.read_text().splitlines() if not line.startswith("run ")]
    target.write_text("\n".join([*lines, *(f"run {steps}" for steps in STEPS)]) + "\n")


def bare_command(script: Path, log: Path, nprocs: int) -> list[str]:
    """The bare binary on ``script`` with its screen output in ``log`` (``mpirun`` for more
    than one rank)."""
    from pygran_liggghts.session import mpirun_prefix

    binary = shutil.which("liggghts")
    if binary is None:
        raise SystemExit("the bare binary is not installed: apt-get install -y liggghts")
    launcher = mpirun_prefix(nprocs) if nprocs > 1 else []
    return [*launcher, binary, "-in", str(script), "-screen", str(log), "-log", "none"]


def loop_times(log: Path) -> list[tuple[int, float]]:
    """Steps and seconds of each run loop, from LIGGGHTS' screen output (``Loop time``)."""
    found = re.findall(r"^Loop time of (\S+) on \d+ procs for (\d+) steps", log.read_text(), re.M)
    return [(int(steps), float(seconds)) for seconds, steps in found]


def busy_loop(cpu: int | None = None) -> subprocess.Popen:
    """A process that keeps one core busy (on ``cpu`` when given) until killed."""
    pin = f"import os; os.sched_setaffinity(0, {{{cpu}}})\n" if cpu is not None else ""
    return subprocess.Popen([sys.executable, "-c", pin + "while True: pass\n"])
