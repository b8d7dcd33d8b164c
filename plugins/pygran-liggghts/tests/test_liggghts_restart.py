"""Checkpoints and resuming on real LIGGGHTS: PyGran's checkpoint names LIGGGHTS' own
restart file; the script's calls before it are replayed (LIGGGHTS restores its fixes by id),
and the dump LIGGGHTS writes is cut back and continued."""

import shutil

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.io import open_trajectory
from pygran_core.simulation.checkpoint import read_checkpoint
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT as MATERIAL

R = 1e-3


def study(output, restart):
    """100 particles inserted (LIGGGHTS' insert/pack) fall onto a floor until step 2000,
    then the floor moves lower. (LIGGGHTS' insertion draws from a random stream its restart
    files do not keep: resuming while it still inserts would place other particles.)"""
    require_solver(find_library)
    with simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(-0.006, 0.006, -0.006, 0.006, -0.005, 0.03),
        boundary=("p", "p", "f"),
        gravity=(9.81, 0, 0, -1),
        dt=1e-5,
        output=str(output),
        species=({"material": MATERIAL, "radius": R},),
        traj={"pfile": "traj.dump", "freq": 200, "args": ("id", "type", "x", "y", "z", "radius")},
        restart=restart,
        progress=False,
    ) as sim:
        floor = sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=100, region=("block", -0.005, 0.005, -0.005, 0.005, 0.01, 0.028))
        monitor = sim.monitor(quantities=("n",), freq=100, file="n.txt")
        sim.run(2000)
        sim.remove(floor)
        sim.setupWall(species=1, plane="zplane", peq=-0.004)
        sim.run(1000)
        return sim.extractIds(), sim.extractCoords(), monitor.values["n"], sim.step


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    output = tmp_path_factory.mktemp("straight")
    return output, study(output, (600, "restart", "restart.*.h5"))


@pytest.mark.parametrize("step", [1200, 2400])
def test_a_resumed_run_continues_where_it_stopped(straight, tmp_path, step):
    output, (ids, x, counts, end) = straight
    checkpoint = read_checkpoint(output / "restart" / f"restart.{step}.h5")
    assert checkpoint.engine == "liggghts" and checkpoint.step == step
    resumed = tmp_path / "out"
    shutil.copytree(output, resumed)  # as left by a crash after the end: later files included
    again = study(resumed, (600, "restart", "restart.*.h5", True, f"restart.{step}.h5"))
    assert again[3] == end
    np.testing.assert_array_equal(again[0], ids)  # the same insertions, none repeated
    np.testing.assert_array_equal(again[2], counts)
    # LIGGGHTS rebuilds its neighbour lists on reading a restart: the same physics, not bitwise
    assert np.abs(again[1] - x).max() < 0.5 * R
    with open_trajectory(resumed / "traj.dump") as frames:
        steps = [frame.timestep for frame in frames]
        assert steps == list(range(0, end + 1, 200))
        np.testing.assert_array_equal(np.sort(frames[-1].arrays["id"]), ids)


def test_single_checkpoint_file_keeps_one_liggghts_restart(tmp_path):
    study(tmp_path, (1000, "restart", "restart.h5"))
    assert read_checkpoint(tmp_path / "restart" / "restart.h5").step == 3000
    assert sorted(p.name for p in (tmp_path / "restart").iterdir()) == ["restart.3000.restart", "restart.h5"]
