"""Call forms of PyGran 1.x scripts found by trying them as a user: positional moveMesh, a
monitor file in a folder of its own, an output folder with brackets, and the lost-particle
count and flags on the simulation object; on native and LIGGGHTS."""

from pathlib import Path

import numpy as np
import pytest

from PyGran import analysis, params, simulation
from pygran_core.errors import ConfigError

MESHES = Path(__file__).resolve().parents[1] / "data" / "meshes"
ENGINES = ["native", "liggghts"]


def require(engine):
    if engine == "liggghts":
        from pygran_liggghts.library import find_library

        from pygran_core.testing.solvers import require_solver

        require_solver(find_library)


def plate(engine, output, **extra):
    """A square plate (the mm mesh at z = 3 mm, scaled to m and moved to z = 0) in a 4 mm box."""
    material = params.organic
    material["coefficientRestitution"] = 0.5
    pdict = {
        "engine": engine,
        "output": str(output),
        "box": (-2e-3, 2e-3, -2e-3, 2e-3, -1e-3, 3e-3),
        "gravity": (9.81, 0, 0, -1),
        "dt": 1e-6,
        "species": ({"material": material, "radius": 2e-4},),
        "mesh": {
            "wall": {
                "file": str(MESHES / "square.stl"),
                "mtype": "mesh/surface",
                "args": {"scale": 1e-3, "move": (0, 0, -3e-3)},
            }
        },
        "traj": {"freq": 500, "pfile": "traj.dump"},
        "progress": False,
    }
    return simulation.DEM(**pdict | extra)


@pytest.mark.parametrize("engine", ENGINES)
def test_move_mesh_with_liggghts_words_as_the_mixture_demo_writes_it(engine, tmp_path):
    """``moveMesh(name, *args)`` (the manual's form) moves the plate exactly as the keyword
    form does: the sphere on it is at the same place, to the last bit, after 3000 steps."""
    require(engine)
    positions = []
    for form in ("words", "keywords", "still"):
        with plate(engine, tmp_path / form) as sim:
            sim.createParticles(1, "single", 0.0, 0.0, 2.1e-4)
            if form == "words":
                words = ("viblin", "axis 0 0 1", "order 1", "amplitude 12.5e-6", "phase 0", "period 0.0025")
                sim.moveMesh("wall", *words)
            elif form == "keywords":
                sim.moveMesh(
                    "wall", viblin=("axis", 0, 0, 1), order=1, amplitude=12.5e-6, phase=0, period=0.0025
                )
            sim.run(3000)
            positions.append(sim.extractCoords())
    np.testing.assert_array_equal(positions[0], positions[1])
    assert abs(positions[0][0, 2] - positions[2][0, 2]) > 1e-6  # the plate moved the sphere
    with plate(engine, tmp_path / "mixed") as sim, pytest.raises(ConfigError, match="not both"):
        sim.moveMesh("wall", "linear", 0, 0, 1e-3, period=1.0)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_monitor_file_in_a_folder_of_its_own(engine, tmp_path):
    """``file='monitors/ke.dat'``: the folder is made, and the file holds LIGGGHTS' averages."""
    require(engine)
    with plate(engine, tmp_path / "out") as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 1e-3)
        sim.monitor(
            var="ke", species="all", name="ke", file="monitors/ke.dat", nevery=10, nrepeat=1, nfreq=100
        )
        sim.run(1000)
    rows = np.loadtxt(tmp_path / "out" / "monitors" / "ke.dat")
    assert rows[:, 0].tolist() == list(range(0, 1001, 100))
    mass = 4 / 3 * np.pi * 2e-4**3 * 1000
    assert rows[-1, 1] == pytest.approx(0.5 * mass * (9.81 * 1e-3) ** 2, rel=1e-6)  # falling freely


@pytest.mark.parametrize("engine", ENGINES)
def test_an_output_folder_with_brackets_and_the_lost_count(engine, tmp_path):
    """An output folder ``run[1]`` is a folder, not a glob pattern; particles thrown out of
    the box through the declared opening are counted on the simulation object."""
    require(engine)
    output = tmp_path / "run[1]"
    with plate(engine, output) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 3e-4)
        sim.createParticles(1, "single", 1e-3, 1e-3, 2e-3, vel=(0, 0, 5.0))
        sim.expect_outflow("z+")
        sim.run(1000)
        assert (sim.lost, sim.last_lost.count, sim.last_lost.where) == (1, 1, {"z+": 1})
        assert sim.time_step_check is not None
    system = analysis.System(Particles=str(output / "traj.dump"))
    assert len(system) == 3 and len(system.Particles) == 2
    system.goto(-1)
    assert len(system.Particles) == 1


def test_flags_are_true_or_false_not_words(tmp_path):
    """``progress='no'`` would read as true: refused, as ``run(check_dt='no')`` is."""
    with pytest.raises(ConfigError, match="progress must be True, False or None, got 'no'"):
        plate("native", tmp_path / "a", progress="no")
    with (
        plate("native", tmp_path / "b") as sim,
        pytest.raises(ConfigError, match="check_dt must be True or False"),
    ):
        sim.run(10, check_dt="no")
