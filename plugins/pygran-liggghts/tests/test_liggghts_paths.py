"""Output folders and mesh files whose names LIGGGHTS' input parser would misread: spaces, '#'
(a comment), '$' (a variable, even inside quotes in LIGGGHTS 3.8) and quotes. Every file
LIGGGHTS writes or reads through its input (dumps, mesh dumps, restart files, the mesh) lands
where it should, and a checkpoint in such a folder resumes."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.io import open_trajectory
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT

PLATE = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes" / "square.stl"
NAMES = ["my run", "run#1", "run$x", "it's", 'say "hi"', "all $ # ' \" of them"]


def fall(output: Path, resume: bool = False) -> np.ndarray:
    """Two spheres fall onto the plate (square.stl in mm, in a folder of the same name);
    a checkpoint every 100 steps."""
    require_solver(find_library)
    mesh_dir = output / "mesh files"
    mesh_dir.mkdir(parents=True, exist_ok=True)
    shutil.copy(PLATE, mesh_dir / "plate.stl")
    with simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(-1e-3, 1e-3, -1e-3, 1e-3, 0, 4e-3),
        gravity=(9.81, 0, 0, -1),
        dt=1e-6,
        output=str(output),
        species=({"material": SOFT, "radius": 1e-4},),
        mesh={"plate": {"file": str(mesh_dir / "plate.stl"), "args": ("scale 1e-3",)}},
        traj={"freq": 100, "pfile": "traj.dump", "mfile": "plate*.vtk"},
        restart=(100, "restart", "restart.h5", resume, "restart.h5" if resume else None),
        progress=False,
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="plate")
        sim.createParticles(1, "single", np.array([[-5e-4, 0, 3.2e-3], [5e-4, 0, 3.2e-3]]))
        sim.run(300)
        return sim.extractCoords()


@pytest.mark.parametrize("name", NAMES)
def test_awkward_folder_names(tmp_path, name):
    output = tmp_path / name
    x = fall(output)
    assert x[:, 2] == pytest.approx(3.2e-3 - 0.5 * 9.81 * (300e-6) ** 2, rel=1e-9)
    with open_trajectory(output / "traj.dump") as frames:
        assert [frame.timestep for frame in frames] == [0, 100, 200, 300]
    assert sorted(p.name for p in output.glob("plate*.vtk")) == [f"plate{s}.vtk" for s in (0, 100, 200, 300)]
    assert (output / "restart" / "restart.300.restart").is_file()
    assert not list(output.parent.glob("*.dump"))  # nothing written beside the folder


def test_resume_in_an_awkward_folder(tmp_path):
    output = tmp_path / NAMES[-1]
    first = fall(output)
    np.testing.assert_allclose(fall(output, resume=True), first, rtol=0, atol=1e-12)
