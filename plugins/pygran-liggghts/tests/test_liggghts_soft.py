"""Materials softer than LIGGGHTS' 5 MPa guard run (soft_particles yes is sent)."""

import pytest

from pygran_core import registry, simulation
from pygran_core.testing.solvers import require_solver

SOFT = {
    "youngsModulus": 1e6,
    "poissonsRatio": 0.3,
    "coefficientRestitution": 0.5,
    "coefficientFriction": 0.5,
    "density": 1000.0,
}


def test_soft_material_runs_and_falls_freely(tmp_path):
    require_solver(registry.get_engine("liggghts").locate_solver)
    params = {
        "engine": "liggghts",
        "model": "HertzMindlin",
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, 0, 2e-3),
        "gravity": (9.81, 0, 0, -1),
        "dt": 5e-7,
        "species": ({"material": SOFT, "radius": 5e-5},),
        "output": str(tmp_path),
        "traj": {"pfile": None},
        "progress": False,
    }
    with simulation.DEM(**params) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 1e-3)
        sim.run(1000)
        assert sim.extractCoords()[0, 2] == pytest.approx(1e-3 - 0.5 * 9.81 * (1000 * 5e-7) ** 2, rel=1e-9)
    assert "soft_particles yes" in (tmp_path / "in.pygran").read_text()


def test_set_velocity_and_radius_by_species_region_and_ids(tmp_path):
    require_solver(registry.get_engine("liggghts").locate_solver)
    species = ({"material": SOFT, "radius": 5e-5}, {"material": SOFT, "radius": 5e-5})
    params = {
        "engine": "liggghts",
        "model": "HertzMindlin",
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, 0, 2e-3),
        "dt": 5e-7,
        "species": species,
        "output": str(tmp_path),
        "traj": {"pfile": None},
        "progress": False,
    }
    with simulation.DEM(**params) as sim:
        for k, x in enumerate((-6e-4, -2e-4, 2e-4, 6e-4)):
            sim.createParticles(1 + k % 2, "single", x, 0.0, 1e-3)
        assert sim.velocity(species=2, vel=(0, 0, 0.1)) == 2
        assert sim.set(region=("block", 0, 1e-3, -1e-3, 1e-3, 0, 2e-3), radius=8e-5) == 2
        assert sim.set(ids=[1], vel=(0.2, 0, 0)) == 1
        assert sim.extractVelocities()[:, 0].tolist() == [0.2, 0, 0, 0]
        assert sim.extractVelocities()[:, 2].tolist() == [0, 0.1, 0, 0.1]
        assert sim.extractRadii().tolist() == pytest.approx([5e-5, 5e-5, 8e-5, 8e-5])
        mass = sim.engine.extract("mass")
        assert mass[2] / mass[0] == pytest.approx((8 / 5) ** 3)
