"""Resuming runs that were really killed: a user's study script runs in a child process, is
SIGKILLed (at seeded random moments, and at chosen points: inside a checkpoint's HDF5 write,
between its seal and its rename, after an H5MD trajectory is laid out and before its first
frame, in the middle of a frame, while a resumed
run cuts its trajectory back; after its last checkpoint, as when a finished study is simply
run again), then the same script is run again. Every file a kill leaves is
readable (or a ``ReadError``, never a hang), and the run that finishes ends where an
uninterrupted run ends: bitwise on the native engine (particles, monitor and every trajectory
frame); on YADE to rounding (its collider lists the pairs not touching anew, which may change
the order forces are summed in); on LIGGGHTS, which rebuilds its neighbour lists from its
restart file, with the same particles, monitor and frames and positions within half a radius.
Also: a checkpoint whose insertion state, monitor tables or
LIGGGHTS restart entry is malformed (sealed anew, as a tool rewriting it would) is a
``ReadError`` naming the file and the key."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pygran_core import params, registry, simulation
from pygran_core.errors import ReadError
from pygran_core.io import open_trajectory
from pygran_core.simulation.checkpoint import encode_text, read_checkpoint, write_checkpoint
from pygran_core.testing.solvers import require_solver

#: The user's study on the native engine (H5MD trajectory, a checkpoint every 500 steps; it
#: resumes from the newest checkpoint when there is one). ``sys.argv[1]`` is the output folder.
NATIVE = '''
"""Spheres poured onto a floor by rate, then the floor lowered."""

import sys
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core import params, simulation

output = Path(sys.argv[1])
settings = {
    "engine": "native",
    "model": simulation.HertzMindlin,
    "box": (-2e-3, 2e-3, -2e-3, 2e-3, -2e-3, 8e-3),
    "boundary": ("p", "p", "f"),
    "gravity": (9.81, 0, 0, -1),
    "dt": 1e-6,
    "output": str(output),
    "progress": False,
    "species": ({"material": params.cohesionless, "radius": ("normal", 1.5e-4, 1e-5)},),
    "traj": {"pfile": "traj.h5", "freq": 250, "args": ("id", "x", "y", "z", "vx", "vy", "vz", "radius")},
    "restart": (500, "restart", "restart.*.h5", any((output / "restart").glob("restart.*.h5"))),
    "threads": 1,
}
with simulation.DEM(**settings) as sim:
    floor = sim.setupWall(species=1, plane="zplane", peq=0.0)
    sim.insert(
        species=1,
        insert="by_rate",
        rate=200000,
        freq=500,
        duration=0.003,
        region=("block", -1.8e-3, 1.8e-3, -1.8e-3, 1.8e-3, 3e-3, 7.8e-3),
    )
    ke = sim.monitor(quantities=("ke", "n"), freq=100, file="monitor.txt")
    sim.run(4000)
    sim.remove(floor)
    sim.setupWall(species=1, plane="zplane", peq=-1.5e-3)
    sim.run(6000)
    final = {q: sim.engine.extract(q) for q in ("id", "x", "v", "omega", "f", "radius")}
    np.savez(output / "final.npz", monitor=ke.values["ke"], **final)
'''

#: The same kind of study on LIGGGHTS: 100 spheres packed above a floor (insertion at step 0
#: only: LIGGGHTS' restart files do not keep its insertion's random stream), poured, then the
#: floor lowered; a checkpoint every 600 steps.
LIGGGHTS = '''
"""100 spheres packed above a floor, poured, then the floor lowered."""

import sys
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core import params, simulation

output = Path(sys.argv[1])
settings = {
    "engine": "liggghts",
    "model": simulation.HertzMindlin,
    "box": (-0.006, 0.006, -0.006, 0.006, -0.005, 0.03),
    "boundary": ("p", "p", "f"),
    "gravity": (9.81, 0, 0, -1),
    "dt": 1e-5,
    "output": str(output),
    "progress": False,
    "species": ({"material": params.cohesionless, "radius": 1e-3},),
    "traj": {"pfile": "traj.h5", "freq": 200, "args": ("id", "type", "x", "y", "z", "radius")},
    "restart": (600, "restart", "restart.*.h5", any((output / "restart").glob("restart.*.h5"))),
}
with simulation.DEM(**settings) as sim:
    floor = sim.setupWall(species=1, plane="zplane", peq=0.0)
    sim.insert(species=1, value=100, region=("block", -0.005, 0.005, -0.005, 0.005, 0.01, 0.028))
    n = sim.monitor(quantities=("n",), freq=100, file="monitor.txt")
    sim.run(2000)
    sim.remove(floor)
    sim.setupWall(species=1, plane="zplane", peq=-0.004)
    sim.run(1000)
    np.savez(output / "final.npz", id=sim.extractIds(), x=sim.extractCoords(), monitor=n.values["n"])
'''

#: YADE: 40 spheres in a drum of triangles turning about y, between two plane walls, with drag;
#: the walls made after the spheres (a replayed script makes them again with other body ids);
#: the drag removed half-way; YADE's default time step (replayed from the checkpoint's
#: journal on resume); a checkpoint every 400 steps.
YADE = '''
"""Spheres tumbling in a turning drum made of triangles, the drag removed half-way."""

import sys
from pathlib import Path

import numpy as np

from pygran_core import params, simulation

output = Path(sys.argv[1])
turn = np.linspace(0.0, 2 * np.pi, 25)
ring = np.stack([9e-3 * np.cos(turn), np.zeros_like(turn), 9e-3 * np.sin(turn)], 1)
low, high = ring + [0, -3e-3, 0], ring + [0, 3e-3, 0]
drum = np.concatenate(
    [np.stack([low[:-1], low[1:], high[1:]], 1), np.stack([low[:-1], high[1:], high[:-1]], 1)]
)
across, along, up = np.arange(-5e-3, 6e-3, 2.5e-3), [-1.5e-3, 1.5e-3], np.arange(-5.5e-3, 3e-3, 2.5e-3)
grid = np.stack(np.meshgrid(across, along, up), -1)  # 40 spheres, inside the drum
settings = {
    "engine": "yade",
    "model": simulation.HertzMindlin,
    "box": (-0.01, 0.01, -0.004, 0.004, -0.01, 0.01),
    "gravity": (9.81, 0, 0, -1),
    "output": str(output),
    "progress": False,
    "species": ({"material": params.cohesionless, "radius": 1e-3},),
    "mesh": {"drum": {"triangles": drum, "material": params.steel}},
    "traj": {"pfile": "traj.h5", "freq": 400, "args": ("id", "type", "x", "y", "z", "vx", "vz", "radius")},
    "restart": (400, "restart", "restart.*.h5", any((output / "restart").glob("restart.*.h5"))),
}
with simulation.DEM(**settings) as sim:
    sim.createParticles(1, "single", grid.reshape(-1, 3))
    sim.setupWall(species=1, plane="yplane", peq=-3e-3)
    sim.setupWall(species=1, plane="yplane", peq=3e-3)
    sim.setupWall(wtype="mesh", mesh="drum")
    sim.moveMesh("drum", rotate=("origin", 0, 0, 0), axis=(0, 1, 0), omega=3.0)
    drag = sim.addViscous(species=1, gamma=2e-5)
    ke = sim.monitor(quantities=("ke",), freq=200, file="monitor.txt")
    sim.run(2400)
    sim.remove(drag)
    sim.run(2400)
    final = {q: sim.engine.extract(q) for q in ("id", "x", "v", "omega", "radius")}
    np.savez(output / "final.npz", monitor=ke.values["ke"], **final)
'''

#: Runs a script (``argv[3:]``) and SIGKILLs itself at the ``argv[2]``-th time it reaches
#: the point ``argv[1]``: the deterministic kills (a timer from outside could not hit these).
KILLER = """
import os, runpy, signal, sys

