"""Runs that would eat the machine are refused before any work, with the limit and the
estimate: step counts past the step counters, trajectories larger than the disk, monitor
values larger than the memory, particles that cannot fit in their region (random close
packing) or in memory; and no worker process outlives a script killed with SIGKILL."""

from __future__ import annotations

import itertools
import math
import os
import subprocess
import sys
import textwrap
import time
import tracemalloc
import warnings
from pathlib import Path

import pytest

from pygran_core import registry, simulation
from pygran_core.errors import ConfigError, InsertionWarning
from pygran_core.simulation.calls import CLOSE_PACKING, PARTICLE_BYTES, available_memory
from pygran_core.simulation.diagnostics import FRAME_BYTES, MAX_STEP
from pygran_core.testing.mistakes import R, valid
from pygran_core.testing.solvers import require_solver

ENGINES = ("native", "liggghts", "yade")
#: A 6 mm cube: at random close packing it holds 0.64 * (6 mm)^3 / (4/3 pi (1 mm)^3) = 33.0
#: spheres of the first species' radius.
SMALL = ("block", 0, 0.006, 0, 0.006, 0, 0.006)
FIT = CLOSE_PACKING * 0.006**3 / (4 / 3 * math.pi * R**3)


def dem(tmp_path: Path, engine: str, **changes) -> simulation.DEM:
    spec = registry.get_engine(engine)
    if spec.locate_solver is not None:
        require_solver(spec.locate_solver)
    return simulation.DEM(**valid(tmp_path / "out", engine) | changes)


@pytest.mark.parametrize("engine", ENGINES)
def test_an_impossible_insert_is_refused_up_front(tmp_path, engine):
    """The audit's case: 10^9 particles into a 6 mm box never returned on LIGGGHTS."""
    assert FIT == pytest.approx(33.0, abs=0.05)
    with dem(tmp_path, engine) as sim:
        began = time.monotonic()
        with pytest.raises(
            ConfigError, match=r"insert: 1e\+09 particles cannot fit .* at most 33\.0\d* particles"
        ):
            sim.insert(1, value=1e9, region=SMALL)
        with pytest.raises(ConfigError, match=r"insert: 34 particles cannot fit"):
            sim.insert(1, value=34, region=SMALL)
        mass = 1.01 * FIT * 4 / 3 * math.pi * R**3 * sim.spec.species[0].density
        with pytest.raises(ConfigError, match=r"insert: .* kg cannot fit"):
            sim.insert(1, value=mass, mech="mass_in_region", region=SMALL)
        with pytest.raises(ConfigError, match=r"createParticles: 1e\+12 particles cannot fit"):
            sim.createParticles(1, "random", 10**12, region=SMALL)
        assert time.monotonic() - began < 2
        with warnings.catch_warnings():  # 20 of 33: made, or fewer with an InsertionWarning
            warnings.simplefilter("ignore", InsertionWarning)
            sim.insert(1, value=20, region=SMALL)
            sim.run(1)
        assert 0 < len(sim.extractIds()) <= 20


def test_particles_beyond_the_memory_are_refused(tmp_path):
    """Requests that fit their region but not the memory: a rate over a long duration, and
    a lattice over a large box (refused before its sites are listed)."""
    free = available_memory()
    with dem(tmp_path, "native", box=(0, 1000.0, 0, 1000.0, 0, 1000.0)) as sim:
        with pytest.raises(
            ConfigError, match=r"insert asks for 1e\+14 particles, which need about 1e\+08 GB"
        ):
            sim.insert(1, value=1e6, insert="by_rate", duration=1e8, region=("block", 0, 1, 0, 1, 0, 1))
        tracemalloc.start()
        try:
            with pytest.raises(
                ConfigError, match=r"createParticles lattice of spacing 0.002 asks for 1.25e\+17"
            ):
                sim.createParticles(1, "lattice", 2e-3, region=("block", 0, 1000.0, 0, 1000.0, 0, 1000.0))
            assert tracemalloc.get_traced_memory()[1] < 10**6
        finally:
            tracemalloc.stop()
    assert 1.25e17 * PARTICLE_BYTES > free


def test_runs_beyond_the_counters_the_disk_or_the_memory_are_refused(tmp_path):
    """run(10**15) grew the memory by 300 MB/s listing its output steps; now it is refused at
    once, and a run's pieces are listed as it goes."""
    with dem(tmp_path, "native", traj={"pfile": "traj.dump", "freq": 1000}) as sim:
        began = time.monotonic()
        frames = 10**15 // 1000
        with pytest.raises(ConfigError, match=r"would write 1e\+12 trajectory frames .* at least 1e\+05 GB"):
            sim.run(10**15)
        assert frames * FRAME_BYTES > os.statvfs(tmp_path).f_bavail * os.statvfs(tmp_path).f_frsize
        with pytest.raises(ConfigError, match=rf"past step {MAX_STEP}, the most the step counters hold"):
            sim.run(MAX_STEP + 1)
        assert time.monotonic() - began < 1
        tracemalloc.start()
        try:
            pieces = list(itertools.islice(sim.engine._run_chunks(10**15), 1000))
            assert tracemalloc.get_traced_memory()[1] < 2 * 10**6
        finally:
            tracemalloc.stop()
        assert pieces == [1000] * 1000  # every frame's step, and nothing listed beyond
        assert sim.step == 0
    with dem(tmp_path / "monitored", "native") as sim:
        sim.monitor(quantities=("ke",), freq=1)
        with pytest.raises(ConfigError, match=r"would keep 3e\+12 monitor values in memory"):
            sim.run(10**12)
        sim.run(10)
        assert sim.step == 10


SCRIPT = """
import sys
from pygran_core import simulation
from pygran_core.testing.mistakes import valid

with simulation.DEM(**valid(sys.argv[1], sys.argv[2]) | {"nprocs": int(sys.argv[3])}) as sim:
    sim.setupWall(species=1, plane="zplane", peq=0.0)
    sim.createParticles(1, "lattice", 2e-3, region=("block", 0, 0.02, 0, 0.02, 0, 0.02))
    print("running", flush=True)
    sim.run(10**11)  # pieces of minutes each: the worker does not stop between them
"""


def descendants(pid: int) -> set[int]:
    """The processes ``pid`` started, and theirs (Linux /proc), still running."""
    found = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in map(int, (task / "children").read_text().split()):
            found |= {child} | descendants(child)
    return found


def running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"  # a zombie has ended, waiting for its parent to read its exit status


@pytest.mark.parametrize(("engine", "nprocs"), [("liggghts", 1), ("liggghts", 2), ("yade", 1)])
def test_a_worker_dies_with_its_script(tmp_path, engine, nprocs):
    """The audit's case: after kill -9 of the script the LIGGGHTS worker ran on (to 14 GB).
    With nprocs=2 the script starts mpirun, which starts the two ranks: all end."""
    require_solver(registry.get_engine(engine).locate_solver)
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent(SCRIPT))
    command = [sys.executable, str(script), str(tmp_path / "out"), engine, str(nprocs)]
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None and process.stdout.readline() == "running\n"
            time.sleep(0.5)
            (worker,) = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
            started = descendants(process.pid)  # the worker or mpirun, and what it started
            assert int(worker) in started and all(map(running, started))
        finally:
            process.kill()
            process.wait()
    deadline = time.monotonic() + 3
    while any(map(running, started)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(map(running, started)), f"{sorted(filter(running, started))} outlived the script"
