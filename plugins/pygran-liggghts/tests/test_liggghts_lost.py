"""Particles LIGGGHTS inserts and loses within one piece of a run: each is seen after its
insertion, so placed at the face it leaves through (a declared outflow is logged, not
warned). Losses of particles present at the start are the conformance suite's
(``test_lost_particles``) and tests/test_lost_particles.py's, on every engine."""

from __future__ import annotations

import warnings

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
