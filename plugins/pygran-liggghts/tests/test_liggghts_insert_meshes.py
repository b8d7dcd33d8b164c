"""insert() on LIGGGHTS into a region that a mesh wall crosses: LIGGGHTS' fix insert keeps
clear of particles only, so such an insertion (by pack or by rate) is made by PyGran, clear of
the mesh, as the placing engines make it; one into the inside of the mesh stays LIGGGHTS' own."""

import shutil
import warnings

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.errors import ConfigError, InsertionWarning
from pygran_core.simulation import geometry
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT as MATERIAL

R = 1e-3
DRUM = geometry.drum(radius=0.02, length=0.02, axis="y")
#: A block whose corners stick out of the drum (its half-diagonal 27 mm, the drum's radius 20 mm).
BLOCK = ("block", -0.019, 0.019, -0.009, 0.009, -0.019, 0.019)


def dem(output, engine="liggghts", **settings):
    require_solver(find_library)
    return simulation.DEM(
        engine=engine,
        model="HertzMindlin",
        box=(-0.025, 0.025, -0.015, 0.015, -0.025, 0.025),
        gravity=(9.81, 0, 0, -1),
        dt=1e-5,
        output=str(output),
        species=({"material": MATERIAL, "radius": R},),
        mesh={"drum": {"triangles": DRUM, "material": MATERIAL}},
        traj={"pfile": None},
        progress=False,
        **settings,
    )


def clearance(x):
    """Each centre's distance to the drum's nearest triangle, in radii."""
    return geometry.triangle_distance(x, DRUM.triangles) / R


def test_a_block_crossing_the_drum_is_filled_clear_of_it(tmp_path):
    with dem(tmp_path / "liggghts") as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.insert(species=1, value=300, region=BLOCK, seed=7)
        placed = sim.extractCoords()
        sim.run(200)
        assert len(sim.extractCoords()) == 300 and sim.lost == 0
    assert len(placed) == 300
    assert clearance(placed).min() >= 1.0
    assert np.sum(clearance(placed) < 2) > 10  # the mesh is where they are: some lie against it
    assert "insert/pack" not in (tmp_path / "liggghts" / "in.pygran").read_text()
    with dem(tmp_path / "native", engine="native") as sim:  # the placing engines' particles
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.insert(species=1, value=300, region=BLOCK, seed=7)
        np.testing.assert_allclose(sim.extractCoords(), placed, rtol=0, atol=1e-15)


def test_more_than_fits_is_reported_at_the_users_line(tmp_path):
    with dem(tmp_path) as sim, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.insert(species=1, value=3500, region=BLOCK)
        made = len(sim.extractCoords())
    short = [w for w in caught if issubclass(w.category, InsertionWarning)]
    assert len(short) == 1 and short[0].filename == __file__
    assert f"{made} of 3500 particles inserted" in str(short[0].message)
    assert 1000 < made < 3500


def test_by_rate_across_the_drum_keeps_its_rate_clear_of_it(tmp_path):
    """1e5 particles/s every 100 steps of 1e-5 s: 100 at the call, then at steps 100 and 200 of
    the run, each batch clear of the drum and of the particles before it."""
    with dem(tmp_path) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.insert(species=1, value=1e5, region=BLOCK, insert="by_rate", freq=100, seed=3)
        assert clearance(sim.extractCoords()).min() >= 1.0
        sim.run(250)
        x = sim.extractCoords()
        assert sim.lost == 0
    assert len(x) == 300
    log = (tmp_path / "pygran.log").read_text()
    for step in (0, 100, 200):
        assert f"insert at step {step}: 100 of 100 particles, placed by PyGran clear of mesh drum" in log
    assert clearance(x).min() > 0.99  # 2.5 ms later: resting on the drum at most
    assert "insert/rate/region" not in (tmp_path / "in.pygran").read_text()


def test_inside_the_drum_liggghts_inserts_by_rate_itself(tmp_path):
    """A region that is the drum's inside (LIGGGHTS' cylinder inscribed in it) is clear of it."""
    with dem(tmp_path) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.insert(species=1, value=1e5, region=("mesh", DRUM), insert="by_rate", freq=100)
        sim.run(250)
        x = sim.extractCoords()
    assert "insert/rate/region" in (tmp_path / "in.pygran").read_text()
    assert len(x) > 100 and clearance(x).min() > 0.99


def test_moving_the_mesh_while_pygran_inserts_across_it_is_refused(tmp_path):
    """PyGran places clear of the mesh where it stands; a moving mesh's position is LIGGGHTS'."""
    with dem(tmp_path) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        inserting = sim.insert(species=1, value=1e5, region=BLOCK, insert="by_rate", freq=100)
        with pytest.raises(
            ConfigError, match=r"moveMesh\('drum'\) while the insertion .* Remove that insertion"
        ):
            sim.moveMesh("drum", rotate=True, axis=(0, 1, 0), origin=(0, 0, 0), omega=1.0)
        sim.remove(inserting)
        sim.moveMesh("drum", rotate=True, axis=(0, 1, 0), origin=(0, 0, 0), omega=1.0)
        sim.run(200)
        assert len(sim.extractCoords()) == 100  # the batch made at the call only


def resumable(output, restart):
    """By rate across the drum (100 every 100 steps), then, at step 300 (a checkpoint's), 5
    particles created at random and 50 inserted at once."""
    require_solver(find_library)
    with dem(output, restart=restart) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="drum")
        sim.insert(species=1, value=1e5, region=BLOCK, insert="by_rate", freq=100, seed=3)
        sim.run(300)
        sim.createParticles(1, "random", 5, region=BLOCK, seed=5)
        sim.insert(species=1, value=50, region=BLOCK, seed=4)
        sim.run(150)
        return len(sim.extractCoords()), sim.lost


@pytest.mark.parametrize("step", [200, 300])
def test_a_resumed_run_goes_on_inserting_across_the_drum(tmp_path, step):
    """LIGGGHTS creates no atoms after reading a restart file until it has run: it runs 0 steps."""
    straight = resumable(tmp_path / "straight", (100, "restart", "restart.*.h5"))
    assert straight == (5 * 100 + 5 + 50, 0)  # events at steps 0, 100, ..., 400
    shutil.copytree(tmp_path / "straight", tmp_path / "resumed")
    restart = (100, "restart", "restart.*.h5", True, f"restart.{step}.h5")
    assert resumable(tmp_path / "resumed", restart) == straight
