"""``monitor(var='ke', species=k, ...)`` on the native engine (capability ``monitor-species``):
the core's sampling of some species, on native's particles."""

import numpy as np
import pytest

from pygran_core import simulation
from pygran_core.params import cohesionless, organic


def test_a_monitor_of_one_species_sums_its_kinetic_energy_only(tmp_path):
    """Two species falling side by side (spheres far apart, of two radii):
    at each output step (0 too), the monitor of species 2 (nevery=nfreq, one sample) is 1/2 m v^2
    summed over species 2 as extracted then (1e-12), less than the whole's, and its
    ``erotate`` monitor is 1/2 (2/5 m r^2) w^2 summed over species 2 (spinning spheres of both)."""
    params = {
        "engine": "native",
        "box": (-1e-2, 1e-2, -1e-2, 1e-2, -1e-2, 1e-2),
        "species": ({"material": organic, "radius": 1e-3}, {"material": cohesionless, "radius": 5e-4}),
        "gravity": (9.81, 0, 0, -1),
        "dt": 1e-6,
        "output": str(tmp_path / "out"),
        "traj": {"pfile": None},
    }
    with simulation.DEM(**params) as sim:
        for x in (-6e-3, -2e-3):
            sim.createParticles(1, "single", x, 0.0, 5e-3)
        for x in (2e-3, 6e-3, 8e-3):
            sim.createParticles(2, "single", x, 0.0, 5e-3)
        sim.set(vel=(0.3, 0, 0.1), omega=(0, 50, 0), ids=[4])
        sim.set(omega=(20, 0, 0), ids=[1])
        ke = sim.monitor(var="ke", species=2, name="ke2", file="ke2.dat", nevery=100, nrepeat=1, nfreq=100)
        spin = sim.monitor(
            var="erotate", species=2, name="rot2", file="rot2.dat", nevery=100, nrepeat=1, nfreq=100
        )
        expected, whole, rotation = [], [], []
        for k in range(6):  # step 0 (where LIGGGHTS' fix ave/time samples too), then every 100
            if k:
                sim.run(100, params["dt"])
            types = sim.engine.extract("type")
            mass, v = sim.engine.extract("mass"), sim.engine.extract("v")
            energy = 0.5 * mass * np.sum(v * v, axis=1)
            expected.append(energy[types == 2].sum())
            w, r = sim.engine.extract("omega"), sim.engine.extract("radius")
            rotation.append((0.2 * mass * r**2 * np.sum(w * w, axis=1))[types == 2].sum())
            whole.append(energy.sum())
    assert ke.values["ke"] == pytest.approx(expected, rel=1e-12)
    assert np.all(ke.values["ke"][1:] < np.array(whole[1:]))  # species 1 falls from rest
    assert spin.values["erotate"] == pytest.approx(rotation, rel=1e-12)
    assert min(rotation) > 0
