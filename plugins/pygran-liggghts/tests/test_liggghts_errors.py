"""LIGGGHTS errors and crashes become EngineError with LIGGGHTS' message and source line, however
LIGGGHTS stops (error->all, error->one on rank 0 or another rank, a signal); the session goes on."""

import math
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from pygran_liggghts.library import LIBRARY_ENV, find_library

from pygran_core import simulation
from pygran_core.errors import EngineError
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT as MATERIAL

SQUARE = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes" / "square.stl"


def make(path, **extra):
    require_solver(find_library)
    return simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(0, 0.01, 0, 0.01, 0, 0.01),
        dt=1e-6,
        output=str(path),
        species=({"material": MATERIAL, "radius": 1e-3},),
        progress=False,
        **extra,
    )


def works(path):
    """A new simulation in the same process still runs."""
    with make(path) as sim:
        assert sim.createParticles(1, "single", 0.005, 0.005, 0.005) == 1
        sim.run(10)
        assert sim.extractCoords().shape == (1, 3)


def test_bad_raw_command(tmp_path):
    sim = make(tmp_path / "bad")
    with pytest.raises(EngineError, match=r"ERROR: Unknown command: fix_this_typo 1 \(.*input\.cpp:\d+\)"):
        sim.command("fix_this_typo 1")
    with pytest.raises(EngineError, match="stopped after an error"):
        sim.run(10)
    sim.close()
    assert "Unknown command" in (tmp_path / "bad" / "liggghts.log").read_text(errors="replace")
    works(tmp_path / "after")


def test_mesh_driven_out_of_the_box(tmp_path):
    """An error LIGGGHTS finds only while it runs: a plate moved out of the box at 10 m/s."""
    square = {"file": str(SQUARE), "args": {"scale": 1e-3, "move": (5e-3, 5e-3, 2e-3)}}
    with make(tmp_path / "impossible", mesh={"plate": square}) as sim:
        sim.moveMesh("plate", linear=(0, 0, 10))
        with pytest.raises(
            EngineError, match=r"Mesh elements have been lost / left the domain.* \(\S*:\d+\)"
        ):
            sim.run(1000)
    works(tmp_path / "after")


def test_worker_crash(tmp_path):
    with make(tmp_path / "crash") as sim:
        os.kill(sim.engine._channel.session.process.pid, signal.SIGKILL)
        with pytest.raises(EngineError, match=r"ended by SIGKILL \(Killed\)"):
            sim.run(10)
    works(tmp_path / "after")


#: A script that starts a simulation on ``nprocs`` (``argv[2]``) ranks, prints its worker's
#: socket folder, and waits to be killed.
WAITING = """
import sys, time
from pygran_core import simulation
from pygran_core.testing.validation import SOFT

sim = simulation.DEM(
    engine="liggghts", model="HertzMindlin", box=(0, 0.01, 0, 0.01, 0, 0.01), dt=1e-6, output=sys.argv[1],
    species=({"material": SOFT, "radius": 1e-3},), nprocs=int(sys.argv[2]), progress=False,
)
sim.createParticles(1, "single", 0.005, 0.005, 0.005)
sim.run(10)
print(sim.engine._channel.session._dir, flush=True)
time.sleep(600)
"""


def session_processes(sid: int) -> list[int]:
    """Processes of the session ``sid`` still running (Linux /proc)."""
    left = []
    for entry in os.listdir("/proc"):
        try:
            if entry.isdigit() and os.getsid(int(entry)) == sid:
                left.append(int(entry))
        except OSError:
            pass
    return left


