"""The engine suite's checks of walls: primitive walls, a mesh wall and every ``moveMesh`` style."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.optimize import brentq

from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.insertion import triangle_distance
from pygran_core.testing.engines.base import GRAVITY, EngineSuite, G, Outcome, attempt

#: The period of the mesh motions (a quarter of it is the time each is run for, at least).
MOTION_PERIOD = 0.04


class WallChecks(EngineSuite):
    """Primitive walls, the silo as a mesh wall, and each ``moveMesh`` style on it."""

    def test_primitive_walls(self, tmp_path):
        """Spheres (no gravity) bounce off a z plane, an x plane and a z cylinder around them;
        with the z plane removed, a fourth passes where it would have bounced."""
        v = 0.1
        starts = np.array([[0.0, 0.0, -3e-3], [3e-3, 0.0, 3e-3], [-6e-3, 0.0, 3e-3], [0.0, 4e-3, -2e-3]])
        velocities = np.array([[0.0, 0.0, -v], [v, 0.0, 0.0], [-v, 0.0, 0.0], [0.0, 0.0, -v]])
        dt = self.dt()
        with self.dem(tmp_path, dt=dt) as sim:
            if not self.supports("primitive-walls"):
                with pytest.raises(UnsupportedFeature):
                    sim.setupWall(species=1, plane="zplane", peq=-5e-3)
                return
            floor = sim.setupWall(species=1, plane="zplane", peq=-5e-3)
            sim.setupWall(species=1, plane="xplane", peq=5e-3)
            sim.setupWall(species=1, axis="z", centre=(0.0, 0.0), radius=8e-3)
            for x, u in zip(starts, velocities):
                sim.createParticles(1, "single", *x, vel=tuple(u))
            sim.run(round(0.015 / dt))  # 1 mm to each wall at 0.1 m/s: 10 ms
            after = sim.extractVelocities()
            sim.remove(floor)  # the fourth sphere, 2 mm from it, has not reached it
            sim.run(round(0.02 / dt))
            z, end = sim.extractCoords()[3, 2], sim.time
        bounced = [after[0, 2], -after[1, 0], after[2, 0]]
        assert all(0.5 * v < b <= v * (1 + 1e-9) for b in bounced), after
        assert z == pytest.approx(-2e-3 - v * end, rel=1e-6) and z < -5e-3

    def silo(self, data_dir: Path) -> dict[str, Any]:
        """``silo.stl`` (a conical hopper, in mm) as the mesh ``silo``, not a wall yet."""
        file = data_dir / "meshes" / "silo.stl"
        return {"silo": {"file": str(file), "args": ("scale 1e-3",), "import": False}}

    @staticmethod
    def seat(sim: DEM, radius: float) -> float:
        """The height on the silo's axis where a sphere of ``radius`` touches its facets."""
        triangles = sim.spec.meshes[0].triangles()
        return brentq(
            lambda z: float(triangle_distance(np.array([[0.0, 0.0, z]]), triangles)[0]) - radius,
            0.0,
            3e-3,
            xtol=1e-12,
        )

    def test_mesh_wall(self, tmp_path, data_dir):
        """A sphere (r = 0.5 mm) set on the axis of the silo (outlet radius 0.3 mm), where it
        touches the facets, stays there; removing the mesh's wall by name, it falls freely."""
        radius = 5e-4
        box = (-1.5e-3, 1.5e-3, -1.5e-3, 1.5e-3, -4e-3, 4e-3)
        keywords = dict(box=box, mesh=self.silo(data_dir), gravity=GRAVITY, dt=self.dt(radius))
        if not self.supports("mesh-walls"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, radius, **keywords).close()
            return
        with self.dem(tmp_path, radius, **keywords) as sim:
            sim.setupWall(wtype="mesh", mesh="silo")
            seat = self.seat(sim, radius)
            sim.createParticles(1, "single", 0.0, 0.0, seat)
            sim.run(2000)
            held, speed, start = sim.extractCoords()[0], sim.extractVelocities()[0, 2], sim.time
            sim.remove("silo")
            sim.run(1000)
            fallen, duration = sim.extractCoords()[0], sim.time - start
        assert seat - 0.02 * radius < held[2] <= seat + 1e-9 and np.hypot(*held[:2]) < 1e-3 * radius, held
        assert fallen[2] - held[2] == pytest.approx(speed * duration - 0.5 * G * duration**2, rel=1e-3)

    @pytest.fixture(scope="class")
    @classmethod
    def mesh_motions(cls, tmp_path_factory, data_dir) -> dict[str, Outcome]:
        """A sphere seated in the silo, then each ``moveMesh`` style in turn (each motion
        removed before the next): what each did to the sphere, or what it raised."""
        suite = cls()
        radius, period = 5e-4, MOTION_PERIOD
        box = (-1.5e-3, 1.5e-3, -1.5e-3, 1.5e-3, -4e-3, 4e-3)
        dt = suite.dt(radius)
        quarter = round(period / 4 / dt)
        results: dict[str, Outcome] = {}

        def rotate(sim: DEM) -> tuple[float, float, float]:
            before = float(sim.extractOmegas()[0, 2])
            sim.run(quarter)
            return before, float(sim.extractOmegas()[0, 2]), 2 * math.pi / period

        def linear(sim: DEM) -> tuple[float, float]:
            z, t = sim.extractCoords()[0, 2], sim.time
            sim.run(2 * quarter)
            return float(sim.extractCoords()[0, 2] - z), 2e-3 * (sim.time - t)

        def wiggle(sim: DEM) -> tuple[float, float]:
            z = sim.extractCoords()[0, 2]
            sim.run(quarter)
            up = sim.extractCoords()[0, 2] - z
            sim.run(quarter)
            return float(up), float(sim.extractCoords()[0, 2] - z)

        def viblin(sim: DEM) -> float:
            z = sim.extractCoords()[0, 2]
            sim.run(2 * quarter)
            return float(sim.extractCoords()[0, 2] - z)

        def vibrot(sim: DEM) -> float:
            sim.run(quarter)
            return float(sim.extractOmegas()[0, 2])

        amplitude = 2e-5
        phases: dict[str, tuple[dict[str, Any], Callable[[DEM], Any]]] = {
            "rotate": ({"rotate": ("origin", 0.0, 0.0, 0.0), "axis": (0, 0, 1), "period": period}, rotate),
            "linear": ({"linear": (0.0, 0.0, 2e-3)}, linear),
            "wiggle": ({"wiggle": ("amplitude", 0.0, 0.0, amplitude), "period": period}, wiggle),
            "viblin": (
                {"viblin": ("axis", 0, 0, 1), "order": 1, "amplitude": (amplitude,), "phase": (0.0,)}
                | {"period": (period,)},
                viblin,
            ),
            "vibrot": (
                {"vibrot": ("origin", 0, 0, 0), "axis": (0, 0, 1), "order": 1, "amplitude": (0.5,)}
                | {"phase": (0.0,), "period": (period,)},
                vibrot,
            ),
        }
        try:
            sim = suite.dem(
                tmp_path_factory.mktemp("motions"),
                radius,
                box=box,
                mesh=suite.silo(data_dir),
                gravity=GRAVITY,
                dt=dt,
            )
        except Exception as exc:  # noqa: BLE001 - every style's test reads it
            return {style: Outcome(error=exc) for style in phases}
        with sim:
            outcome = attempt(lambda: sim.setupWall(wtype="mesh", mesh="silo"))
            if outcome.error is not None:
                return {style: outcome for style in phases}
            sim.createParticles(1, "single", 0.0, 0.0, suite.seat(sim, radius))
            sim.run(quarter)
            for style, (kwargs, measure) in phases.items():
                try:
                    handle = sim.moveMesh("silo", **kwargs)
                except Exception as exc:  # noqa: BLE001 - read by the style's test
                    results[style] = Outcome(error=exc)
                    continue
                results[style] = attempt(partial(measure, sim))
                removed = attempt(partial(sim.remove, handle))
                if removed.error is not None:  # the next styles would not start from rest
                    return results | {s: removed for s in phases if s not in results}
        return results

    def motion(self, mesh_motions: dict[str, Outcome], style: str, *needs: str) -> Any:
        """The style's measurement, or ``None`` once its UnsupportedFeature is asserted."""
        if all(self.supports(need) for need in ("mesh-walls", "moving-mesh", *needs)):
            return mesh_motions[style].get()
        with pytest.raises(UnsupportedFeature):
            mesh_motions[style].get()
        return None

    def test_move_mesh_rotate(self, mesh_motions):
        """The silo turning about its axis spins the sphere seated in it (at rest before) up to
        its own rate."""
        measured = self.motion(mesh_motions, "rotate")
        if measured is not None:
            before, spin, omega = measured
            assert abs(before) < 1e-3 * omega and spin == pytest.approx(omega, rel=0.02), measured

    def test_move_mesh_linear(self, mesh_motions):
        """The silo moving up at 2 mm/s lifts the sphere with it."""
        measured = self.motion(mesh_motions, "linear")
        if measured is not None:
            lift, expected = measured
            assert lift == pytest.approx(expected, rel=0.03), measured

    def test_move_mesh_wiggle(self, mesh_motions):
        """A slow vertical wiggle of 20 um lifts the sphere by it after a quarter period and
        brings it back after half."""
        measured = self.motion(mesh_motions, "wiggle")
        if measured is not None:
            up, back = measured
            assert up == pytest.approx(2e-5, rel=0.05) and abs(back) < 1e-6, measured

    def test_move_mesh_viblin(self, mesh_motions):
        """A vertical viblin of one harmonic (amplitude 20 um, phase 0) lowers the sphere by
        twice its amplitude after half a period."""
        measured = self.motion(mesh_motions, "viblin", "mesh-vibration")
        if measured is not None:
            assert measured == pytest.approx(-4e-5, rel=0.05)

    def test_move_mesh_vibrot(self, mesh_motions):
        """A vibrot about the axis (0.5 rad, phase 0) spins the sphere at -0.5 w after a quarter period."""
        measured = self.motion(mesh_motions, "vibrot", "mesh-vibration")
        if measured is not None:
            assert measured == pytest.approx(-0.5 * 2 * math.pi / MOTION_PERIOD, rel=0.02)
