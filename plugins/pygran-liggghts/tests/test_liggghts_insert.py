"""insert() on real LIGGGHTS as on the placing engines: small regions, two insertions into one
region before a run, the target of a repeated insertion kept across a resume, and the
shortfall of insertions into a full region reported."""

import re
import shutil
import warnings

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import params, simulation
from pygran_core.errors import InsertionWarning, PyGranWarning
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT as MATERIAL


def dem(output, **params):
    require_solver(find_library)
    settings = {
        "engine": "liggghts",
        "model": "HertzMindlin",
        "box": (-0.006, 0.006, -0.006, 0.006, -0.005, 0.03),
        "boundary": ("p", "p", "f"),
        "gravity": (9.81, 0, 0, -1),
        "dt": 1e-5,
        "output": str(output),
        "species": ({"material": MATERIAL, "radius": 5e-4}, {"material": MATERIAL, "radius": 5e-4}),
        "traj": {"pfile": None},
        "progress": False,
    }
    return simulation.DEM(**settings | params)


def test_a_region_smaller_than_liggghts_default_volume_limit(tmp_path):
    """A 0.4 mm cube (6.4e-11 m^3, below LIGGGHTS' default volume_limit of 1e-10) takes its
    particles: every region is given the original PyGran's volume_limit 1e-20."""
    region = ("block", 3e-4, 7e-4, 3e-4, 7e-4, 3e-4, 7e-4)
    with dem(
        tmp_path, box=(0, 1e-3, 0, 1e-3, 0, 1e-3), dt=5e-7, species=({"material": MATERIAL, "radius": 4e-5},)
    ) as sim:
        sim.insert(species=1, value=10, region=region)
        sim.run(10)
        x = sim.extractCoords()
    assert len(x) == 10
    assert np.all((x > 3e-4 + 4e-5 - 1e-6) & (x < 7e-4 - 4e-5 + 1e-6))
    assert "volume_limit 1e-20" in (tmp_path / "in.pygran").read_text()


def test_two_insertions_into_one_region_before_a_run_both_insert(tmp_path):
    """insert(value=N) adds N to what the region holds, also when the particles of the insert
    call before it are only made as the next run starts (LIGGGHTS), as the placing engines do."""
    region = ("block", -0.005, 0.005, -0.005, 0.005, 0.005, 0.025)
    with dem(tmp_path) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=100, region=region)
        sim.insert(species=2, value=100, region=region)
        sim.run(10)
        types = sim.engine.extract("type")
        sim.insert(species=1, value=30, region=region)  # 200 present now: 230 after the next run
        sim.run(10)
        after = sim.engine.extract("type")
    assert np.bincount(types).tolist() == [0, 100, 100]
    assert np.bincount(after).tolist() == [0, 130, 100]
    # logged as the placing engines log it: each asked for its own 100, then 30
    log = (tmp_path / "pygran.log").read_text()
    assert log.count("insert at step 1: 100 of 100 particles") == 2
    assert "insert at step 11: 30 of 30 particles" in log


def repeated(output, restart):
    """20 particles shot down through a region that a repeated insertion then tops up to 10
    every 1000 steps (they leave it within 300 steps). The second insert call comes when the
    region is empty: its target is 10, whatever the region holds when a resume replays it."""
    region = ("block", -0.005, 0.005, -0.005, 0.005, 0.02, 0.024)
    with dem(output, restart=restart) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=20, region=region, vel=(0, 0, -1))
        sim.run(1000)
        sim.insert(species=1, value=10, region=region, vel=(0, 0, -1), freq=1000)
        sim.run(3000)
        return len(sim.extractIds())


def test_a_repeated_insertion_keeps_its_target_when_resumed(tmp_path):
    """Insertions at steps 1000, 2000 and 3000 add 10 each. Resumed from the checkpoint of step
    2100, while the region holds the 10 particles of step 2000, the replayed insert call keeps
    its target of 10 (counted anew, it would be 20 and the insertion of step 3000 would add 20)."""
    straight = tmp_path / "straight"
    assert repeated(straight, (700, "restart", "restart.*.h5")) == 50
    resumed = tmp_path / "resumed"
    shutil.copytree(straight, resumed)
    assert repeated(resumed, (700, "restart", "restart.*.h5", True, "restart.2100.h5")) == 50
    log = (resumed / "pygran.log").read_text()
    assert "resumed from" in log and "restart.2100.h5" in log


def test_an_earlier_volume_fraction_waiting_for_the_run_is_named(tmp_path):
    """What an insertion of a volume fraction will place as the next run starts is not known
    at the call: a second insertion of a number of particles into that region says so."""
    region = ("block", -0.005, 0.005, -0.005, 0.005, 0.005, 0.025)
    with dem(tmp_path) as sim:
        sim.insert(species=1, value=0.02, mech="volumefraction_region", region=region)
        with pytest.warns(PyGranWarning, match="volumefraction_region into this region .* run at least one"):
            sim.insert(species=2, value=10, region=region)
        sim.run(10)
        sim.insert(species=2, value=10, region=region)
        sim.run(10)
        types = sim.engine.extract("type")
    assert np.bincount(types, minlength=3)[2] == 10  # none at the first run, 10 at the second


