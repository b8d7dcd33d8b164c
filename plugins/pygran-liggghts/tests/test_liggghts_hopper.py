"""A hopper made of tests/data/meshes/silo.stl: fill by pack, remove the stopper, flow."""

from pathlib import Path

import numpy as np
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.testing.solvers import require_solver

SILO = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes" / "silo.stl"
MATERIAL = {
    "youngsModulus": 1e7,
    "poissonsRatio": 0.3,
    "coefficientRestitution": 0.5,
    "coefficientFriction": 0.3,
    "density": 2500.0,
}


def test_hopper_flows_after_the_stopper_is_removed(tmp_path):
    require_solver(find_library)
    assert SILO.is_file(), f"the shared fixture {SILO} is missing"
    with simulation.DEM(
        engine="liggghts",
        model=simulation.models.HertzMindlin,
        box=(-1.1e-3, 1.1e-3, -1.1e-3, 1.1e-3, -1e-3, 3.2e-3),
        gravity=(9.81, 0, 0, -1),
        dt=5e-7,
        output=str(tmp_path / "hopper"),
        species=({"material": MATERIAL, "radius": ("poly", (6e-5, 7e-5), (0.5, 0.5))},),
        mesh={"silo": {"file": str(SILO), "material": MATERIAL, "args": ("scale 1e-3",)}},
        traj={"freq": 10000, "pfile": "traj.dump", "mfile": "silo*.vtk"},
        progress=False,
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="silo")
        stopper = sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(
            species=1, value=150, region=("cylinder", "z", 0, 0, 5.5e-4, 1.6e-3, 2.9e-3), vel=(0, 0, -0.2)
        )
        sim.run(10000)
        filled = sim.extractCoords()
        assert len(filled) == 150
        assert filled[:, 2].min() > 0
        sim.remove(stopper)
        sim.run(50000)
        x = sim.extractCoords()
        out = tmp_path / "hopper"
    assert np.sum(x[:, 2] < 0) + (len(filled) - len(x)) >= 10  # particles left through the outlet
    meshes = sorted(out.glob("silo*.vtk"))
    assert len(meshes) == 7  # steps 0, 10000, ..., 60000
    assert "POINTS" in meshes[-1].read_text(errors="replace")
    assert (out / "traj.dump").read_text().count("ITEM: TIMESTEP") == 7
