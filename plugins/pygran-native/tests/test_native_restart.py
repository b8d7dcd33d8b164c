"""Checkpoints and resuming on the native engine: a resumed run ends bitwise where an
uninterrupted one does, trajectories and monitors included."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from pygran_core import simulation
from pygran_core.errors import ConfigError, ReadError
from pygran_core.io import open_trajectory
from pygran_core.simulation.checkpoint import read_checkpoint
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.validation import SOFT

QUANTITIES = ("x", "v", "omega", "f", "torque", "radius", "id")


def hopper_script(output: Path, restart: tuple, threads: int = 2, pfile: str = "traj.dump") -> dict:
    """A short study touching every kind of state: insertion by rate into a box with a
    stopper, a monitor, a trajectory, the stopper removed mid-way, friction history."""
    params = {
        "engine": "native",
        "model": HertzMindlin,
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, -1e-3, 4e-3),
        "boundary": ("p", "p", "f"),
        "gravity": (9.81, 0, 0, -1),
        "dt": 1e-6,
        "output": str(output),
        "progress": False,
        "species": ({"material": SOFT, "radius": ("normal", 6e-5, 6e-6)},),
        "traj": {"pfile": pfile, "freq": 250, "args": ("id", "x", "y", "z", "vx", "vy", "vz", "radius")},
        "restart": restart,
        "threads": threads,
        "seed": 5,
    }
    result = {}
    with simulation.DEM(**params) as sim:
        stopper = sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(
            species=1,
            insert="by_rate",
            rate=40000,
            freq=500,
            duration=0.003,
            region=("block", -9e-4, 9e-4, -9e-4, 9e-4, 1e-3, 3.5e-3),
        )
        ke = sim.monitor(quantities=("ke", "n"), freq=100, file="ke.txt")
        sim.run(2000)
        sim.remove(stopper)
        sim.setupWall(species=1, plane="zplane", peq=-8e-4)
        sim.run(1500)
        result = {q: sim.engine.extract(q) for q in QUANTITIES}
        result["ke"] = ke.values["ke"]
        result["step"], result["time"] = sim.step, sim.time
    return result


def assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """The uninterrupted run, writing a checkpoint every 300 steps."""
    output = tmp_path_factory.mktemp("straight")
    return output, hopper_script(output, (300, "restart", "restart.*.h5"))


def test_checkpoints_are_written_at_their_frequency(straight):
    output, result = straight
    steps = sorted(read_checkpoint(p).step for p in (output / "restart").glob("restart.*.h5"))
    assert steps == list(range(300, 3501, 300))
    checkpoint = read_checkpoint(output / "restart" / "restart.2100.h5")
    assert checkpoint.engine == "native" and checkpoint.facts == {"threads": 2}
    assert checkpoint.journal[-1][0] == "run 1500 1e-06" and len(checkpoint.journal) == 7


@pytest.mark.parametrize("step", [900, 2100, 3300])
def test_resuming_ends_bitwise_where_the_uninterrupted_run_ends(straight, tmp_path, step):
    """From a checkpoint inside the first run (insertion still going), inside the second
    (after the stopper's removal) and near the end; the trajectory is cut back and continued."""
    output, result = straight
    resumed = tmp_path / "out"
    (resumed / "restart").mkdir(parents=True)
    for name in ("traj.dump", "ke.txt", "pygran.log"):
        (resumed / name).write_bytes((output / name).read_bytes())  # as left by a crash after `step`
    (resumed / "restart" / f"restart.{step}.h5").write_bytes(
        (output / "restart" / f"restart.{step}.h5").read_bytes()
    )
    again = hopper_script(resumed, (300, "restart", "restart.*.h5", True, f"restart.{step}.h5"))
    assert_same(result, again)
    assert (resumed / "traj.dump").read_bytes() == (output / "traj.dump").read_bytes()
    assert (resumed / "ke.txt").read_text() == (output / "ke.txt").read_text()
    assert "resumed from" in (resumed / "pygran.log").read_text()


def test_resume_picks_the_newest_checkpoint(straight, tmp_path):
    output, result = straight
    resumed = tmp_path / "out"
    (resumed / "restart").mkdir(parents=True)
    for step in (600, 1800):
        name = f"restart.{step}.h5"
        (resumed / "restart" / name).write_bytes((output / "restart" / name).read_bytes())
    assert_same(result, hopper_script(resumed, (300, "restart", "restart.*.h5", True)))
    assert "restart.1800.h5 (step 1800)" in (resumed / "pygran.log").read_text()


def test_h5md_trajectory_is_cut_back_and_continued(tmp_path):
    first = hopper_script(tmp_path / "a", (1000, "restart", "restart.h5"), pfile="traj.h5")
    # the single checkpoint file now holds step 3000; the trajectory runs to 3500
    again = hopper_script(tmp_path / "a", (1000, "restart", "restart.h5", True), pfile="traj.h5")
    assert_same(first, again)
    with open_trajectory(tmp_path / "a" / "traj.h5") as frames:
        assert [frame.timestep for frame in frames] == list(range(0, 3501, 250))
        np.testing.assert_array_equal(frames[-1].arrays["x"], first["x"][:, 0])


def test_a_killed_run_resumes_bitwise(straight, tmp_path):
    """The real thing: SIGKILL the script once a checkpoint exists, then run it again with resume."""
    output, result = straight
    script = tmp_path / "study.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import sys, numpy as np
            sys.path.insert(0, {str(Path(__file__).parent)!r})
            from test_native_restart import hopper_script, QUANTITIES
            resume = len(sys.argv) > 1
            result = hopper_script({str(tmp_path / "out")!r}, (300, "restart", "restart.*.h5", resume))
            np.savez({str(tmp_path / "result.npz")!r}, **result)
            """
        )
    )
    child = subprocess.Popen([sys.executable, str(script)])
    first = tmp_path / "out" / "restart" / "restart.300.h5"
    deadline = time.monotonic() + 120
    while not first.exists() and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    os.kill(child.pid, signal.SIGKILL)
    assert child.wait() == -signal.SIGKILL, "the study finished before it could be killed"
    assert not (tmp_path / "result.npz").exists()
    subprocess.run([sys.executable, str(script), "resume"], check=True, timeout=300)
    with np.load(tmp_path / "result.npz") as saved:
        assert_same(result, dict(saved))
    assert (tmp_path / "out" / "traj.dump").read_bytes() == (output / "traj.dump").read_bytes()


def test_a_changed_script_is_refused_with_the_differing_call(straight, tmp_path):
    output, _ = straight
    resumed = tmp_path / "out"
    (resumed / "restart").mkdir(parents=True)
    (resumed / "restart" / "restart.2100.h5").write_bytes(
        (output / "restart" / "restart.2100.h5").read_bytes()
    )
    with pytest.raises(
        ConfigError,
        match=r"call 2 is `run 2500 1e-06` where that script's was `insertion InsertSpec\(",
    ):
        with simulation.DEM(
            engine="native",
            model=HertzMindlin,
            box=(-1e-3, 1e-3, -1e-3, 1e-3, -1e-3, 4e-3),
            species=({"material": SOFT, "radius": 6e-5},),
            output=str(resumed),
            restart=(300, "restart", "restart.*.h5", True),
        ) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            sim.run(2500, 1e-6)


def resume_in(output):
    return simulation.DEM(
        engine="native",
        model=HertzMindlin,
        box=(0, 1, 0, 1, 0, 1),
        species=({"material": SOFT, "radius": 0.01},),
        output=str(output),
        restart=(100, "restart", "restart.h5", True),
    )


def test_resume_without_a_checkpoint_says_what_to_do(tmp_path):
    with pytest.raises(ConfigError, match="run once without resume"):
        resume_in(tmp_path)


def test_a_file_that_is_not_a_checkpoint_is_named(tmp_path):
    bad = tmp_path / "restart" / "restart.h5"
    bad.parent.mkdir()
    bad.write_text("not hdf5")
    with pytest.raises(ReadError, match=r"restart\.h5: unreadable checkpoint"):
        resume_in(tmp_path)


def test_a_long_journal_fits_in_the_checkpoint(tmp_path):
    """Thousands of calls (far beyond the 64 KiB of an HDF5 attribute) before a checkpoint."""

    def script(resume):
        with simulation.DEM(
            engine="native",
            model=HertzMindlin,
            box=(0, 0.05, 0, 0.05, 0, 0.05),
            species=({"material": SOFT, "radius": 1e-3},),
            output=str(tmp_path),
            restart=(10, "restart", "restart.h5", resume),
            progress=False,
            traj={"pfile": None},
        ) as sim:
            for i in range(3000):
                sim.createParticles(
                    1,
                    "single",
                    0.002 + 0.003 * (i % 15),
                    0.002 + 0.003 * (i // 15 % 15),
                    0.002 + 0.003 * (i // 225),
                )
            sim.run(20, 1e-5)
            return sim.extractCoords()

    first = script(False)
    assert len(read_checkpoint(tmp_path / "restart" / "restart.h5").journal) == 3001
    np.testing.assert_array_equal(script(True), first)


def test_resume_compares_created_arrays_by_content(tmp_path):
    """Two createParticles arrays of 3,000 values that differ only in the middle print alike
    (numpy shortens them), yet resuming the other script is refused."""

    def script(offset: float, resume: bool) -> None:
        centres = np.stack(np.meshgrid(*[np.arange(10) * 2.5e-4 + 1.25e-4] * 3, indexing="ij"), -1)
        centres = centres.reshape(-1, 3)
        centres[500, 2] += offset
        with simulation.DEM(
            engine="native",
            model=HertzMindlin,
            box=(0, 2.5e-3, 0, 2.5e-3, 0, 2.5e-3),
            dt=1e-6,
            output=str(tmp_path / "out"),
            progress=False,
            species=({"material": SOFT, "radius": 1e-4},),
            traj={"pfile": None},
            restart=(100, "restart", "restart.*.h5", resume),
            threads=1,
        ) as sim:
            sim.createParticles(1, "single", centres)
            sim.run(200)

    script(0.0, resume=False)
    assert "..." in np.array2string(np.zeros((1000, 3)))  # what a repr-based check compared
    with pytest.raises(ConfigError, match="is not the one that wrote"):
        script(1e-5, resume=True)
    script(0.0, resume=True)  # the same script resumes
