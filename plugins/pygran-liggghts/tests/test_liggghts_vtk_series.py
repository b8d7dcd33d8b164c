"""The mesh frames LIGGGHTS writes itself (``dump mesh/vtk``) get their ``.pvd`` index, as
PyGran's own VTK series do: one entry per frame with its simulated time, and on resume the
index continued from the checkpoint's step. Read with pyvista's ``.pvd`` reader (LIGGGHTS runs
in a worker process, so pyvista may share the test's)."""

import importlib.util
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.io import open_trajectory
from pygran_core.simulation import geometry
from pygran_core.testing.solvers import in_ci, require_solver
from pygran_core.testing.validation import SOFT as MATERIAL

DT = 1e-5
#: Frame steps and their times: 100 steps of DT still, 100 turning, then 100 of 2 DT turning.
STEPS = [0, 50, 100, 150, 200, 250, 300]
TIMES = [0.0, 50 * DT, 100 * DT, 150 * DT, 200 * DT, 200 * DT + 50 * 2 * DT, 200 * DT + 100 * 2 * DT]


def study(output, restart=None):
    """A drum mesh wall, still for 100 steps, then turning; the time step doubled at step 200."""
    require_solver(find_library)
    with simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(-0.025, 0.025, -0.015, 0.015, -0.025, 0.025),
        gravity=(9.81, 0, 0, -1),
        dt=DT,
        output=str(output),
        species=({"material": MATERIAL, "radius": 1e-3},),
        mesh={"drum": {"triangles": geometry.drum(radius=0.02, length=0.02, axis="y"), "material": MATERIAL}},
        traj={"pfile": None, "mfile": "walls*.vtk", "freq": 50},
        restart=restart,
        progress=False,
    ) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.run(100)
        sim.moveMesh("drum", rotate=True, axis=(0, 1, 0), origin=(0, 0, 0), omega=20.0)
        sim.run(100)
        sim.run(100, dt=2 * DT)


def read_series(output):
    """(time, step, file) of each index entry; each frame's points by pyvista's .pvd reader."""
    if importlib.util.find_spec("pyvista") is None:
        message = "pyvista is not installed (pip install pyvista)"
        if in_ci():
            pytest.fail(f"CI=true and {message}", pytrace=False)
        pytest.skip(message)
    import pyvista as pv

    entries = [
        (float(e.get("timestep")), int(e.get("cycle")), e.get("file"))
        for e in ET.parse(output / "walls.pvd").getroot().iter("DataSet")
    ]
    reader = pv.get_reader(str(output / "walls.pvd"))
    points = []
    for time in reader.time_values:
        reader.set_active_time_value(time)
        points.append(np.asarray(reader.read()[0].points, float))
    return entries, list(reader.time_values), points


def check(output):
    entries, times, points = read_series(output)
    assert [step for _, step, _ in entries] == STEPS
    np.testing.assert_allclose([time for time, _, _ in entries], TIMES, rtol=1e-12)
    np.testing.assert_allclose(times, TIMES, rtol=1e-12)
    for (_, _, name), seen in zip(entries, points):
        with open_trajectory(output / name) as frames:
            np.testing.assert_allclose(seen, frames[0].arrays["points"], rtol=1e-6)  # VTK's float32
    # the drum stands still until step 100: LIGGGHTS' copies of its first file are not kept
    assert [name for _, _, name in entries] == ["walls0.vtk"] * 3 + [f"walls{step}.vtk" for step in STEPS[3:]]
    np.testing.assert_array_equal(points[2], points[0])  # still
    assert np.abs(points[3] - points[2]).max() > 1e-4  # turned 0.01 rad: a corner 0.02 m out moves 0.2 mm
    return entries


def test_liggghts_mesh_frames_are_indexed_with_their_time(tmp_path):
    study(tmp_path)
    entries = check(tmp_path)
    assert sorted(p.name for p in tmp_path.glob("walls*.vtk")) == sorted({name for _, _, name in entries})


@pytest.mark.parametrize("checkpoint", [100, 200])
def test_a_resumed_run_continues_the_index(tmp_path, checkpoint):
    """Resumed from a copy of the finished run, at step 100 (the drum still: that frame is
    indexed as the first file, and LIGGGHTS' copy written again as the run resumes is not
    kept) or 200 (turning: the frame's own file, written again in place): the index keeps its
    entries up to the checkpoint, then the new frames follow, and the folder holds the files
    the index names, as in the run straight through."""
    first = tmp_path / "first"
    study(first, (100, "restart", "restart.*.h5"))
    resumed = tmp_path / "resumed"
    shutil.copytree(first, resumed)
    study(resumed, (100, "restart", "restart.*.h5", True, f"restart.{checkpoint}.h5"))
    entries = check(resumed)
    assert entries == check(first)
    assert sorted(p.name for p in resumed.glob("walls*.vtk")) == sorted({name for _, _, name in entries})
