"""The engine suite's checks of runs and their options: the time-step check, lost particles, the
trajectory, threads and MPI ranks, periodic boundaries, size distributions, multisphere
particles and raw commands."""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pygran_core.errors import ConfigError, LostParticlesWarning, TimeStepWarning, UnsupportedFeature
from pygran_core.io import open_trajectory
from pygran_core.testing.engines.base import GRAVITY, MATERIAL, RADIUS, EngineSuite, G, create
from pygran_core.testing.validation import sphere_mass


class RunChecks(EngineSuite):
    """What a run checks and writes, and the options and capabilities it runs with."""

    def test_time_step_check(self, tmp_path):
        """Before a run, a time step too long for the contacts that can happen is refused and
        one that resolves them poorly warned about; a safe one is neither."""
        dt = self.dt()
        with self.dem(tmp_path, dt=dt) as sim:
            create(sim, [[-2e-3, 0, 0], [2e-3, 0, 0]])
            with pytest.raises(ConfigError, match="fewer than 3 steps"):
                sim.run(10, dt=1000 * dt)
            assert sim.step == 0
            with pytest.warns(TimeStepWarning):
                sim.run(10, dt=3 * dt)
            with warnings.catch_warnings():
                warnings.simplefilter("error", TimeStepWarning)
                sim.run(10, dt=dt)
            assert sim.step == 20

    def test_lost_particles(self, tmp_path):
        """A sphere leaving the box through its top is reported lost through z+."""
        dt = self.dt()
        with self.dem(tmp_path, dt=dt) as sim:
            create(sim, [[0, 0, 8e-3], [0, 0, -5e-3]], vel=(0.0, 0.0, 1.0))
            with pytest.warns(LostParticlesWarning, match="z\\+"):
                sim.run(round(0.005 / dt))
            assert len(sim.extractIds()) == 1 and sim.engine.lost == 1
            assert dict(sim.engine.last_lost.where) == {"z+": 1}

    def test_trajectory(self, tmp_path):
        """The trajectory file holds a frame every ``freq`` steps with the particles then."""
        traj = {"pfile": "traj.dump", "freq": 100}
        with self.dem(tmp_path, dt=self.dt(), traj=traj, gravity=GRAVITY) as sim:
            create(sim, [[0, 0, 0], [3e-3, 0, 0]], vel=(0.0, 0.1, 0.0))
            sim.run(200)
            ids, x = sim.extractIds(), sim.extractCoords()
        with open_trajectory(tmp_path / "traj.dump") as frames:
            assert [f.timestep for f in frames] == [0, 100, 200]
            last = frames[-1].arrays
        order = np.argsort(last["id"])
        np.testing.assert_array_equal(last["id"][order], ids)
        np.testing.assert_allclose(np.column_stack([last[k][order] for k in "xyz"]), x, rtol=1e-5, atol=1e-12)

    def columns(self, output: Path, **options: Any) -> np.ndarray:
        """Four columns of two spheres falling 0.2 mm onto a floor: positions and velocities
        after 1500 steps, with ``options`` (threads, nprocs) in place of the class's."""
        x = np.array([[i, j, k] for i in (-3e-3, 3e-3) for j in (-3e-3, 3e-3) for k in (1.2e-3, 3.4e-3)])
        box = (-6e-3, 6e-3, -6e-3, 6e-3, 0.0, 6e-3)
        with self.dem(output, dt=self.dt(), gravity=GRAVITY, box=box, **options) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            create(sim, x)
            sim.run(1500)
            return np.hstack([sim.extractCoords(), sim.extractVelocities()])

    def test_threads(self, tmp_path):
        """Two threads give what one does."""
        if not self.supports("threads"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, threads=2).close()
            return
        one = self.columns(tmp_path / "one", threads=1)
        np.testing.assert_allclose(self.columns(tmp_path / "two", threads=2), one, rtol=0, atol=1e-12)

    def test_mpi(self, tmp_path):
        """Two MPI ranks give what one does."""
        if not self.supports("mpi"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, nprocs=2).close()
            return
        one = self.columns(tmp_path / "one", nprocs=1)
        np.testing.assert_allclose(self.columns(tmp_path / "two", nprocs=2), one, rtol=0, atol=1e-12)

    def test_periodic(self, tmp_path):
        """Periodic in x: a sphere leaving through x+ comes back through x-, and two spheres
        meet across the boundary and bounce apart."""
        dt = self.dt()
        keywords: dict[str, Any] = {"dt": dt, "boundary": ("p", "f", "f")}
        if not self.supports("periodic"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, **keywords).close()
            return
        with self.dem(tmp_path, **keywords) as sim:
            sim.createParticles(1, "single", 8e-3, -5e-3, 0.0, vel=(0.1, 0.0, 0.0))
            sim.createParticles(1, "single", -8e-3, 5e-3, 0.0, vel=(-0.1, 0.0, 0.0))
            sim.createParticles(1, "single", 8e-3, 5e-3, 0.0, vel=(0.1, 0.0, 0.0))
            sim.run(round(0.03 / dt))
            x, v, t = sim.extractCoords(), sim.extractVelocities(), sim.time
        assert x[0, 0] == pytest.approx((8e-3 + 0.1 * t + 0.01) % 0.02 - 0.01, abs=1e-9)
        assert v[1, 0] > 0.05 and v[2, 0] < -0.05, v

    def test_polydisperse(self, tmp_path):
        """A normal size distribution (mean 1 mm, sd 0.1 mm, cut at 3 sd) gives each sphere its
        own radius within the cut, and the mass of that radius."""
        species = ({"material": dict(MATERIAL), "radius": ("normal", RADIUS, 0.1 * RADIUS)},)
        across = np.arange(-7.5e-3, 8e-3, 3e-3)
        x = np.stack(np.meshgrid(across, across, [0.0], indexing="ij"), -1).reshape(-1, 3)
        if not self.supports("polydisperse"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, species=species).close()
            return
        with self.dem(tmp_path, species=species, dt=self.dt(0.7 * RADIUS)) as sim:
            create(sim, x)
            r, mass = sim.extractRadii(), sim.engine.extract("mass")
        assert len(r) == len(x) and np.all((r >= 0.7 * RADIUS) & (r <= 1.3 * RADIUS))
        assert 0.05 * RADIUS < np.std(r) < 0.15 * RADIUS and abs(np.mean(r) / RADIUS - 1) < 0.06
        np.testing.assert_allclose(mass, 4 / 3 * math.pi * r**3 * MATERIAL["density"], rtol=1e-9)

    def test_multisphere(self, tmp_path):
        """A tablet of two touching spheres, inserted in a region (LIGGGHTS makes multisphere
        particles by insertion only), falls as one rigid body. Extracts give each of its
        spheres a row (the original PyGran's convention), each carrying the body's mass, here
        the two spheres' (they do not overlap; LIGGGHTS integrates it by Monte Carlo, to
        0.2 %). The drop after the step of its insertion is ``v1 T - g T^2 / 2`` to within the
        integrator's order (a leapfrog's velocity lags half a step: 1/1000 of the drop)."""
        species = (
            {"style": "multisphere/tablet", "material": dict(MATERIAL), "nspheres": 2}
            | {"radius": RADIUS, "length": 4 * RADIUS},
        )
        if not self.supports("multisphere"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, species=species).close()
            return
        dt, steps = self.dt(), 1000
        region = ("block", -3e-3, 3e-3, -3e-3, 3e-3, -3e-3, 3e-3)
        with self.dem(tmp_path, species=species, dt=dt, gravity=GRAVITY) as sim:
            sim.insert(species=1, value=1, region=region)
            sim.run(1)
            x1, v1 = sim.extractCoords(), sim.extractVelocities()
            sim.run(steps)
            x, mass = sim.extractCoords(), sim.engine.extract("mass")
        assert len(x) == len(x1) == 2, x
        assert np.linalg.norm(x[1] - x[0]) == pytest.approx(2 * RADIUS, rel=1e-12)
        g, duration = G * np.array(GRAVITY[1:]), steps * dt
        np.testing.assert_allclose(x - x1, v1 * duration + g * duration**2 / 2, rtol=2e-3, atol=1e-12)
        assert mass[0] == mass[1] == pytest.approx(2 * sphere_mass(MATERIAL, RADIUS), rel=2e-3), mass

    def test_raw_commands(self, tmp_path):
        """The engine's native command (:attr:`raw_command`) reaches the solver."""
        with self.dem(tmp_path, dt=self.dt()) as sim:
            sim.createParticles(1, "single", 0.0, 0.0, 0.0)
            if not self.supports("raw-commands"):
                with pytest.raises(UnsupportedFeature):
                    sim.command("run 0")
                return
            assert self.raw_command is not None, "an engine declaring raw-commands gives raw_command"
            sim.command(self.raw_command)
            sim.run(10)
            v = sim.extractVelocities()[0]
        np.testing.assert_allclose(v, [0.5, 0.0, 0.0], rtol=1e-12)
