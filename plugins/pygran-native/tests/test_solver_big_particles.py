"""Big particles among small ones: the cells fit the small ones, and the few particles over
twice the smallest radius search the cells within their reach. Balls ploughing through a bed
of beads (no gravity, so every contact comes from the motion) must be in contact with exactly
the beads they overlap, as a brute-force search over all pairs finds them, at every check, in
open and periodic boxes, on one and two threads."""

from __future__ import annotations

import numpy as np
import pytest
from pygran_native.solver import Solver

BEAD, BALL, SKIN, DT = 1e-3, 6e-3, 1e-3, 2e-6
BOX = np.array([[0.0, 0.0, 0.0], [0.03, 0.03, 0.02]])


def bed_and_balls(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A jittered lattice of beads with three balls (and the beads they would overlap
    removed), the balls moving at 8-10 m/s towards each other."""
    rng = np.random.default_rng(seed)
    spacing = 2.15 * BEAD
    shape = ((BOX[1] - BOX[0]) / spacing).astype(int)
    beads = (np.indices(shape).reshape(3, -1).T + 0.5) * spacing
    beads += rng.uniform(-0.05, 0.05, beads.shape) * BEAD
    balls = np.array([[0.008, 0.008, 0.01], [0.022, 0.008, 0.01], [0.015, 0.018, 0.01]])
    gap = np.linalg.norm(beads[:, None, :] - balls[None, :, :], axis=2).min(axis=1)
    beads = beads[gap > BALL + BEAD + 0.2e-3]
    x = np.vstack([beads, balls])
    r = np.r_[np.full(len(beads), BEAD), np.full(len(balls), BALL)]
    v = np.zeros_like(x)
    v[-3:] = [[10.0, 0.0, 0.0], [-7.0, 7.0, 0.0], [0.0, -8.0, 0.0]]
    return x, r, v


def overlapping_pairs(x: np.ndarray, r: np.ndarray, ids: np.ndarray, periodic) -> set[tuple[int, int]]:
    """Every pair of ids that overlap, by brute force (nearest periodic image)."""
    d = x[:, None, :] - x[None, :, :]
    side = BOX[1] - BOX[0]
    for axis in range(3):
        if periodic[axis]:
            d[..., axis] -= side[axis] * np.round(d[..., axis] / side[axis])
    gap = np.sqrt((d**2).sum(axis=2)) - (r[:, None] + r[None, :])
    i, j = np.nonzero(np.triu(gap < 0, k=1))
    return {tuple(sorted((int(a), int(b)))) for a, b in zip(ids[i], ids[j])}


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("periodic", [(False, False, False), (True, True, False)])
def test_balls_touch_exactly_the_beads_they_overlap(threads, periodic):
    x, r, v = bed_and_balls(seed=5)
    s = Solver(box=BOX, periodic=periodic, gravity=(0, 0, 0), skin=SKIN, threads=threads)
    s.set_contact_model("hertz", youngs=5e7, poisson=0.3, restitution=0.5, friction=0.5)
    ids = s.add_particles(x, r, densities=2500, velocities=v)
    balls = set(int(k) for k in ids[-3:])
    met = balls_met = 0
    for _ in range(8):
        s.run(100, DT)
        cells, radius, big = s.grid
        assert big == 3 and radius == BEAD, "the balls are searched apart from the cells"
        assert ((BOX[1] - BOX[0]) / cells).max() < 2 * BALL + SKIN
        i, j, overlap, _ = s.contacts()
        listed = {tuple(sorted((int(a), int(b)))) for a, b in zip(i, j)}
        assert listed == overlapping_pairs(s.positions, s.radii, s.ids, periodic)
        assert np.all(overlap > 0)
        met += sum(1 for pair in listed if balls & set(pair))
        balls_met += sum(1 for pair in listed if set(pair) <= balls)
    assert met > 100 and balls_met > 0, "the balls met beads and each other"


def test_a_bed_of_two_sizes_keeps_one_grid():
    """Beads of 1 and 2 mm (the drum's mixture) are all small: nothing is searched apart."""
    x = (np.indices((6, 5, 4)).reshape(3, -1).T + 0.5) * 5e-3
    r = np.where(np.arange(len(x)) % 2, BEAD, 2 * BEAD)
    s = Solver(box=BOX, periodic=(False,) * 3, gravity=(0, 0, 0), skin=SKIN, threads=1)
    s.set_contact_model("hertz", youngs=5e7, poisson=0.3, restitution=0.5, friction=0.5)
    s.add_particles(x, r, densities=2500)
    s.run(1, DT)
    _, radius, big = s.grid
    assert big == 0 and radius == np.inf
