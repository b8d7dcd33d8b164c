"""The engine conformance suite (:mod:`pygran_core.testing.engines`) on real LIGGGHTS."""

import numpy as np
import pytest

from pygran_core.testing.engines import GRAVITY, MATERIAL, RADIUS, EngineConformance
from pygran_core.testing.validation import sphere_mass


class TestLiggghtsConformance(EngineConformance):
    engine = "liggghts"
    refuses = frozenset({"monitor-contacts", "monitor-wall_force"})
    raw_command = "set atom 1 vx 0.5"

    def test_multisphere(self, tmp_path):
        """The suite's tablet of two touching spheres, as LIGGGHTS makes one: by insertion only
        (as the step after the call starts, as every LIGGGHTS insertion), its spheres given one
        row each (the original PyGran's extracts) with the body's mass, which LIGGGHTS computes
        by Monte Carlo over 1e6 samples. It falls as one body: its spheres 2 R apart, both by v1 T - g T^2 / 2
        (velocity Verlet from the state after the step it was inserted in)."""
        species = (
            {"style": "multisphere/tablet", "material": dict(MATERIAL), "nspheres": 2}
            | {"radius": RADIUS, "length": 4 * RADIUS},
        )
        region = ("block", -3e-3, 3e-3, -3e-3, 3e-3, -3e-3, 3e-3)
        with self.dem(tmp_path, species=species, dt=self.dt(), gravity=GRAVITY) as sim:
            sim.insert(species=1, value=1, region=region)
            sim.run(1)
            x1, v1 = sim.extractCoords(), sim.extractVelocities()
            sim.run(1000)
            x, bodies, mass = sim.extractCoords(), sim.engine.bodies(), sim.engine.extract("mass")
            duration = 1000 * sim.engine.dt
        assert bodies.tolist() == [1, 1]
        assert np.linalg.norm(x[1] - x[0]) == pytest.approx(2 * RADIUS, rel=1e-12)
        np.testing.assert_allclose(
            x - x1,
            v1 * duration + np.array(GRAVITY[1:]) * GRAVITY[0] * duration**2 / 2,
            rtol=1e-9,
            atol=1e-12,
        )
        # each sphere carries the body's mass, which LIGGGHTS computes by Monte Carlo
        assert mass[0] == mass[1] == pytest.approx(2 * sphere_mass(MATERIAL, RADIUS), rel=2e-3)
