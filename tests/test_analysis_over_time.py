"""Analysis over time as a user writes it (issue 44, items 3 and 6): the simulated time of
every frame, a per-frame function with keywords as a (time, value) table, plots with units on
their axes, how Lacey's index depends on its cell size; and the original PyGran's loop over a
System and ``imaging.slice`` arguments in either order."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pygran_core import analysis, params, simulation
from pygran_core.analysis import imaging, mixing, plot
from pygran_core.analysis.dynamics import Temporal
from pygran_core.errors import ConfigError

DT = 8e-6
EVERY = 200


@pytest.fixture(scope="module")
def mixing_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two species of beads falling into a box on native: an H5MD trajectory of 6 frames."""
    output = tmp_path_factory.mktemp("mixing") / "out"
    with simulation.DEM(
        engine="native",
        box=(0, 0.02, 0, 0.02, 0, 0.04),
        gravity=(9.81, 0, 0, -1),
        dt=DT,
        output=str(output),
        seed=7,
        species=[{"material": params.organic, "radius": ("constant", r)} for r in (1e-3, 8e-4)],
        traj={"freq": EVERY, "pfile": "traj.h5"},
    ) as sim:
        sim.insert(species=(1, 2), value=150, region=("block", 0, 0.02, 0, 0.02, 0.005, 0.035))
        sim.run(5 * EVERY)
    return output / "traj.h5"


def test_every_frame_has_its_time_and_keywords_reach_the_function(mixing_run: Path) -> None:
    system = analysis.System(Particles=str(mixing_run))
    times = [system.time for _ in system.frames()]
    np.testing.assert_allclose(times, np.arange(6) * EVERY * DT, rtol=1e-12)

    lacey = Temporal(system).timeseries("computeLaceyIndex", resol=4e-3, species=1)
    time, value = lacey  # unpacks as a pair
    np.testing.assert_allclose(time, times, rtol=1e-12)
    expected = []
    for _ in system.frames():
        expected.append(mixing.lacey(system.Particles, resol=4e-3, species=1))
    np.testing.assert_array_equal(value, expected)
    # the default cell (three mean diameters, 5.4 mm here) measures something else
    assert not np.allclose(Temporal(system).series("computeLaceyIndex"), expected)
    table = lacey.table()
    assert table.shape == (6, 2)
    np.testing.assert_array_equal(table[:, 0], time)
    com = Temporal(system).timeseries("computeCOM").table()
    assert com.shape == (6, 4) and np.all(np.diff(com[:, 3]) < 0)  # the beads fall
    with pytest.raises(ConfigError, match="takes no arguments"):
        Temporal(system).series("x", 1)


def test_plots_carry_units_on_their_axes(mixing_run: Path) -> None:
    system = analysis.System(Particles=str(mixing_run))
    ax = Temporal(system).timeseries("computeLaceyIndex", resol=4e-3, species=1).plot(label="Lacey index")
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (s)", "Lacey index")
    np.testing.assert_allclose(ax.lines[0].get_xdata(), np.arange(6) * EVERY * DT)
    system.goto(-1)
    particles = system.Particles
    ax = plot.rdf(particles.computeRDF(rMax=6e-3))
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("r (m)", "g(r)")
    ax = plot.rdf(particles.computeRDF(rMax=6e-3), diameter=2e-3)
    assert ax.get_xlabel() == "r / d (particle diameters)"
    coon = analysis.equilibrium.Neighbors(particles).coon
    ax = plot.coordination(coon)
    heights = [bar.get_height() for bar in ax.patches]
    assert sum(heights) == pytest.approx(1.0) and len(heights) == coon.max() + 1
    assert ax.get_xlabel().startswith("coordination number")
    ax = plot.time_series(([0.0, 1e-3], [2.0, 3.0]), label="z", unit="m", units="micro")
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (µs)", "z (m)")


def test_lacey_index_rises_with_the_cell_size_over_a_layered_bed() -> None:
    # a cubic lattice of 1 mm beads, species in layers 4 mm thick: cells of 2 mm are pure
    # (M = 0); cells of 8 mm hold one layer of each species, every cell at the mean (M > 1)
    sites = np.stack(np.meshgrid(*[np.arange(32) + 0.5] * 3, indexing="ij"), -1).reshape(-1, 3) * 1e-3
    layered = analysis.Particles(
        x=sites[:, 0],
        y=sites[:, 1],
        z=sites[:, 2],
        radius=np.full(len(sites), 5e-4),
        type=np.where((sites[:, 2] // 4e-3) % 2 == 0, 1, 2),
    )
    assert layered.computeLaceyIndex(resol=2e-3) == 0.0
    assert layered.computeLaceyIndex(resol=4e-3) == 0.0
    n = 8**3  # particles per 8 mm cell: an ordered mixture gives n / (n - 1)
    assert layered.computeLaceyIndex(resol=8e-3) == pytest.approx(n / (n - 1), rel=1e-12)
    # the default, three mean diameters (3 mm), straddles the layers in some cells only
    assert 0 < layered.computeLaceyIndex() < 1


def test_original_loop_rewinds_and_yields_each_following_frame(data_dir: Path) -> None:
    # The original PyGran: frame 0 is read on construction; "for frame in System" rewinds and
    # yields 1, 2, ..., N - 1. The hopper's frame 0 is empty, so the loop never sees it.
    System = analysis.System(Particles=str(data_dir / "liggghts-hopper" / "particles*.dump"))
    assert System.frame == 0 and System.Particles.natoms == 0
    frames, counts = [], []
    for frame in System:
        frames.append(frame)
        counts.append(System.Particles.natoms)
    assert frames == list(range(1, 31))
    assert min(counts) == 423 and counts[0] == 571
    System.goto(12)
    assert [frame for frame in System][:3] == [1, 2, 3]  # rewinds first, wherever it was
    with pytest.raises(ConfigError, match="carries no time"):
        print(System.time)  # LIGGGHTS dumps of the 3.x series hold timesteps only


def test_original_slice_takes_size_and_resolution_in_either_order(tmp_path: Path) -> None:
    sites = np.stack(np.meshgrid(*[np.arange(4) * 2e-3 + 1e-3] * 3, indexing="ij"), -1).reshape(-1, 3)
    Particles = analysis.Particles(
        x=sites[:, 0],
        y=sites[:, 1],
        z=sites[:, 2],
        radius=np.full(len(sites), 1e-3),
        type=np.ones(len(sites)),
    )
    size, resol = (80, 80), 1e-4
    today = imaging.slice(Particles, 3e-3, 3.2e-3, "z", resol, size)
    original = imaging.slice(Particles, 3e-3, 3.2e-3, "z", size, resol, str(tmp_path / "slice.png"))
    np.testing.assert_array_equal(original, today)
    # the mid-plane z = 3.1 mm cuts the 16 spheres of the layer at z = 3 mm, 0.1 mm from their
    # equator: discs of area pi (r^2 - 0.1^2) mm^2, on 0.1 mm pixels
    assert np.count_nonzero(today) * resol**2 == pytest.approx(16 * np.pi * (1e-6 - 1e-8), rel=0.02)
    assert (tmp_path / "slice.png").is_file()
    with pytest.raises(ConfigError, match="either order"):
        imaging.slice(Particles, 2e-3, 2.2e-3, "z", 2e-4, 3e-4)
