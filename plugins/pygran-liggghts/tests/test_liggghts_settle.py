"""The settle scenario of shared/benchmarks/settle.md at small N on 1 and 2 MPI ranks."""

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.testing.solvers import require_solver

R, DENSITY = 1e-3, 2500.0
MATERIAL = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.45,
    "coefficientRestitution": 0.3,
    "coefficientFriction": 0.5,
    "density": DENSITY,
}
CELLS = (8, 6, 5)  # 240 particles


def lattice(cells, seed=12345):
    """settle.md: simple-cubic lattice of spacing 1.1 x 2r, each site jittered by up to 0.45 (a - 2r)."""
    a = 1.1 * 2 * R
    grid = np.stack(np.meshgrid(*(np.arange(n) for n in cells), indexing="ij"), -1).reshape(-1, 3)
    jitter = np.random.default_rng(seed).uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * R)
    return (grid + 0.5) * a + jitter, a


def settle(tmp_path, nprocs):
    require_solver(find_library)
    x0, a = lattice(CELLS)
    nx, ny, nz = CELLS
    with simulation.DEM(
        engine="liggghts",
        model=simulation.models.HertzMindlin,
        nprocs=nprocs,
        box=(0, nx * a, 0, ny * a, 0, (nz + 3) * a),
        boundary=("p", "p", "f"),
        gravity=(9.81, 0, 0, -1),
        dt=1e-5,
        nns_skin=4e-4,
        output=str(tmp_path / f"np{nprocs}"),
        species=({"material": MATERIAL, "radius": R},),
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        for position in x0:
            sim.createParticles(1, "single", *position)
        start = sim.extractCoords()
        sim.run(8000)
        sim.run(4000)
        return x0, start, sim.extractCoords(), sim.extractIds(), sim.extractVelocities()


def packing_fraction(x, box_xy):
    """Solid volume over the volume of the bed below the mean height of its top layer."""
    top = np.sort(x[:, 2])[-len(x) // CELLS[2] :].mean() + R
    return len(x) * 4 / 3 * np.pi * R**3 / (box_xy * top)


def test_settle_on_one_and_two_ranks(tmp_path):
    results = {n: settle(tmp_path, n) for n in (1, 2)}
    _, a = lattice(CELLS)
    area = CELLS[0] * CELLS[1] * a * a
    fractions = {}
    for n, (x0, start, x, ids, v) in results.items():
        assert len(x) == len(x0) == np.prod(CELLS)
        assert np.array_equal(ids, np.arange(1, len(x0) + 1))  # gathered in id order
        np.testing.assert_allclose(start, x0, rtol=0, atol=1e-12)
        assert np.linalg.norm(v, axis=1).mean() < 0.01  # settled
        fractions[n] = packing_fraction(x, area)
    assert 0.45 < fractions[1] < 0.65
    assert fractions[2] == pytest.approx(fractions[1], rel=0.01)
    assert (tmp_path / "np2" / "in.pygran").read_text().count("create_atoms") == len(results[2][0])