import h5py

point, due, script = sys.argv[1], int(sys.argv[2]), sys.argv[3]
sys.argv = sys.argv[3:]
reached = 0


def reach():
    global reached
    reached += 1
    if reached == due:
        os.kill(os.getpid(), signal.SIGKILL)


if point == "checkpoint-dataset":  # inside the HDF5 write of a checkpoint's state
    create = h5py.Group.create_dataset

    def create_dataset(self, name, *args, **kwargs):
        if self.file.filename.endswith(".partial") and name == "state/solver/core_x":  # once each
            reach()
        return create(self, name, *args, **kwargs)

    h5py.Group.create_dataset = create_dataset
elif point == "checkpoint-rename":  # written and sealed, not yet renamed
    replace = os.replace

    def renaming(src, dst):
        if str(src).endswith(".partial"):
            reach()
        return replace(src, dst)

    os.replace = renaming
elif point in ("frame", "cut"):  # a trajectory frame half written (while cutting back: "cut")
    setitem, write_direct = h5py.Dataset.__setitem__, h5py.Dataset.write_direct

    def positions_written(dataset):
        folder = os.path.dirname(dataset.file.filename)
        cutting = os.path.exists(os.path.join(folder, "traj.before-resume.h5"))
        if dataset.name.endswith("position/value") and cutting == (point == "cut"):
            reach()

    def writing(self, key, value):
        positions_written(self)
        return setitem(self, key, value)

    def writing_direct(self, source, *args, **kwargs):
        positions_written(self)
        return write_direct(self, source, *args, **kwargs)

    h5py.Dataset.__setitem__ = writing
    h5py.Dataset.write_direct = writing_direct
