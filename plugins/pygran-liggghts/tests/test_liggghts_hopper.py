"""A hopper made of tests/data/meshes/silo.stl: fill by pack, remove the stopper, flow."""

import re
import xml.etree.ElementTree as ET
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
        sim.engine.expect_outflow("z-")  # what leaves the hopper falls out of the box
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
    index = ET.parse(out / "silo.pvd").getroot()
    assert [int(e.get("cycle")) for e in index.iter("DataSet")] == list(range(0, 60001, 10000))
    assert {e.get("file") for e in index.iter("DataSet")} == {"silo0.vtk"}  # the silo stands still
    assert [p.name for p in out.glob("silo*.vtk")] == ["silo0.vtk"]
    assert "POINTS" in (out / "silo0.vtk").read_text(errors="replace")
    assert (out / "traj.dump").read_text().count("ITEM: TIMESTEP") == 7


VALVE = SILO.with_name("valve.stl")
#: The impeller (valve.stl: two crossed flat blades 1 mm long at z = 0.5 mm) moved 1 mm down,
#: below the hopper's outlet, and its spin (rad/s).
PLATE_Z, OMEGA, RADIUS = -0.5e-3, 100.0, 5e-5


def mesh_walls(path: Path) -> list[str]:
    """The meshes of each fix wall/gran of mesh walls in the input script, in order."""
    return re.findall(r"wall/gran .* mesh n_meshes \d+ meshes (.*)", path.read_text())


def test_hopper_and_rotating_impeller_are_walls_together(tmp_path):
    """Both meshes are walls of one fix wall/gran (rebuilt as each is added or removed): the
    hopper holds the spheres, which fall through its outlet onto the spinning impeller; those
    resting on its blades are carried round; once the impeller wall is removed they fall."""
    require_solver(find_library)
    mesh = {
        "silo": {"file": str(SILO), "material": MATERIAL, "args": ("scale 1e-3",)},
        "impeller": {"file": str(VALVE), "material": MATERIAL, "args": ("scale 1e-3", "move 0 0 -1e-3")},
    }
    with simulation.DEM(
        engine="liggghts",
        model=simulation.models.HertzMindlin,
        box=(-1.1e-3, 1.1e-3, -1.1e-3, 1.1e-3, -1.5e-3, 3.2e-3),
        gravity=(9.81, 0, 0, -1),
        dt=5e-7,
        output=str(tmp_path),
        species=({"material": MATERIAL, "radius": RADIUS},),
        mesh=mesh,
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="silo")
        sim.engine.expect_outflow("x-", "x+", "y-", "y+", "z-")  # flung off the impeller, or past it
        impeller = sim.setupWall(wtype="mesh", mesh="impeller")
        sim.moveMesh("impeller", rotate=True, axis=(0, 0, 1), origin=(0, 0, 0), omega=OMEGA)
        sim.insert(species=1, value=100, region=("cylinder", "z", 0, 0, 3.5e-4, 6e-4, 2e-3), vel=(0, 0, -0.2))
        sim.run(30000)
        x, v, carried = sim.extractCoords(), sim.extractVelocities(), sim.extractIds()
        axial = np.hypot(x[:, 0], x[:, 1])
        in_hopper = x[:, 2] > 0
        # the hopper's cone: radius 0.3 mm at z = 0 to 1 mm at z = 3 mm (inscribed 16-gon)
        assert np.all(axial[in_hopper] < 3e-4 + x[in_hopper, 2] * 7e-4 / 3e-3)
        on_plate = (x[:, 2] > PLATE_Z) & (x[:, 2] < PLATE_Z + 3 * RADIUS) & (axial < 0.5e-3)
        assert on_plate.sum() >= 10, x[:, 2]
        swirl = (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]) / axial**2  # angular speed about z
        # dragged round by friction: rolling spheres orbit at 2/7 of a turntable's rate, sliding
        # ones faster, none faster than the blades
        assert 0.1 < np.median(swirl[on_plate]) / OMEGA < 1.0
        sim.remove(impeller)
        sim.run(10000)
        after = sim.extractCoords()[np.isin(sim.extractIds(), carried[on_plate]), 2]
    assert len(after) == on_plate.sum() and np.all(after < PLATE_Z)
    assert mesh_walls(tmp_path / "in.pygran") == ["pg_mesh1", "pg_mesh1 pg_mesh2", "pg_mesh1"]
