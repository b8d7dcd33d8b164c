"""The engine suite's checks of forces and monitors: drag, gravity, every monitor quantity, ``set``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.dem import DEM
from pygran_core.testing.engines.base import GRAVITY, MATERIAL, RADIUS, EngineSuite, G
from pygran_core.testing.validation import sphere_mass


class ForceChecks(EngineSuite):
    """``addViscous``, gravity over runs of two time steps, monitors, ``set``."""

    def test_viscous_drag(self, tmp_path):
        """A drag on species 2 only slows its sphere as ``exp(-gamma scale t / m)``; the sphere
        of species 1 keeps its speed; removed, the drag stops."""
        dt, v = self.dt(), 0.1
        species = ({"material": dict(MATERIAL), "radius": RADIUS},) * 2
        mass = sphere_mass(MATERIAL, RADIUS)
        steps = 1000
        gamma, scale = 0.25 * mass / (steps * dt), 2.0
        with self.dem(tmp_path, dt=dt, species=species) as sim:
            sim.createParticles(1, "single", 0.0, -3e-3, 0.0, vel=(v, 0.0, 0.0))
            sim.createParticles(2, "single", 0.0, 3e-3, 0.0, vel=(v, 0.0, 0.0))
            if not self.supports("viscous"):
                with pytest.raises(UnsupportedFeature):
                    sim.addViscous(gamma=gamma, species=2, scale=scale)
                    sim.run(1)
                return
            drag = sim.addViscous(gamma=gamma, species=2, scale=scale)
            sim.run(steps)
            slowed = sim.extractVelocities()[:, 0]
            sim.remove(drag)
            sim.run(steps)
            after = sim.extractVelocities()[:, 0]
        assert slowed[0] == pytest.approx(v, rel=1e-12)
        assert slowed[1] == pytest.approx(v * math.exp(-0.5), rel=1e-3)
        np.testing.assert_allclose(after, slowed, rtol=1e-3)  # the drag (40 % over a run) stopped

    def test_gravity_and_monitor(self, tmp_path):
        """Free fall along (0.6, 0, -0.8) over two runs of different time steps follows the
        closed form; a monitor samples n, time and ke = m (g t)^2 / 2 at its frequency into
        memory and its file, PyGran 1.x's averaged monitor averages them, and a removed
        monitor samples no more.

        Positions within 1e-3 of the closed form: velocity Verlet gives it exactly, a leapfrog
        taking the initial velocity at -dt/2 is off by dt/t.
        """
        dt = self.dt()
        direction = np.array([0.6, 0.0, -0.8])
        mass = sphere_mass(MATERIAL, RADIUS)
        with self.dem(tmp_path, dt=dt, gravity=(G, *direction)) as sim:
            sim.createParticles(1, "single", -5e-3, 0.0, 5e-3)
            monitor = sim.monitor(quantities=("ke", "n", "time"), freq=250, file="fall.txt")
            averaged = sim.monitor(var="ke", name="keavg", nevery=10, nrepeat=5, nfreq=250)
            sim.run(2000)
            sim.run(1000, dt=dt / 2)
            x, v, t = sim.extractCoords()[0], sim.extractVelocities()[0], sim.time
            sim.remove(monitor)
            sim.run(250)
            samples, means = monitor.values, averaged.values
        assert sim.step == 3250 and t == pytest.approx(2500 * dt, rel=1e-12)
        np.testing.assert_allclose(v, G * t * direction, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(x - [-5e-3, 0.0, 5e-3], 0.5 * G * t**2 * direction, rtol=1e-3, atol=1e-12)
        steps = np.arange(0, 3001, 250)
        np.testing.assert_array_equal(samples["step"], steps)
        times = np.where(steps <= 2000, steps * dt, 2000 * dt + (steps - 2000) * dt / 2)
        np.testing.assert_allclose(samples["time"], times, rtol=1e-12)
        np.testing.assert_array_equal(samples["n"], 1)
        np.testing.assert_allclose(samples["ke"], 0.5 * mass * (G * times) ** 2, rtol=1e-9, atol=1e-30)
        lines = (tmp_path / "fall.txt").read_text().splitlines()
        assert len(lines) == 1 + len(steps) and lines[0].startswith("#")
        window = np.arange(-40, 1, 10)
        expected = [np.mean(0.5 * mass * (G * (k + window) * dt) ** 2) for k in range(250, 2001, 250)]
        np.testing.assert_allclose(means["ke"][:8], expected, rtol=1e-9)
        assert (tmp_path / "keavg.dat").read_text().count("\n") == 2 + len(means["ke"])

    def probe_monitor(self, sim: DEM, quantity: str) -> Any:
        """A monitor of ``quantity`` every step, or ``None`` once its refusal is asserted (at
        the call or at the first sample)."""
        if self.supports(f"monitor-{quantity}"):
            return sim.monitor(quantities=(quantity,), freq=1, file=f"{quantity}.txt")
        with pytest.raises(UnsupportedFeature):
            refused = sim.monitor(quantities=(quantity,), freq=1, file=f"{quantity}.txt")
            try:
                sim.run(1)
            finally:
                sim.remove(refused)
        return None

    def test_optional_monitors(self, tmp_path):
        """ke_rot of a spinning sphere is I w^2 / 2; contacts counts two pairs of spheres (no
        other contact) while they collide head-on, none before or after; wall_force of a
        sphere settling on a floor (added only where wall_force is supported: a floor holds a
        contact of its own) averages its weight. A quantity the engine refuses raises
        UnsupportedFeature, at the call or at its first sample."""
        dt, mass = self.dt(), sphere_mass(MATERIAL, RADIUS)
        sphere = dict(MATERIAL, radius=RADIUS)
        contact_time = self.model(material=sphere, partner=sphere).contactTime(0.2)
        floor = self.supports("monitor-wall_force")
        with self.dem(tmp_path, dt=dt, gravity=GRAVITY if floor else None) as sim:
            if floor:
                sim.setupWall(species=1, plane="zplane", peq=-0.01)
                sim.createParticles(1, "single", 7e-3, 7e-3, -0.01 + RADIUS)
            sim.createParticles(1, "single", -7e-3, -7e-3, 7e-3, omega=(0.0, 0.0, 30.0))
            for y in (-4e-3, 4e-3):
                for side in (-1, 1):
                    sim.createParticles(1, "single", side * 1.25e-3, y, 0.0, vel=(-side * 0.1, 0.0, 0.0))
            monitors = {q: self.probe_monitor(sim, q) for q in ("ke_rot", "contacts", "wall_force")}
            sim.run(round(2 * (0.5e-3 / 0.2 + contact_time) / dt))
        spin, contacts, force = (monitors[q] for q in ("ke_rot", "contacts", "wall_force"))
        if spin is not None:
            inertia = 0.4 * mass * RADIUS**2
            np.testing.assert_allclose(spin.values["ke_rot"], 0.5 * inertia * 30.0**2, rtol=1e-6)
        if contacts is not None:
            counts = contacts.values["contacts"] - (1 if floor else 0)
            assert counts[0] == counts[-1] == 0 and set(counts) == {0, 2}, np.unique(counts)
            assert np.count_nonzero(counts == 2) * dt == pytest.approx(contact_time, rel=0.1)
        if force is not None:
            assert np.mean(force.values["wall_force"]) == pytest.approx(mass * G, rel=0.05)

    def test_set(self, tmp_path):
        """set() assigns velocities to all, to ids, and spins to a region's particles, returning
        how many it changed; set(radius=...) changes the radius and with it the mass."""
        x0 = np.array([[-6e-3, 0, 0], [-2e-3, 0, 0], [2e-3, 0, 0], [6e-3, 0, 0]], float)
        with self.dem(tmp_path, dt=self.dt(0.5 * RADIUS)) as sim:
            sim.createParticles(1, "single", x0[0, 0], 0.0, 0.0)
            for x in x0[1:]:
                sim.createParticles(1, "single", *x)
            if not self.supports("set"):
                with pytest.raises(UnsupportedFeature):
                    sim.set(vel=(0.0, 0.0, 0.1))
                return
            ids = sim.extractIds()
            assert sim.set(vel=(0.0, 0.0, 0.1)) == 4
            assert sim.velocity(vel=(0.0, 0.1, 0.0), ids=[int(ids[1])]) == 1
            assert sim.set(omega=(0.0, 0.0, 5.0), region=("block", 0, 0.01, -0.01, 0.01, -0.01, 0.01)) == 2
            if self.supports("set-radius"):
                assert sim.set(radius=0.5 * RADIUS, ids=[int(ids[3])]) == 1
            else:
                with pytest.raises(UnsupportedFeature):
                    sim.set(radius=0.5 * RADIUS, ids=[int(ids[3])])
            v, w, r = sim.extractVelocities(), sim.extractOmegas(), sim.extractRadii()
            mass = sim.engine.extract("mass")
            sim.run(100)
            x = sim.extractCoords()
        np.testing.assert_allclose(v, [[0, 0, 0.1], [0, 0.1, 0], [0, 0, 0.1], [0, 0, 0.1]], atol=1e-15)
        np.testing.assert_allclose(w, [[0, 0, 0], [0, 0, 0], [0, 0, 5], [0, 0, 5]], atol=1e-12)
        np.testing.assert_allclose(x, x0 + v * sim.time, rtol=0, atol=1e-12)
        if self.supports("set-radius"):
            np.testing.assert_allclose(r, [RADIUS] * 3 + [0.5 * RADIUS], rtol=1e-12)
            np.testing.assert_allclose(mass[3], sphere_mass(MATERIAL, 0.5 * RADIUS), rtol=1e-9)