elif point == "layout":  # the trajectory file laid out, its first frame not yet begun
    resize = h5py.Dataset.resize

    def resizing(self, size, axis=None):
        if self.name.startswith("/particles/") and self.name.endswith("/step") and self.shape[0] == 0:
            reach()
        return resize(self, size, axis)

    h5py.Dataset.resize = resizing
runpy.run_path(script, run_name="__main__")
"""

#: Opens every file given the way a user would (trajectories with analysis.System, going
#: through every frame; checkpoints with read_checkpoint) and prints what happened as JSON.
CHECKER = """
import json, sys
from pathlib import Path

from pygran_core import analysis
from pygran_core.errors import ReadError
from pygran_core.simulation.checkpoint import read_checkpoint

results = {}
for path in sys.argv[1:]:
    try:
        if Path(path).parent.name == "restart":
            results[path] = ["ok", read_checkpoint(path).step]
        else:
            with analysis.System(Particles=path) as system:
                counts = [len(system.Particles) for _ in system.frames()]
            results[path] = ["ok", len(counts)]
    except ReadError as exc:
        results[path] = ["ReadError", str(exc)]
    except BaseException as exc:
        results[path] = [type(exc).__name__, str(exc)]
print(json.dumps(results))
"""

#: Seconds any child may take before it counts as hung (generous: the cores are shared).
TIMEOUT = 120
#: Seconds a killed study's own child processes (the LIGGGHTS worker) may outlive it.
ORPHAN_TIMEOUT = 30


@dataclass
class Outcome:
    """What a finished run leaves: final arrays, monitor file, trajectory frames."""

    final: dict[str, np.ndarray]
    monitor: str
    frames: list[tuple[int, dict[str, np.ndarray]]]


def outcome(output: Path) -> Outcome:
    with np.load(output / "final.npz") as saved:
        final = dict(saved)
    (path,) = (p for p in output.glob("traj.*") if ".before-resume" not in p.name and "xdmf" not in p.name)
    with open_trajectory(path) as trajectory:
        frames = [(frame.timestep, dict(frame.arrays)) for frame in trajectory]
    return Outcome(final, (output / "monitor.txt").read_text(), frames)


def assert_same(got: Outcome, expected: Outcome) -> None:
    assert got.final.keys() == expected.final.keys()
    for key in expected.final:
        np.testing.assert_array_equal(got.final[key], expected.final[key], err_msg=key)
    assert got.monitor == expected.monitor
    assert [step for step, _ in got.frames] == [step for step, _ in expected.frames]
    for (step, arrays), (_, reference) in zip(got.frames, expected.frames):
        assert arrays.keys() == reference.keys()
        for key in reference:
            np.testing.assert_array_equal(arrays[key], reference[key], err_msg=f"{key} at step {step}")


def assert_continued(got: Outcome, expected: Outcome) -> None:
    """LIGGGHTS: the same particles, particle counts and frames; positions within half a radius."""
    np.testing.assert_array_equal(got.final["id"], expected.final["id"])
    np.testing.assert_array_equal(got.final["monitor"], expected.final["monitor"])
    assert np.abs(got.final["x"] - expected.final["x"]).max() < 0.5e-3
    assert [step for step, _ in got.frames] == [step for step, _ in expected.frames]
    for (step, arrays), (_, reference) in zip(got.frames, expected.frames):
        np.testing.assert_array_equal(np.sort(arrays["id"]), np.sort(reference["id"]), err_msg=f"step {step}")


def assert_to_rounding(got: Outcome, expected: Outcome) -> None:
    """YADE: the same particles and frames, every number within rounding of the straight run's."""
    assert got.final.keys() == expected.final.keys()
    for key in expected.final:
        np.testing.assert_allclose(got.final[key], expected.final[key], rtol=1e-9, atol=1e-12, err_msg=key)
    monitors = [np.loadtxt(io.StringIO(outcome.monitor)) for outcome in (got, expected)]
    np.testing.assert_allclose(*monitors, rtol=1e-9, atol=1e-15)
    assert [step for step, _ in got.frames] == [step for step, _ in expected.frames]
    for (step, arrays), (_, reference) in zip(got.frames, expected.frames):
        assert arrays.keys() == reference.keys()
        for key in reference:
            np.testing.assert_allclose(
                arrays[key], reference[key], rtol=1e-9, atol=1e-12, err_msg=f"{key} at step {step}"
            )


