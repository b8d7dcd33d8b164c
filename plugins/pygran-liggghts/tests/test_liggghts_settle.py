"""The settle scenario of benchmarks/README.md at small N on 1 and 2 MPI ranks."""

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import RADIUS, SETTLE_SPACING, settle_positions, settle_setup

CELLS = (8, 6, 5)  # 240 particles


def settle(tmp_path, nprocs):
    require_solver(find_library)
    with settle_setup("liggghts", tmp_path / f"np{nprocs}", CELLS, nprocs=nprocs) as sim:
        start = sim.extractCoords()
        sim.run(8000)
        sim.run(4000)
        return settle_positions(CELLS), start, sim.extractCoords(), sim.extractIds(), sim.extractVelocities()


def packing_fraction(x, box_xy):
    """Solid volume over the volume of the bed below the mean height of its top layer."""
    top = np.sort(x[:, 2])[-len(x) // CELLS[2] :].mean() + RADIUS
    return len(x) * 4 / 3 * np.pi * RADIUS**3 / (box_xy * top)


def test_settle_on_one_and_two_ranks(tmp_path):
    results = {n: settle(tmp_path, n) for n in (1, 2)}
    area = CELLS[0] * CELLS[1] * SETTLE_SPACING**2
    fractions = {}
    for n, (x0, start, x, ids, v) in results.items():
        assert len(x) == len(x0) == np.prod(CELLS)
        assert np.array_equal(ids, np.arange(1, len(x0) + 1))  # gathered in id order
        np.testing.assert_allclose(start, x0, rtol=0, atol=1e-12)
        assert np.linalg.norm(v, axis=1).mean() < 0.01  # settled
        fractions[n] = packing_fraction(x, area)
    assert 0.45 < fractions[1] < 0.65
    assert fractions[2] == pytest.approx(fractions[1], rel=0.01)
    assert (tmp_path / "np2" / "in.pygran").read_text().count("read_dump ") == 1  # the bed in one command