def test_batches_by_rate_into_a_full_region_warn_once_with_the_numbers(tmp_path):
    """4000 particles/s every 1000 steps of 5 us asks for 20 particles per batch, of 1 mm radius
    in a 5 mm cube (about 8 fit): the first batch's shortfall is an InsertionWarning with the
    numbers, the later batches' are logged, and the particles present are those reported."""
    region = ("block", 0, 0.005, 0, 0.005, 0, 0.005)
    organic = params.organic
    with dem(
        tmp_path,
        box=(0, 0.02, 0, 0.02, 0, 0.02),
        boundary=("f", "f", "f"),
        dt=5e-6,
        species=({"material": organic, "radius": 1e-3},),
    ) as sim:
        sim.insert(1, value=4000, region=region, insert="by_rate", freq=1000)
        with pytest.warns(InsertionWarning) as caught:
            sim.run(1)
        first = len(sim.extractIds())
        with warnings.catch_warnings():
            warnings.simplefilter("error", InsertionWarning)
            sim.run(2500)  # batches at steps 1001 and 2001: logged only
        total = len(sim.extractIds())
    assert 0 < first < 20 and len(caught) == 1
    assert str(caught[0].message).startswith(
        f"insertion at step 1: {first} of 20 particles inserted, the region {region} is full "
        f"(no free place for the other {20 - first})"
    )
    later = re.findall(
        r"insertion at step (\d+): (\d+) of 20 particles inserted", (tmp_path / "pygran.log").read_text()
    )
    assert [step for step, _ in later] == ["1", "1001", "2001"]
    assert first + sum(int(made) for _, made in later[1:]) == total


def test_a_volume_fraction_of_one_fills_what_fits_and_logs_how_much(tmp_path):
    """insert(mech='volumefraction_region', value=1) into a 5 mm cube of 0.5 mm spheres asks
    for about as many spheres as the cube's volume holds (239): what fits goes in (a random
    packing, 20 % to 64 %), the shortfall is an InsertionWarning with both numbers, and
    pygran.log gives the fraction reached, as the front end counts it."""
    region = ("block", 0, 0.005, 0, 0.005, 0, 0.005)
    organic = params.organic
    with dem(
        tmp_path,
        box=(0, 0.01, 0, 0.01, 0, 0.01),
        boundary=("f", "f", "f"),
        dt=2e-6,
        species=({"material": organic, "radius": 5e-4},),
    ) as sim:
        sim.insert(1, value=1, mech="volumefraction_region", region=region)
        with pytest.warns(InsertionWarning) as caught:
            sim.run(1)
        x = sim.extractCoords()
    asked = round(0.005**3 / (4 / 3 * np.pi * 5e-4**3))
    assert asked == 239 and str(caught[0].message).startswith(
        f"insertion at step 1: {len(x)} of about {asked} particles inserted, the region {region} is full"
    )
    inside = np.all((x >= 0) & (x <= 0.005), axis=1)
    fraction = inside.sum() * 4 / 3 * np.pi * 5e-4**3 / 0.005**3
    assert 0.2 < fraction < 0.64
    assert (
        f"volume fraction in the region {region} at step 1: {fraction:.3g} of the 1 asked for"
        in (tmp_path / "pygran.log").read_text()
    )


def test_a_full_region_says_how_many_were_asked_on_top_of_those_there(tmp_path):
    """Two spheres of 1 mm with their centres 0.5 mm inside a 5 mm cube (sticking out of it);
    insert(value=15) asks LIGGGHTS for 15 on top of them, as it counts them (by their centres):
    about 8 fit (more than 19, the packing bound, is refused up front), and the warning says
    how many of the 15 went in."""
    region = ("block", 0, 0.005, 0, 0.005, 0, 0.005)
    with dem(
        tmp_path,
        box=(0, 0.02, 0, 0.02, 0, 0.02),
        boundary=("f", "f", "f"),
        dt=5e-6,
        species=({"material": params.organic, "radius": 1e-3},),
    ) as sim:
        sim.createParticles(1, "single", [(0.0005, 0.0025, 0.0025), (0.0045, 0.0025, 0.0025)])
        sim.insert(1, value=15, region=region)
        with pytest.warns(InsertionWarning) as caught:
            sim.run(1)
        made = len(sim.extractIds()) - 2
    assert 0 < made < 15
    assert str(caught[0].message).startswith(
        f"insertion at step 1: {made} of 15 particles inserted, the region {region} is full "
        f"(no free place for the other {15 - made})"
    )
