"""User mistakes across engines. The table itself (pygran_core.testing.mistakes) runs in the
engine conformance suite, on every engine that subclasses it (native, LIGGGHTS, YADE, the
toy plugin); here: the table's size, and mistakes that need a scenario of their own."""

from __future__ import annotations

import warnings

import pytest

from pygran_core import params
from pygran_core.errors import (
    ConfigError,
    InsertionWarning,
    LostParticlesWarning,
    PyGranError,
    TimeStepWarning,
)
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.mistakes import CALL, SETUP, UNSUPPORTED, valid

ENGINES = ("native", "yade", "liggghts")


def test_the_table_is_large_and_every_row_expects_a_pygran_error():
    rows = SETUP + CALL + UNSUPPORTED
    assert len(rows) >= 60
    assert len({row[0] for row in rows}) == len(rows)
    assert all(issubclass(row[2], PyGranError) for row in SETUP + CALL)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_second_lattice_in_the_same_place_is_refused(tmp_path, engine):
    """Two createParticles lattices over one region would put every particle on top of another."""
    with DEM(**valid(tmp_path / "out", engine)) as sim:
        region = ("block", 0, 0.016, 0, 0.016, 0, 0.016)
        made = sim.createParticles(1, "lattice", 2e-3, region=region)
        assert made >= 7**3
        with pytest.raises(ConfigError, match="createParticles position .* overlaps the particle present"):
            sim.createParticles(1, "lattice", 2e-3, region=region)
        assert len(sim.extractIds()) == made


@pytest.mark.parametrize("engine", ENGINES)
def test_a_full_region_is_a_warning_that_says_how_many(tmp_path, engine):
    """Asked for 15 particles where about 8 fit (random close packing would hold 19, so the
    request is not refused up front): an InsertionWarning with the numbers, also in
    pygran.log; the particles that fit are there."""
    with DEM(**valid(tmp_path / "out", engine)) as sim:
        region = ("block", 0, 0.005, 0, 0.005, 0, 0.005)
        with pytest.warns(InsertionWarning) as caught:
            sim.insert(1, value=15, region=region)
            sim.run(1)
        inserted = len(sim.extractIds())
        assert 0 < inserted < 15
        message = str(caught[0].message)
        assert (
            f"{inserted} of 15 particles inserted" in message
            and "region ('block', 0, 0.005, 0, 0.005, 0, 0.005) is full" in message
        )
        assert f"{inserted} of 15 particles inserted" in (sim.output / "pygran.log").read_text()


@pytest.mark.parametrize("engine", ENGINES)
def test_a_script_ported_with_its_old_time_step_is_stopped_or_warned(tmp_path, engine):
    """A PyGran 1.x script: glass spheres of 0.1 mm with the dt of 1e-6 s it used for larger
    particles, far above their contact time. The run is refused with a safe dt; forced with
    check_dt=False it warns, and every particle it loses is counted and reported."""
    glass = dict(params.glass, cohesionEnergyDensity=0.0)  # YADE has no cohesion
    script = {
        "engine": engine,
        "model": HertzMindlin,
        "box": (0, 2e-3, 0, 2e-3, 0, 4e-3),
        "species": ({"material": glass, "radius": 1e-4},),
        "gravity": (9.81, 0, 0, -1),
        "dt": 1e-6,
        "output": str(tmp_path / "out"),
        "traj": {"pfile": None},
        "progress": False,
    }
    with DEM(**script) as sim:
        sim.setupWall(plane="zplane", peq=0.0)
        sim.createParticles(1, "lattice", 2.2e-4, region=("block", 0, 2e-3, 0, 2e-3, 0, 2e-3))
        created = len(sim.extractIds())
        with pytest.raises(ConfigError, match=r"dt = 1e-06") as info:
            sim.run(2000)
        assert "check_dt=False" in str(info.value) and sim.step == 0
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sim.run(2000, check_dt=False)
        kinds = [w.category for w in caught]
        assert TimeStepWarning in kinds
        gone = created - len(sim.extractIds())
        assert sim.engine.lost == gone
        if gone:
            lost = [str(w.message) for w in caught if w.category is LostParticlesWarning]
            assert lost and lost[0].startswith(f"{gone} particle")
