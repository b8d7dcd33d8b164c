"""The native engine through simulation.DEM: the front end's calls on the compiled solver."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pygran_core import analysis, simulation
from pygran_core.errors import ConfigError, UnsupportedFeature
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.validation import SOFT

SILO = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes" / "silo.stl"


def dem(tmp_path, **overrides):
    params = {
        "engine": "native",
        "model": HertzMindlin,
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, -1e-3, 4e-3),
        "gravity": (9.81, 0, 0, -1),
        "dt": 5e-7,
        "output": str(tmp_path / "out"),
        "progress": False,
        "species": ({"material": SOFT, "radius": 5e-5},),
        "traj": {"pfile": None},
        "threads": 1,
    }
    return simulation.DEM(**{**params, **overrides})


def test_free_fall_is_exact(tmp_path):
    with dem(tmp_path) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 3e-3, vel=(0.01, 0, 0))
        sim.run(2000)
        t = 2000 * 5e-7
        np.testing.assert_allclose(
            sim.extractCoords()[0], [0.01 * t, 0, 3e-3 - 0.5 * 9.81 * t**2], rtol=1e-12
        )
        np.testing.assert_allclose(sim.extractVelocities()[0], [0.01, 0, -9.81 * t], rtol=1e-12)


def test_insertion_is_overlap_free_and_reproducible(tmp_path):
    region = ("block", -9e-4, 9e-4, -9e-4, 9e-4, 0.0, 3e-3)
    positions = []
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        with dem(
            tmp_path / name, seed=seed, species=({"material": SOFT, "radius": ("normal", 5e-5, 5e-6)},)
        ) as sim:
            sim.insert(species=1, value=400, region=region)
            positions.append(sim.extractCoords())
            radii = sim.extractRadii()
    assert len(positions[0]) == 400
    np.testing.assert_array_equal(positions[0], positions[1])
    assert not np.array_equal(positions[0], positions[2])
    pairs = cKDTree(positions[2]).query_pairs(2 * radii.max(), output_type="ndarray")
    gaps = np.linalg.norm(positions[2][pairs[:, 0]] - positions[2][pairs[:, 1]], axis=1)
    assert np.all(gaps >= radii[pairs[:, 0]] + radii[pairs[:, 1]])


def test_viscous_drag_gives_the_terminal_velocity(tmp_path):
    """To 1e-6 and, once the drag is removed, to 1e-9 with velocity Verlet's lag (the
    conformance suite checks the drag law to 1e-3 on every engine)."""
    with dem(tmp_path, dt=1e-5) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 3e-3)
        mass = SOFT["density"] * 4 / 3 * np.pi * 5e-5**3
        gamma = mass / 1e-3  # relaxation time 1 ms
        drag = sim.addViscous(gamma=gamma)
        sim.run(2000)  # 20 relaxation times
        assert sim.extractVelocities()[0, 2] == pytest.approx(-9.81 * 1e-3, rel=1e-6)
        sim.remove(drag)
        sim.run(100)
        # velocity Verlet: the first half kick after removal still uses the force computed with drag
        lag = 0.5 * 1e-5 * (gamma / mass) * 9.81e-3
        assert sim.extractVelocities()[0, 2] == pytest.approx(-9.81e-3 - 100 * 1e-5 * 9.81 + lag, rel=1e-9)


def test_hopper_fills_then_discharges_after_the_stopper_is_removed(tmp_path):
    mesh = {"hopper": {"file": str(SILO), "mtype": "mesh/surface", "material": SOFT, "args": ("scale 1e-3",)}}
    with dem(tmp_path, mesh=mesh, traj={"pfile": "traj.h5", "freq": 10000}) as sim:
        sim.setupWall(wtype="mesh", species=1, mesh="hopper")
        stopper = sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=300, region=("cylinder", "z", 0, 0, 5.5e-4, 1.6e-3, 3e-3))
        assert len(sim.extractIds()) == 300
        sim.run(20000)
        z = sim.extractCoords()[:, 2]
        assert len(z) == 300 and z.min() > 0
        sim.remove(stopper)
        sim.engine.expect_outflow("z-")  # the outlet lets them fall out of the box: logged, not warned
        sim.run(40000)
        remaining = len(sim.extractIds())
        assert dict(sim.engine.last_lost.where) == {"z-": 300 - remaining} == {"z-": sim.engine.lost}
    assert remaining < 300 - 30, "the hopper did not discharge"
    system = analysis.System(Particles=str(tmp_path / "out" / "traj.h5"))
    assert len(system) == 7  # steps 0, 10000, ..., 60000
    system.goto(-1)
    assert len(system.Particles) == remaining


def test_unsupported_and_wrong_calls_are_clear(tmp_path):
    mesh = {"hopper": {"file": str(SILO), "args": ("scale 1e-3",), "import": False}}
    with dem(tmp_path, mesh=mesh) as sim:
        with pytest.raises(
            ConfigError, match="not a wall yet: call setupWall\\(wtype='mesh', mesh='hopper'\\)"
        ):
            sim.moveMesh("hopper", linear=(0, 0, 1e-3))
        sim.setupWall(wtype="mesh", mesh="hopper")
        sim.moveMesh("hopper", wiggle=True, amplitude=(0, 0, 1e-4), period=0.01)
        with pytest.raises(ConfigError, match="already moves"):
            sim.moveMesh("hopper", linear=(0, 0, 1e-3))
    with pytest.raises(ConfigError, match="at least one species"):
        simulation.DEM(engine="native", box=(0, 1, 0, 1, 0, 1), output=str(tmp_path / "x"))

    class Plastic(simulation.models.SpringDashpot):
        """A model from a plugin with a force law the native engine has no kernel for."""

        kernel = "thornton-ning-2"

    with pytest.raises(UnsupportedFeature, match="does not support the Plastic contact model"):
        dem(tmp_path, model=Plastic)


def test_velocity_by_species_with_spin_and_no_radius(tmp_path):
    """velocity() chooses by species and sets spins too; a radius is set(), not velocity()
    (the conformance suite sets velocities, spins and radii by ids and regions)."""
    species = ({"material": SOFT, "radius": 5e-5}, {"material": SOFT, "radius": 5e-5})
    with dem(tmp_path, gravity=None, species=species) as sim:
        for k, x in enumerate((-6e-4, -2e-4, 2e-4, 6e-4)):
            sim.createParticles(1 + k % 2, "single", x, 0.0, 1e-3)
        assert sim.velocity(species=2, vel=(0, 0, 0.1), omega=(1, 0, 0)) == 2
        np.testing.assert_array_equal(sim.extractVelocities()[:, 2], [0, 0.1, 0, 0.1])
        np.testing.assert_array_equal(sim.extractOmegas()[:, 0], [0, 1, 0, 1])
        with pytest.raises(ConfigError, match="use set\\(radius=...\\)"):
            sim.velocity(radius=1e-4)


def test_an_array_of_positions_draws_a_radius_per_particle(tmp_path):
    """Each row of an (N, 3) array gets its own radius from the species' distribution; an
    array of another shape is refused (the conformance suite checks the rows' positions)."""
    positions = np.random.default_rng(1).uniform(-8e-4, 8e-4, (50, 3)) * (1, 1, 0) + (0, 0, 1e-3)
    positions[:, 2] += np.arange(50) * 5e-5
    species = ({"material": SOFT, "radius": ("normal", 5e-5, 5e-6)},)
    with dem(tmp_path, species=species, seed=3) as sim:
        assert sim.createParticles(1, "single", positions, vel=(0, 0, -0.1)) == 50
        assert len(np.unique(sim.extractRadii())) == 50
        with pytest.raises(ConfigError, match=r"\(N, 3\) array of finite coordinates, got shape \(4, 2\)"):
            sim.createParticles(1, "single", np.zeros((4, 2)))
