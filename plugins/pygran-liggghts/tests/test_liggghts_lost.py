"""Particles LIGGGHTS loses (through a fixed face of the box) are counted exactly in every run,
those inserted and lost within one piece of a run included, and reported by the front end:
a warning naming how many and where, or a log line for an outflow the script expects."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.errors import LostParticlesWarning
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT

R = 5e-4


def open_box(path):
    """A box 2 mm high and 6 mm wide with no floor: what falls leaves through z-."""
    require_solver(find_library)
    return simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(-3e-3, 3e-3, -3e-3, 3e-3, 0, 2e-3),
        gravity=(9.81, 0, 0, -1),
        dt=1e-5,
        output=str(path),
        species=({"material": SOFT, "radius": R},),
        traj={"pfile": None},
        progress=False,
    )


def test_particles_falling_out_are_counted_and_warned(tmp_path):
    with open_box(tmp_path) as sim:
        sim.createParticles(
            1, "single", np.array([[x, 0.0, 1e-3] for x in (-2.4e-3, -1.2e-3, 0.0, 1.2e-3, 2.4e-3)])
        )
        sim.run(500)  # 0.5 mm in 5 ms: none out yet
        assert sim.engine.lost == 0
        with pytest.warns(
            LostParticlesWarning, match=r"5 particles lost in the run from step 500 to 2500: 5 through z-"
        ):
            sim.run(2000)  # out after 14 ms
        assert sim.engine.lost == 5 and dict(sim.engine.last_lost.where) == {"z-": 5}
        assert len(sim.extractIds()) == 0
    assert "5 particles lost" in (tmp_path / "pygran.log").read_text()


def test_an_expected_outflow_is_logged_not_warned(tmp_path):
    with open_box(tmp_path) as sim:
        sim.engine.expect_outflow("z-")
        sim.createParticles(1, "single", 0.0, 0.0, 1e-3)
        with warnings.catch_warnings():
            warnings.simplefilter("error", LostParticlesWarning)
            sim.run(2500)
        assert sim.engine.lost == 1
    assert "1 particle left through the expected outflow (z-)" in (tmp_path / "pygran.log").read_text()


def test_inserted_and_lost_within_one_piece_of_a_run(tmp_path):
    """Spheres inserted every 1.5 ms up to 1.9 mm above the open bottom at 1 m/s downwards
    leave within 2 ms, inside the piece of the run (2 ms) they were inserted in: each is
    counted, and placed at the face it leaves through, the outflow the script expects."""
    with open_box(tmp_path) as sim:
        sim.engine.expect_outflow("z-")
        sim.insert(
            species=1,
            value=2000,  # particles per second, for 10 ms: 20, 3 every 150 steps
            insert="by_rate",
            freq=150,
            duration=0.01,
            region=("block", -2.4e-3, 2.4e-3, -2.4e-3, 2.4e-3, 5.5e-4, 1.9e-3),
            vel=(0, 0, -1.0),
        )
        with warnings.catch_warnings():
            warnings.simplefilter("error", LostParticlesWarning)
            sim.run(2000)
        assert sim.engine.lost == 20 and dict(sim.engine.last_lost.where) == {"z-": 20}
        assert len(sim.extractIds()) == 0
    log = (tmp_path / "pygran.log").read_text()
    assert "20 particles left through the expected outflow (z-) in the run from step 0 to 2000" in log