#: How a resumed study is compared, by study (the engine, then a variant).
SAME = {
    "native": assert_same,
    "yade": assert_to_rounding,
    "liggghts": assert_continued,
    "liggghts-dump": assert_continued,
}


@pytest.fixture(scope="module")
def scripts(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("scripts")
    for name, text in (
        ("native.py", NATIVE),
        ("liggghts.py", LIGGGHTS),
        ("liggghts-dump.py", LIGGGHTS.replace("traj.h5", "traj.dump")),  # the dump LIGGGHTS writes
        ("yade.py", YADE),
        ("killer.py", KILLER),
        ("checker.py", CHECKER),
    ):
        (folder / name).write_text(textwrap.dedent(text))
    return folder


def launch(scripts: Path, engine: str, output: Path, *killer: str) -> subprocess.Popen:
    """The study in a child process of its own session (so that what it starts can be found),
    through the killer when ``killer`` gives its point and count."""
    through = [str(scripts / "killer.py"), *killer] if killer else []
    return subprocess.Popen(
        [sys.executable, *through, str(scripts / f"{engine}.py"), str(output)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )


def survivors(child: subprocess.Popen) -> list[int]:
    """Processes left in the killed child's session (Linux /proc)."""
    left = []
    for entry in os.listdir("/proc"):
        try:
            if entry.isdigit() and os.getsid(int(entry)) == child.pid:
                left.append(int(entry))
        except OSError:
            pass
    return left


def settle(child: subprocess.Popen) -> str:
    """Wait for a killed study and everything it started to be gone, as a user would before
    running it again; returns the study's stderr."""
    _, stderr = child.communicate(timeout=TIMEOUT)
    deadline = time.monotonic() + ORPHAN_TIMEOUT
    while survivors(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not survivors(child), f"processes of the killed study still run after {ORPHAN_TIMEOUT} s"
    return stderr.decode()


def finish(scripts: Path, engine: str, output: Path) -> None:
    """Run the study (again) to its end."""
    (output / "final.npz").unlink(missing_ok=True)
    child = launch(scripts, engine, output)
    _, stderr = child.communicate(timeout=TIMEOUT)
    assert child.returncode == 0, stderr.decode()


def kill_at(scripts: Path, engine: str, output: Path, point: str, due: int) -> None:
    """Run the study until it reaches ``point`` for the ``due``-th time, and SIGKILL it there."""
    child = launch(scripts, engine, output, point, str(due))
    stderr = settle(child)
    assert child.returncode == -signal.SIGKILL, f"not killed at {point} #{due}: {stderr}"


def check_left_files(scripts: Path, output: Path) -> dict[str, list]:
    """Open every trajectory and checkpoint the kill left; each reads or is a ReadError."""
    paths = sorted(str(p) for p in [*output.glob("traj*"), *(output / "restart").glob("*.h5*")])
    child = subprocess.run(
        [sys.executable, str(scripts / "checker.py"), *paths], timeout=TIMEOUT, capture_output=True, text=True
    )
    assert child.returncode == 0, child.stderr
    results = json.loads(child.stdout)
    crashed = {path: result for path, result in results.items() if result[0] not in ("ok", "ReadError")}
    assert not crashed
    return results


def resumed_from(output: Path) -> list[int]:
    """The steps of the checkpoints the runs in ``output`` resumed from, in order (pygran.log)."""
    log = (output / "pygran.log").read_text()
    return [int(step) for step in re.findall(r" resuming from .* \(step (\d+)\)", log)]


def latest_checkpoint(left: dict[str, list]) -> int:
    """The step of the newest whole checkpoint among the files a kill left."""
    return max(int(Path(p).name.split(".")[1]) for p in left if "/restart/" in p and p.endswith(".h5"))


@pytest.fixture(scope="module")
def straight(scripts, tmp_path_factory):
    """The uninterrupted run of an engine's study, and when (seconds after its launch) its
    simulation started and ended, read from the timestamps of pygran.log."""
    runs: dict[str, tuple[Outcome, float, float]] = {}

    def run(engine: str) -> tuple[Outcome, float, float]:
        spec = registry.get_engine(engine.split("-")[0])
        if spec.locate_solver is not None:
            require_solver(spec.locate_solver)
        assert "restart" in spec.capabilities
        if engine not in runs:
            output = tmp_path_factory.mktemp(f"straight-{engine}")
            launched = time.time()
            finish(scripts, engine, output)
            stamps = [
                datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f").timestamp()
                for line in (output / "pygran.log").read_text().splitlines()
                if " engine opened" in line or " engine closed" in line
            ]
            runs[engine] = outcome(output), stamps[0] - launched, stamps[-1] - launched
        return runs[engine]

    return run


@pytest.mark.parametrize(
    ("engine", "frames", "particles"),
    [
        ("native", list(range(0, 10001, 250)), 600),
        ("yade", list(range(0, 4801, 400)), 40),
        ("liggghts", list(range(0, 3001, 200)), 100),
    ],
)
def test_the_studies_write_what_the_kills_are_about(straight, engine, frames, particles):
    result, opened, closed = straight(engine)
    assert [step for step, _ in result.frames] == frames
    assert len(result.final["id"]) == particles
    assert closed > opened


@pytest.mark.parametrize(("engine", "kills", "after_checkpoint"), [("native", 8, 3), ("liggghts", 3, 0)])
def test_killed_at_random_moments_resumes(scripts, straight, tmp_path, engine, kills, after_checkpoint):
    """SIGKILLs at seeded random moments of the simulation (a fraction of its duration on the
    uninterrupted run, after the engine opened); after each, the files left are readable and
    the rerun ends where the straight run does."""
    expected, opened, closed = straight(engine)
    delays = np.random.default_rng(17).uniform(0.0, 1.0, kills) * (closed - opened)
    resumed = []
    for k, delay in enumerate(delays):
        output = tmp_path / f"kill{k}"
        child = launch(scripts, engine, output)
        log, deadline = output / "pygran.log", time.monotonic() + TIMEOUT
        while child.poll() is None and time.monotonic() < deadline:
            if log.is_file() and " engine opened" in log.read_text():
                break
            time.sleep(0.005)
        try:
            child.wait(delay)
        except subprocess.TimeoutExpired:
            child.send_signal(signal.SIGKILL)
        settle(child)
        check_left_files(scripts, output)
        finish(scripts, engine, output)
        SAME[engine](outcome(output), expected)
        resumed += resumed_from(output)
    # where the kills landed is measured, not assumed
    assert len(resumed) >= after_checkpoint, f"only {len(resumed)} of {kills} kills came after a checkpoint"


@pytest.mark.parametrize("engine", ["native", "liggghts"])
def test_killed_before_the_first_frame_starts_over(scripts, straight, tmp_path, engine):
    """Killed between laying out its trajectory file and writing the first frame: the file
    has no frames, which reading names as a ReadError, and the rerun starts over."""
    expected = straight(engine)[0]
    output = tmp_path / "out"
    kill_at(scripts, engine, output, "layout", 1)
    left = check_left_files(scripts, output)
    assert (
        left[str(output / "traj.h5")][0] == "ReadError"
        and "holds no frames" in left[str(output / "traj.h5")][1]
    )
    assert not [p for p in left if "/restart/" in p]
    finish(scripts, engine, output)
    assert resumed_from(output) == []
    SAME[engine](outcome(output), expected)


@pytest.mark.parametrize(
    ("engine", "point", "due", "resumes_from"),
    [
        ("native", "checkpoint-dataset", 4, 1500),  # in the 4th checkpoint (step 2000), at its positions
        ("native", "checkpoint-rename", 9, 4000),  # the 9th checkpoint written and sealed, not renamed
        ("native", "frame", 30, 7000),  # in the 30th frame (step 7250)
        ("yade", "checkpoint-rename", 5, 1600),  # the 5th checkpoint (step 2000) sealed, not renamed
        ("liggghts", "checkpoint-rename", 3, 1200),  # LIGGGHTS' restart file of step 1800 written
        ("liggghts", "frame", 14, 2400),  # in the 14th frame (step 2600)
        ("liggghts-dump", "checkpoint-rename", 3, 1200),  # LIGGGHTS' dump written up to step 1800
    ],
)
def test_killed_at_a_chosen_point_resumes(scripts, straight, tmp_path, engine, point, due, resumes_from):
    expected = straight(engine)[0]
    output = tmp_path / "out"
    kill_at(scripts, engine, output, point, due)
    assert latest_checkpoint(check_left_files(scripts, output)) == resumes_from
    finish(scripts, engine, output)
    assert resumed_from(output) == [resumes_from]
    SAME[engine](outcome(output), expected)


@pytest.mark.parametrize(
    ("engine", "due", "resumes_from", "freq"), [("native", 9, 4000, 500), ("liggghts", 3, 1200, 600)]
)
def test_a_resumed_run_killed_again_resumes(scripts, straight, tmp_path, engine, due, resumes_from, freq):
    """Killed between a checkpoint's seal and rename twice, the second time in the run that
    resumed from the first kill (at its third checkpoint); the third run resumes from the
    checkpoint before that."""
    expected, _, _ = straight(engine)
    output = tmp_path / "out"
    kill_at(scripts, engine, output, "checkpoint-rename", due)
    kill_at(scripts, engine, output, "checkpoint-rename", 3)
    finish(scripts, engine, output)
    assert resumed_from(output) == [resumes_from, resumes_from + 2 * freq]
    SAME[engine](outcome(output), expected)


@pytest.mark.parametrize(
    "engine",
    [
        "native",
        "yade",
        "liggghts",
        "liggghts-dump",
    ],
)
def test_a_finished_study_run_again_resumes_at_its_end(scripts, straight, tmp_path, engine):
    """Killed after its last checkpoint (the end of the last run), or simply run twice."""
    expected, _, _ = straight(engine)
    output = tmp_path / "out"
    finish(scripts, engine, output)
    finish(scripts, engine, output)
    assert resumed_from(output) == [expected.frames[-1][0]]
    SAME[engine](outcome(output), expected)


def test_killed_inside_a_checkpoint_write_leaves_the_previous_one(scripts, tmp_path):
    output = tmp_path / "out"
    kill_at(scripts, "native", output, "checkpoint-dataset", 4)
    left = check_left_files(scripts, output)
    partial = str(output / "restart" / "restart.2000.h5.partial")
    assert left[partial][0] == "ReadError"  # half written: refused, never resumed
    assert left[str(output / "restart" / "restart.1500.h5")] == ["ok", 1500]


def test_killed_again_while_the_resumed_run_cuts_its_trajectory(scripts, straight, tmp_path):
    """The first kill leaves frames up to step 7250 past the checkpoint of step 7000; the
    resumed run is killed while it copies the frames it keeps; the third run finishes."""
    expected = straight("native")[0]
    output = tmp_path / "out"
    kill_at(scripts, "native", output, "frame", 30)
    kill_at(scripts, "native", output, "cut", 10)
    check_left_files(scripts, output)
    finish(scripts, "native", output)
    assert resumed_from(output) == [7000, 7000]
    assert_same(outcome(output), expected)


# -- checkpoints whose state is malformed (sealed anew, as a tool rewriting one would) -------


def pour(output: Path, resume: bool) -> simulation.DEM:
    """Spheres inserted by rate every 100 steps for 1 ms; a checkpoint every 200 steps."""
    sim = simulation.DEM(
        engine="native",
        model=simulation.HertzMindlin,
        box=(-2e-3, 2e-3, -2e-3, 2e-3, 0, 4e-3),
        gravity=(9.81, 0, 0, -1),
        dt=1e-6,
        output=str(output),
        progress=False,
        species=({"material": params.cohesionless, "radius": 1.5e-4},),
        traj={"pfile": None},
        restart=(200, "restart", "restart.h5", resume),
        threads=1,
    )
    sim.insert(
        species=1,
        insert="by_rate",
        rate=100000,
        freq=100,
        duration=1e-3,
        region=("block", *[-1.5e-3, 1.5e-3] * 2, 1e-3, 3.5e-3),
    )
    return sim


MALFORMED = {
    "clock missing": (lambda s: s.pop("schedules/insert1/clock"), "no state entry 'schedules/insert1/clock'"),
    "clock of floats": (
        lambda s: s.update({"schedules/insert1/clock": np.array([400.0, 1000.0])}),
        "state entry 'schedules/insert1/clock' is float64 of shape (2,), not integers of shape 2",
    ),
    "clock of 3": (
        lambda s: s.update({"schedules/insert1/clock": np.array([400, 1000, 5])}),
        "'schedules/insert1/clock' is int64 of shape (3,), not integers of shape 2",
    ),
    "due before step 0": (
        lambda s: s.update({"schedules/insert1/clock": np.array([-100, 1000])}),
        "insertion 'schedules/insert1' is due at step -100",
    ),
    "owed as an array": (
        lambda s: s.update({"schedules/insert1/owed": np.zeros(4)}),
        "'schedules/insert1/owed' is float64 of shape (4,), not numbers of shape a scalar",
    ),
    "owed as text": (
        lambda s: s.update({"schedules/insert1/owed": encode_text("0.5")}),
        "'schedules/insert1/owed' is uint8 of shape (3,)",
    ),
    "target nan": (
        lambda s: s.update({"schedules/insert1/target": np.array(np.nan)}),
        "and targets nan",
    ),
    "rng missing": (lambda s: s.pop("schedules/insert1/rng"), "no state entry 'schedules/insert1/rng'"),
    "rng not JSON": (
        lambda s: s.update({"schedules/insert1/rng": encode_text('{"bit_generator": ')}),
        "state entry 'schedules/insert1/rng' is not UTF-8 JSON",
    ),
    "rng a list": (
        lambda s: s.update({"schedules/insert1/rng": encode_text("[1, 2]")}),
        "state entry 'schedules/insert1/rng' is a list, not a dict",
    ),
    "rng of another generator": (
        lambda s: s.update(
            {"schedules/insert1/rng": encode_text('{"bit_generator": "MT19937", "state": {}}')}
        ),
        "'schedules/insert1/rng' is not a random generator's state (ValueError",
    ),
    "rng without its state": (
        lambda s: s.update({"schedules/insert1/rng": encode_text('{"bit_generator": "PCG64"}')}),
        "'schedules/insert1/rng' is not a random generator's state (KeyError",
    ),
    "an insertion the script does not make": (
        lambda s: s.update({k.replace("insert1", "insert7"): v for k, v in s.items() if "insert1" in k}),
        "state entry 'schedules/insert7' is an insertion the script does not make",
    ),
}


@pytest.fixture(scope="module")
def poured(tmp_path_factory) -> Path:
    """A checkpoint of step 400, its insertion still going."""
    output = tmp_path_factory.mktemp("poured")
    with pour(output, resume=False) as sim:
        sim.run(400)
    return output / "restart" / "restart.h5"


@pytest.mark.parametrize("case", MALFORMED)
def test_a_malformed_insertion_state_is_a_read_error_naming_file_and_key(poured, tmp_path, case):
    damage, message = MALFORMED[case]
    checkpoint = read_checkpoint(poured)
    assert checkpoint.step == 400 and "schedules/insert1/clock" in checkpoint.state
    damage(checkpoint.state)
    path = tmp_path / "restart" / "restart.h5"
    write_checkpoint(path, checkpoint)
    with pour(tmp_path, resume=True) as sim, pytest.raises(ReadError) as info:
        sim.run(400)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value), str(info.value)


def test_the_untouched_checkpoint_resumes(poured, tmp_path):
    """The damage above is what the errors are about: the same file rewritten as it is resumes."""
    path = tmp_path / "restart" / "restart.h5"
    write_checkpoint(path, read_checkpoint(poured))
    with pour(tmp_path, resume=True) as sim:
        sim.run(400)
        sim.run(800)
        assert sim.step == 1200 and len(sim.extractIds()) == 100  # 10 at steps 0, 100, ..., 900


def drop(engine: str, output: Path, resume: bool) -> None:
    """Two spheres fall, their kinetic energy and count monitored; a checkpoint every 200 steps."""
    spec = registry.get_engine(engine)
    if spec.locate_solver is not None:
        require_solver(spec.locate_solver)
    with simulation.DEM(
        engine=engine,
        model=simulation.HertzMindlin,
        box=(-2e-3, 2e-3, -2e-3, 2e-3, 0, 4e-3),
        gravity=(9.81, 0, 0, -1),
        dt=1e-6,
        output=str(output),
        progress=False,
        species=({"material": params.cohesionless, "radius": 1.5e-4},),
        traj={"pfile": None},
        restart=(200, "restart", "restart.h5", resume),
    ) as sim:
        sim.createParticles(1, "single", np.array([[0, 0, 1e-3], [5e-4, 0, 1e-3]]))
        sim.monitor(quantities=("ke", "n"), freq=100, file="monitor.txt")
        sim.run(400)


@pytest.fixture(scope="module")
def dropped(tmp_path_factory) -> Any:
    """The folder of ``drop``'s straight run on an engine, made once per engine."""
    folders: dict[str, Path] = {}

    def run(engine: str) -> Path:
        if engine not in folders:
            folders[engine] = tmp_path_factory.mktemp(f"drop-{engine}")
            drop(engine, folders[engine], resume=False)
        return folders[engine]

    return run


def resume_damaged(
    engine: str, first: Path, tmp_path: Path, damage: Any
) -> tuple[Path, pytest.ExceptionInfo]:
    """Resume ``drop`` from its checkpoint of step 400 in ``first`` changed by ``damage`` and
    sealed anew."""
    checkpoint = read_checkpoint(first / "restart" / "restart.h5")
    damage(checkpoint)
    path = tmp_path / "again" / "restart" / "restart.h5"
    write_checkpoint(path, checkpoint)
    for restart in (first / "restart").glob("*.restart"):  # LIGGGHTS' own
        shutil.copy(restart, path.parent)
    with pytest.raises(ReadError) as info:
        drop(engine, tmp_path / "again", resume=True)
    return path, info


@pytest.mark.parametrize("engine", ["native", "yade", "liggghts"])
def test_a_monitor_table_of_another_width_is_a_read_error(dropped, tmp_path, engine):
    path, info = resume_damaged(
        engine,
        dropped(engine),
        tmp_path,
        lambda c: c.monitors.update({k: v[:, :3] for k, v in c.monitors.items()}),
    )
    assert str(info.value).startswith(f"{path}: ") and "monitor" in str(info.value)


@pytest.mark.parametrize(
    "entry",
    [None, np.zeros(3), encode_text("../../first/restart/restart.400.restart")],
    ids=["missing", "floats", "outside the folder"],
)
def test_a_malformed_liggghts_restart_entry_is_a_read_error(dropped, tmp_path, entry):
    def damage(checkpoint):
        checkpoint.state.pop("liggghts/restart")
        if entry is not None:
            checkpoint.state["liggghts/restart"] = entry

    path, info = resume_damaged("liggghts", dropped("liggghts"), tmp_path, damage)
    assert str(info.value).startswith(f"{path}: ") and "'liggghts/restart'" in str(info.value)


@pytest.mark.parametrize(
    ("key", "entry", "message"),
    [
        ("yade/scene", None, "no state entry 'yade/scene'"),
        ("yade/scene", encode_text("not a YADE scene"), "YADE cannot read the scene back"),
        ("yade/walls", encode_text("[1, 2]"), "'yade/walls'"),
        ("yade/walls", encode_text('{"wall1": "x"}'), "'yade/walls'"),
        ("yade/book", encode_text("{"), "'yade/book'"),
    ],
    ids=["missing", "garbage", "walls not a table", "walls without ids", "book not JSON"],
)
def test_a_malformed_yade_scene_is_a_read_error(dropped, tmp_path, key, entry, message):
    def damage(checkpoint):
        checkpoint.state.pop(key)
        if entry is not None:
            checkpoint.state[key] = entry

    path, info = resume_damaged("yade", dropped("yade"), tmp_path, damage)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value), str(info.value)
