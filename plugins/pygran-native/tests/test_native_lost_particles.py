"""Lost particles on the native engine: the compiled solver counts them by face of the box and as
non-finite, with the speed they left at, so the warning says where and how fast from what the
solver saw (not from PyGran's estimate), and checkpoints carry the counts."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core import params, simulation
from pygran_core.errors import LostParticlesWarning, TimeStepWarning
from pygran_core.simulation.models import HertzMindlin

R = 1e-3


def _dem(tmp_path, **extra):
    settings = {
        "engine": "native",
        "model": HertzMindlin,
        "box": (0.0, 0.02, 0.0, 0.02, 0.0, 0.02),
        "species": ({"material": dict(params.organic), "radius": R},),
        "output": str(tmp_path / "out"),
        "traj": {"pfile": None},
        "progress": False,
        "dt": 1e-5,
        "threads": 1,
    }
    return simulation.DEM(**settings | extra)


def test_particles_thrown_through_open_faces_are_counted_by_face_with_their_speed(tmp_path):
    with _dem(tmp_path) as sim:
        # a floor holds the bed; 3 spheres thrown towards x+ at 1.5 m/s, 2 towards y- at 0.8 m/s
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        for k in range(3):
            sim.createParticles(1, "single", 0.015, 0.004 + 0.005 * k, 0.01, vel=(1.5, 0, 0))
        for k in range(2):
            sim.createParticles(1, "single", 0.004 + 0.006 * k, 0.006, 0.015, vel=(0, -0.8, 0))
        sim.createParticles(1, "single", 0.01, 0.015, 0.005)  # stays
        with pytest.warns(LostParticlesWarning) as caught:
            sim.run(1000)  # 10 ms without gravity: 15 mm along x, 8 mm along y
        lost = sim.engine.last_lost
        assert (lost.count, dict(lost.where)) == (5, {"x+": 3, "y-": 2})
        assert lost.max_speed == pytest.approx(1.5, rel=1e-12)  # free flight: the speed given
        text = str(caught[0].message)
        assert text.startswith("5 particles lost in the run from step 0 to 1000: 3 through x+, 2 through y-")
        assert "they left at up to 1.5 m/s through x+, y-, where no wall holds them" in text
        assert "does not report lost particles" not in text
        assert len(sim.extractCoords()) == 1 and sim.engine.lost == 5
        sim.engine.expect_outflow("x+", "y-")
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sim.run(100)  # nothing more leaves, and nothing is counted twice
        assert sim.engine.last_lost.count == 0 and sim.engine.lost == 5


def test_a_time_step_far_too_large_throws_particles_out_fast(tmp_path):
    """Two layers of organic spheres (E = 10 MPa) on a floor with dt = 10 contact times: every
    contact overshoots, and the spheres leave at speeds no fall in a 2 cm box explains."""
    with _dem(tmp_path, gravity=(9.81, 0, 0, -1)) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        centres = np.stack(np.meshgrid(*[np.arange(1.1e-3, 0.019, 2.1e-3)] * 2, indexing="ij"), -1)
        for z in (1.05e-3, 3.1e-3):
            for x, y in centres.reshape(-1, 2):
                sim.createParticles(1, "single", x, y, z)
        count = len(sim.extractCoords())
        pair = HertzMindlin(material=dict(params.organic, radius=R), partner=dict(params.organic, radius=R))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sim.engine.run(3000, dt=10 * pair.contactTime(), check_dt=False)
        lost = sim.engine.last_lost
        fall = math.sqrt(2 * 9.81 * 0.02)
        categories = [w.category for w in caught]
        assert categories == [TimeStepWarning, LostParticlesWarning]
        assert lost.count == count == 162  # all of them
        assert set(lost.where) <= {"x-", "x+", "y-", "y+", "z+", "non-finite"}  # not through the floor's z-
        assert lost.max_speed is not None and lost.max_speed > 100 * fall  # measured: 1050 m/s
        text = str(caught[1].message)
        assert f"speeds up to {lost.max_speed:.3g} m/s, over 10 times the" in text
        assert "the time step is probably too large" in text


def test_non_finite_particles_are_counted_and_the_counts_survive_a_checkpoint():
    s = Solver(box=[[0, 0, 0], [0.01] * 3], skin=2e-4, threads=2)
    s.set_contact_model("hertz", youngs=1e7, poisson=0.3, restitution=0.5)
    # two spheres at the same centre: the contact has no normal and both become NaN; a third
    # flies out through z+ at 2 m/s
    s.add_particles([[0.005] * 3, [0.005] * 3, [0.002, 0.002, 0.009]], R, densities=1000.0)
    s.set_velocities([2], [[0, 0, 2.0]])
    s.run(100, 1e-5)
    state = s.get_state()
    assert s.n == 0 and s.lost == 3
    restored = Solver(box=[[0, 0, 0], [0.01] * 3], skin=2e-4, threads=2)
    restored.set_state(state)
    for solver in (s, restored):
        where, speed = solver.take_lost()
        assert where == {"non-finite": 2, "z+": 1} and speed == pytest.approx(2.0, rel=1e-12)
        assert solver.take_lost() == ({}, None)  # taken: reset
