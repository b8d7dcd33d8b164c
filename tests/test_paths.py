"""Output folders and mesh files whose names a solver's input could misread (spaces, '#',
'$', quotes, and '*' and '%', which LIGGGHTS reads in a file name as the step and the
processor), on every engine: a small simulation writes its trajectory (dump and H5MD), its
mesh frames and its checkpoints there, analysis.System reads them back with the particles
where the engine has them, and an engine with ``restart`` resumes from that folder. LIGGGHTS
refuses the names its input cannot hold (tests/test_hostile_inputs.py reruns its saved input
in the others)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pygran_core import analysis, params, registry, simulation
from pygran_core.errors import ConfigError
from pygran_core.testing.solvers import require_solver

PLATE = Path(__file__).parent / "data" / "meshes" / "square.stl"  # 10 mm square at z = 3 mm
NAMES = ["my run", "run#1", "run$x", "it's", 'say "hi"', "star*", "pct%d", "all $ # ' \" * % of them"]
ENGINES = ["native", "liggghts", "yade"]
#: The hardest name each engine takes: LIGGGHTS' input cannot hold '$' (a variable even in
#: quotes), '*' or '%' in a folder (the step, the processor) or both kinds of quote.
HARDEST = {"native": NAMES[-1], "yade": NAMES[-1], "liggghts": "all # ' & of them"}


def refused(engine: str, name: str) -> bool:
    return engine == "liggghts" and (any(c in name for c in "$*%") or ("'" in name and '"' in name))


START = np.array([[-5e-4, 0, 3.2e-3], [5e-4, 0, 3.2e-3], [0, 5e-4, 3.5e-3]])
G, DT, STEPS = 9.81, 1e-6, 300


def fall(engine: str, output: Path, pfile: str, resume: bool = False) -> np.ndarray:
    """Three spheres fall for 300 steps above a mesh plate (read from a folder with a space);
    frames every 100 steps, and a checkpoint every 100 steps where the engine has them."""
    spec = registry.get_engine(engine)
    if spec.locate_solver is not None:
        require_solver(spec.locate_solver)
    mesh_dir = output / "mesh files"
    mesh_dir.mkdir(parents=True, exist_ok=True)
    shutil.copy(PLATE, mesh_dir / "plate.stl")
    restart = (100, "restart", "restart.h5", resume) if "restart" in spec.capabilities else None
    with simulation.DEM(
        engine=engine,
        model=simulation.HertzMindlin,
        box=(-1e-3, 1e-3, -1e-3, 1e-3, 0, 4e-3),
        gravity=(G, 0, 0, -1),
        dt=DT,
        output=str(output),
        species=({"material": params.cohesionless, "radius": 1e-4},),
        mesh={"plate": {"file": str(mesh_dir / "plate.stl"), "args": ("scale 1e-3",)}},
        traj={"freq": 100, "pfile": pfile, "mfile": "plate*.vtk", "args": ("id", "x", "y", "z", "radius")},
        restart=restart,
        progress=False,
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="plate")
        sim.createParticles(1, "single", START)
        sim.run(STEPS)
        return sim.extractCoords()


@pytest.mark.parametrize(
    ("name", "pfile"), [*((name, "traj.dump") for name in NAMES), (NAMES[-1], "traj.h5")]
)
@pytest.mark.parametrize("engine", ENGINES)
def test_awkward_folder_names(tmp_path, engine, name, pfile):
    output = tmp_path / name
    if refused(engine, name):
        with pytest.raises(ConfigError, match=r"^output '.*' holds .*: choose a name without it"):
            fall(engine, output, pfile)
        assert not (output / pfile).exists()
        return
    x = fall(engine, output, pfile)
    drop = START[:, 2] - x[:, 2]
    assert drop == pytest.approx(np.full(3, 0.5 * G * (STEPS * DT) ** 2), rel=1e-2)
    with analysis.System(Particles=str(output / pfile)) as system:
        assert [system.timestep for _ in system.frames()] == [0, 100, 200, 300]
        system.goto(-1)
        particles = system.Particles
        assert len(particles) == 3
        order = np.argsort(particles.id)
        got = np.column_stack([particles.x, particles.y, particles.z])[order]
        np.testing.assert_allclose(got, x, rtol=1e-6, atol=0)
    plates = sorted(output.glob("plate*.vtk"))
    # the plate stands still: one file (LIGGGHTS' copies of it removed), indexed at every frame
    assert [p.name for p in plates] == ["plate0.vtk"]
    with analysis.System(Mesh=str(output / "plate.pvd")) as system:
        assert [system.timestep for _ in system.frames()] == [0, 100, 200, 300]
    with analysis.System(Mesh=str(plates[-1])) as system:
        assert np.ptp(system.Mesh.points[:, 2]) == 0 and system.Mesh.points[0, 2] == pytest.approx(3e-3)
    if "restart" in registry.get_engine(engine).capabilities:
        assert (output / "restart" / "restart.h5").is_file()
    assert sorted(p.name for p in output.parent.iterdir()) == [name]  # nothing written beside it


@pytest.mark.parametrize("engine", [e for e in ENGINES if e != "yade"])  # YADE has no restart
def test_resume_in_an_awkward_folder(tmp_path, engine):
    output = tmp_path / HARDEST[engine]
    first = fall(engine, output, "traj.h5")
    again = fall(engine, output, "traj.h5", resume=True)
    np.testing.assert_allclose(again, first, rtol=0, atol=1e-12)
    assert "resumed from" in (output / "pygran.log").read_text()
