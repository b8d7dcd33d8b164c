"""Materials softer than LIGGGHTS' 5 MPa guard run (soft_particles yes is sent)."""

import pytest

from pygran_core import registry, simulation
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT

#: The suite's soft material, made softer than the guard.
SOFTER = dict(SOFT, youngsModulus=1e6)


def test_soft_material_runs_and_falls_freely(tmp_path):
    require_solver(registry.get_engine("liggghts").locate_solver)
    params = {
        "engine": "liggghts",
        "model": "HertzMindlin",
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, 0, 2e-3),
        "gravity": (9.81, 0, 0, -1),
        "dt": 5e-7,
        "species": ({"material": SOFTER, "radius": 5e-5},),
        "output": str(tmp_path),
        "traj": {"pfile": None},
        "progress": False,
    }
    with simulation.DEM(**params) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 1e-3)
        sim.run(1000)
        assert sim.extractCoords()[0, 2] == pytest.approx(1e-3 - 0.5 * 9.81 * (1000 * 5e-7) ** 2, rel=1e-9)
    assert "soft_particles yes" in (tmp_path / "in.pygran").read_text()
