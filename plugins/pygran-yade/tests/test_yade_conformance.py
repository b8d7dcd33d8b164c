"""The engine conformance suite (:mod:`pygran_core.testing.engines`) on real YADE."""

import numpy as np
import pytest

from pygran_core.testing.engines import GRAVITY, MATERIAL, RADIUS, EngineConformance, sphere_mass


class TestYadeConformance(EngineConformance):
    engine = "yade"
    options = {"threads": 1}  # test_threads compares with two
    refuses = frozenset({"set", "set-radius", "monitor-wall_force"})
    raw_command = "O.bodies[0].state.vel = (0.5, 0.0, 0.0)"

    def test_multisphere(self, tmp_path):
        """The suite's tablet of two touching spheres as one YADE clump: its spheres given one
        row each (as the LIGGGHTS engine and the original PyGran's extracts), each with the
        body's mass (the two spheres' masses: they do not overlap), falling together by
        g t^2 / 2 and staying 2 R apart."""
        species = (
            {"style": "multisphere/tablet", "material": dict(MATERIAL), "nspheres": 2}
            | {"radius": RADIUS, "length": 4 * RADIUS},
        )
        with self.dem(tmp_path, species=species, dt=self.dt(), gravity=GRAVITY) as sim:
            assert sim.createParticles(1, "single", 0.0, 0.0, 0.0) == 1
            x0 = sim.extractCoords()
            sim.run(1000)
            x, t = sim.extractCoords(), sim.time
            bodies, mass = sim.engine.bodies(), sim.engine.extract("mass")
        assert len(x) == 2 and bodies[0] == bodies[1] > 0
        np.testing.assert_allclose(x0, [[-RADIUS, 0.0, 0.0], [RADIUS, 0.0, 0.0]], atol=1e-18)
        assert np.linalg.norm(x[1] - x[0]) == pytest.approx(2 * RADIUS, rel=1e-12)
        np.testing.assert_allclose(x[:, 2], -0.5 * GRAVITY[0] * t**2, rtol=1e-3)
        np.testing.assert_allclose(mass, 2 * sphere_mass(MATERIAL, RADIUS), rtol=1e-9)
