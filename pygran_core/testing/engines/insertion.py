"""The engine suite's checks of ``insert``: by pack once and on a schedule, and by rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pygran_core.errors import UnsupportedFeature
from pygran_core.testing.engines.base import GRAVITY, MATERIAL, RADIUS, EngineSuite


class InsertionChecks(EngineSuite):
    """``insert`` by pack (once and every ``freq`` steps) and by rate."""

    def test_insert_by_pack(self, tmp_path):
        """Once by pack (no gravity): 30 spheres of two species in number fractions 1:3 with
        velocities uniform within +-0.1 m/s and a given spin, then 5 more on top of them in
        the same region; a volume fraction of 0.1 in another region, to within one sphere."""
        low = ("block", -9e-3, 9e-3, -9e-3, 9e-3, -9e-3, 0.0)
        high = ("block", -5e-3, 5e-3, -5e-3, 5e-3, 4e-3, 8e-3)
        species = ({"material": dict(MATERIAL), "radius": RADIUS},) * 2
        first = dict(species=(1, 2), weights=(0.25, 0.75), value=30, region=low)
        spread = dict(vel_type="uniform", vel=(0, 0, 0, 0.1, 0.1, 0.1), omega=("constant", 0, 0, 5))
        with self.dem(tmp_path, dt=self.dt(), species=species) as sim:
            if not self.supports("insert"):
                with pytest.raises(UnsupportedFeature):
                    sim.insert(**first)
                    sim.run(1)
                return
            sim.insert(**first, **spread)
            sim.run(1)
            types, v, w = sim.engine.extract("type"), sim.extractVelocities(), sim.extractOmegas()
            sim.insert(species=1, value=5, region=low)
            sim.run(1)
            assert len(sim.extractIds()) == 35
            sim.insert(species=1, mech="volumefraction_region", value=0.1, region=high)
            sim.run(1)
            x, r = sim.extractCoords(), sim.extractRadii()
        assert len(types) == 30 and abs(np.count_nonzero(types == 2) - 22.5) <= 8, np.bincount(types)
        assert np.abs(v).max() <= 0.1 + 1e-9 and np.all(v.std(axis=0) > 0.03), v
        np.testing.assert_allclose(w, [[0.0, 0.0, 5.0]] * 30, rtol=1e-12)
        upper = x[:, 2] > 2e-3
        assert np.count_nonzero(~upper) == 35
        assert np.all((x[~upper, 2] >= -9e-3 + r[~upper] - 1e-5) & (x[~upper, 2] <= -r[~upper] + 1e-5))
        sphere, volume = 4 / 3 * math.pi * RADIUS**3, 1e-2 * 1e-2 * 4e-3
        assert abs(np.count_nonzero(upper) * sphere - 0.1 * volume) <= sphere, np.count_nonzero(upper)

    def test_insert_by_pack_every_freq(self, tmp_path):
        """By pack every 500 steps: spheres thrown down (1 m/s) leave the region between
        insertions, so each refills it with 8; removing the insertion stops it."""
        box = (-6e-3, 6e-3, -6e-3, 6e-3, -0.04, 0.01)
        region = ("block", -5e-3, 5e-3, -5e-3, 5e-3, 5e-3, 9e-3)
        with self.dem(tmp_path, dt=self.dt(), box=box, gravity=GRAVITY) as sim:
            if not self.supports("insert"):
                with pytest.raises(UnsupportedFeature):
                    sim.insert(species=1, value=8, region=region, freq=500)
                    sim.run(1)
                return
            handle = sim.insert(species=1, value=8, region=region, freq=500, vel=(0.0, 0.0, -1.0))
            counts = []
            for steps in (1, 500, 500):
                sim.run(steps)
                counts.append(len(sim.extractIds()))
            sim.remove(handle)
            sim.run(1000)
            counts.append(len(sim.extractIds()))
        assert counts == [8, 16, 24, 24]

    def test_insert_by_rate(self, tmp_path):
        """By rate, PyGran 1.x's form (``mech='nparticles'``, ``value`` in all, ``rate`` per
        second): 24 spheres at 8 per insertion every 500 steps, then no more."""
        dt = self.dt()
        box = (-6e-3, 6e-3, -6e-3, 6e-3, -0.04, 0.01)
        region = ("block", -5e-3, 5e-3, -5e-3, 5e-3, 5e-3, 9e-3)
        request = dict(
            species=1,
            insert="by_rate",
            mech="nparticles",
            value=24,
            rate=8 / (500 * dt),
            freq=500,
            region=region,
            vel=(0.0, 0.0, -1.0),
        )
        with self.dem(tmp_path, dt=dt, box=box, gravity=GRAVITY) as sim:
            if not self.supports("insert-by-rate"):
                with pytest.raises(UnsupportedFeature):
                    sim.insert(**request)
                return
            sim.insert(**request)
            counts = []
            for steps in (1, 500, 500, 1000):
                sim.run(steps)
                counts.append(len(sim.extractIds()))
        assert counts == [8, 16, 24, 24]