@pytest.mark.parametrize("nprocs", [1, 2])
def test_a_killed_script_leaves_no_worker_and_no_socket_folder(tmp_path, nprocs):
    """The script SIGKILLed (nothing closes its simulation): its worker job sees the socket
    close, ends on every rank, and removes the socket's folder."""
    require_solver(find_library)
    script = tmp_path / "waiting.py"
    script.write_text(textwrap.dedent(WAITING))
    child = subprocess.Popen(
        [sys.executable, str(script), str(tmp_path / "out"), str(nprocs)],
        stdout=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        folder = Path(child.stdout.readline().decode().strip())
        assert folder.name.startswith("pygran-liggghts-")  # its socket is gone once connected
        child.kill()
        child.communicate(timeout=30)
        deadline = time.monotonic() + 30
        while (folder.exists() or session_processes(child.pid)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not session_processes(child.pid)
        assert not folder.exists()
    finally:
        for pid in session_processes(child.pid):
            os.kill(pid, signal.SIGKILL)


def test_worker_that_cannot_start(tmp_path, monkeypatch):
    """The worker starts in the background: DEM() returns, so do setupWall and the first
    createParticles (a new simulation has no particles to check against), and the first call
    that waits for LIGGGHTS raises the worker's own error."""
    require_solver(find_library)
    monkeypatch.setenv(LIBRARY_ENV, str(tmp_path / "nope.so"))  # inherited by the worker
    sim = simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(0, 0.01, 0, 0.01, 0, 0.01),
        output=str(tmp_path / "broken"),
        species=({"material": MATERIAL, "radius": 1e-3},),
        progress=False,
    )
    sim.setupWall(species=1, plane="zplane", peq=0.0)
    assert sim.createParticles(1, "single", [(0.003, 0.005, 0.005), (0.007, 0.005, 0.005)]) == 2
    with pytest.raises(EngineError, match=r"(?s)could not start: .*nope\.so' is not a file"):
        sim.run(10, 1e-6)
    sim.close()
    monkeypatch.delenv(LIBRARY_ENV)
    works(tmp_path / "after")


def triangle(sim, corner):
    """Three touching spheres at ``corner`` + (0..2 mm): the first has two neighbours."""
    x, y, z = corner
    for dx, dy in ((0.0, 0.0), (2e-3, 0.0), (1e-3, math.sqrt(3) * 1e-3)):
        sim.createParticles(1, "single", x + dx, y + dy, z)


@pytest.mark.parametrize(("nprocs", "rank"), [(1, 0), (2, 1)])
def test_error_one_on_any_rank(tmp_path, nprocs, rank):
    """error->one (then MPI_Abort) on the rank that has the spheres: in the upper corner of
    the box, rank 1 of 2 whichever way LIGGGHTS splits it."""
    with make(tmp_path / "one", nprocs=nprocs) as sim:
        triangle(sim, (6.5e-3, 6.5e-3, 7e-3))
        sim.command("neigh_modify page 100 one 1")  # at most one neighbour per sphere
        message = (
            rf"ERROR on proc {rank}: Neighbor list overflow, boost neigh_modify one \(.*neigh_gran\.cpp:\d+\)"
        )
        with pytest.raises(EngineError, match=message):
            sim.run(10)
    works(tmp_path / "after")


def test_error_one_while_reading_a_command(tmp_path):
    with make(tmp_path / "substitution") as sim:
        with pytest.raises(
            EngineError, match=r"ERROR on proc 0: Substitution for illegal variable \(.*input\.cpp:\d+\)"
        ):
            sim.command("print $Q")


def test_signal_inside_liggghts(tmp_path):
    """LIGGGHTS' shell command signals the worker while LIGGGHTS runs it. The kernel hands a
    signal sent to a process to any of its threads: when Open MPI's progress thread takes it,
    the backtrace has no LIGGGHTS frame, so this tries up to three workers for one naming
    LIGGGHTS' function; every one must name the signal."""
    messages = []
    for attempt in range(3):
        with make(tmp_path / f"segv{attempt}") as sim:
            pid = sim.engine._channel.session.process.pid
            with pytest.raises(EngineError, match=r"ended by SIGSEGV \(Segmentation fault\)") as failure:
                sim.command(f"shell kill -SEGV {pid}")
        messages.append(str(failure.value))
        if "execute_command" in messages[-1]:
            break
    assert re.search(r"ended by SIGSEGV \(Segmentation fault\) in .*execute_command", messages[-1]), messages
    works(tmp_path / "after")


def test_an_error_of_several_lines_is_kept_whole(tmp_path):
    """LIGGGHTS explains some errors over several lines, ending with the source line. PyGran's
    own insert refuses a region thinner than its particles up front, so raw commands make one."""
    with make(tmp_path / "region") as sim:
        for line in (
            "fix thin_template all particletemplate/sphere 15485863 atom_type 1 density constant 2500 "
            "radius constant 0.001",
            "fix thin_distribution all particledistribution/discrete 32452843 1 thin_template 1",
            "region thin block 0.001 0.009 0.001 0.009 0.004 0.005 units box",
            "fix thin_insert all insert/pack seed 49979687 distributiontemplate thin_distribution "
            "insert_every once overlapcheck yes all_in yes particles_in_region 10 region thin",
        ):
            sim.command(line)
        with pytest.raises(
            EngineError,
            match=r"ERROR: Unable to calculate region volume\. .* \(a\) region volume is too small .* "
            r"\(c\) region is 2d, but should be 3d \(\S*region\.cpp:\d+\)",
        ):
            sim.run(10)
