"""PyGran 1.x's monitor(var=..., nevery=, nrepeat=, nfreq=): LIGGGHTS' compute + fix ave/time."""

import math

import numpy as np
import pytest
from PyGran.params import stearicAcid

from PyGran import simulation

ENGINES = ["native", "liggghts"]


def require(engine):
    if engine == "liggghts":
        from pygran_liggghts.library import find_library

        from pygran_core.testing.solvers import require_solver

        require_solver(find_library)


@pytest.mark.parametrize("engine", ENGINES)
def test_kinetic_energy_averaged_in_free_fall(engine, tmp_path):
    require(engine)
    stearicAcid["cohesionEnergyDensity"] = 0.0  # spheres far apart: nothing to stick to
    params = {
        "engine": engine,
        "box": (-1e-2, 1e-2, -1e-2, 1e-2, -1e-2, 1e-2),
        "species": ({"material": stearicAcid, "radius": ("constant", 1e-3)},),
        "gravity": (9.81, 0, 0, -1),
        "dt": 5e-6,
        "output": str(tmp_path / "out"),
        "traj": {"pfile": None},
        "nsteps": 1e3,  # the script's own key
    }
    with simulation.DEM(**params) as sim:
        for x in (-5e-3, 0.0, 5e-3):
            sim.createParticles(1, "single", x, 0.0, 5e-3)
        ke = sim.monitor(
            var="ke", species="all", name="ensemble_ke", file="ke.dat", nevery=10, nrepeat=5, nfreq=100
        )
        sim.run(params["nsteps"] / 2, params["dt"])
        sim.run(params["nsteps"] / 2, params["dt"])
        sim.remove(ke)
        sim.run(100, params["dt"])
    lines = (tmp_path / "out" / "ke.dat").read_text().splitlines()
    assert lines[:2] == ["# Time-averaged data for fix ensemble_ke", "# TimeStep c_ensemble_ke"]
    data = np.loadtxt(tmp_path / "out" / "ke.dat")
    assert data[:, 0].tolist() == list(range(100, 1001, 100))  # none after remove()
    mass = 3 * stearicAcid["density"] * 4 / 3 * math.pi * 1e-3**3
    for step, average in data:
        window = np.arange(step - 40, step + 1, 10) * params["dt"]
        # velocity Verlet is exact under a constant force: v = g t
        assert average == pytest.approx(np.mean(0.5 * mass * (9.81 * window) ** 2), rel=1e-9)
    np.testing.assert_array_equal(ke.values["ke"], data[:, 1])
