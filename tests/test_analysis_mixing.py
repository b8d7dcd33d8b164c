"""analysis.mixing: Lacey's index and Danckwerts' segregation on mixtures whose answer is known."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pygran_core.analysis import Particles, mixing
from pygran_core.errors import ConfigError

R = 0.25
CELL = 3.0  # sample cell side; 27 particles per cell on the lattice below


def lattice(cells, types_of_cell=None, types=None):
    """3 x 3 x 3 particles in each cubic cell of side CELL, centred in their sub-cells."""
    grid = np.stack(np.meshgrid(*[np.arange(3 * n) for n in cells], indexing="ij"), -1).reshape(-1, 3)
    positions = (grid + 0.5) * CELL / 3
    if types is None:
        types = types_of_cell[tuple((grid // 3).T)]
    return Particles(
        id=np.arange(1, len(grid) + 1),
        type=np.asarray(types),
        x=positions[:, 0],
        y=positions[:, 1],
        z=positions[:, 2],
        radius=np.full(len(grid), R),
    )


def brute_lacey(particles, size, species):
    """Lacey's index with cells found by looping over particles (numerator and denominator by hand)."""
    origin = [min(particles.x), min(particles.y), min(particles.z)]
    samples: dict[tuple[int, int, int], list[int]] = {}
    for x, y, z, t in zip(particles.x, particles.y, particles.z, particles.type):
        key = tuple(int(np.floor((c - o) / size)) for c, o in zip((x, y, z), origin))
        samples.setdefault(key, []).append(int(t == species))
    n_total = sum(len(s) for s in samples.values())
    p = sum(sum(s) for s in samples.values()) / n_total
    s2 = sum(len(s) * (sum(s) / len(s) - p) ** 2 for s in samples.values()) / n_total
    s0 = p * (1 - p)
    return (s0 - s2) / (s0 - s0 / (n_total / len(samples)))


def test_segregated_mixture_is_zero_and_matches_brute_force():
    halves = np.ones((4, 4, 4), dtype=int)
    halves[:, :, 2:] = 2  # bottom half type 1, top half type 2, each cell pure
    particles = lattice((4, 4, 4), halves)
    assert mixing.lacey(particles, CELL) == 0.0
    assert particles.computeLaceyIndex(CELL) == 0.0
    assert mixing.intensity(particles, CELL) == pytest.approx(1.0, abs=1e-12)
    uneven = np.ones((4, 4, 4), dtype=int)
    uneven[:, :, 3:] = 2  # p = 1/4
    assert mixing.lacey(lattice((4, 4, 4), uneven), CELL) == pytest.approx(0.0, abs=1e-12)


def test_random_mixture_is_one_on_average_and_matches_brute_force():
    rng = np.random.default_rng(11)
    values = []
    for _ in range(20):
        particles = lattice((4, 4, 4), types=rng.integers(1, 3, 27 * 64))
        value = mixing.lacey(particles, CELL)
        assert value == pytest.approx(brute_lacey(particles, CELL, 1), rel=1e-12)
        values.append(value)
    # s^2 over 64 cells spreads by sqrt(2/64) = 18 % about sr^2 = s0^2 / 27, so M by 0.18 / 26 = 0.007
    assert np.mean(values) == pytest.approx(1.0, abs=0.01)
    assert 0.96 < min(values) and max(values) < 1.04


def test_ordered_mixture_exceeds_one_by_n_over_n_minus_one():
    # every cell holds the overall fraction exactly: s^2 = 0, M = n / (n - 1) with n = 27
    grid = np.stack(np.meshgrid(*[np.arange(12)] * 3, indexing="ij"), -1).reshape(-1, 3)
    in_cell = (grid % 3) @ [9, 3, 1]  # 0..26 inside each cell
    particles = lattice((4, 4, 4), types=np.where(in_cell < 9, 1, 2))  # 9 of 27 in every cell
    assert mixing.lacey(particles, CELL) == pytest.approx(27 / 26, rel=1e-12)
    assert mixing.intensity(particles, CELL) == pytest.approx(0.0, abs=1e-12)


def test_cells_and_species_choice():
    rng = np.random.default_rng(2)
    three = lattice((2, 2, 2), types=rng.integers(1, 4, 27 * 8))
    sample = mixing.cells(three, CELL, species=3)
    assert sample.count.tolist() == [27] * 8 and sample.size == CELL
    assert sample.species.sum() == np.count_nonzero(three.type == 3)
    np.testing.assert_allclose(sample.volume, 27 * 4 / 3 * np.pi * R**3)
    expected = sorted(itertools.product(range(2), repeat=3))
    assert sorted(map(tuple, sample.index.tolist())) == expected
    assert mixing.lacey(three, CELL, species=3) == pytest.approx(brute_lacey(three, CELL, 3), rel=1e-12)
    default = mixing.cells(lattice((2, 2, 2), types=[1, 2] * (27 * 4)))
    assert default.size == pytest.approx(6 * R)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"species": 9}, "species=9 is not among"),
        ({"resol": -1.0}, "resol must be a length > 0"),
        ({"resol": 0.1}, "choose a resol larger than"),
    ],
)
def test_mistakes_are_named(kwargs, message):
    particles = lattice((2, 2, 2), types=[1, 2] * (27 * 4))
    with pytest.raises(ConfigError, match=message):
        mixing.lacey(particles, **kwargs)


def test_single_species_and_missing_types_are_refused():
    with pytest.raises(ConfigError, match="single species"):
        mixing.lacey(lattice((2, 2, 2), types=np.ones(27 * 8, dtype=int)), CELL, species=1)
    untyped = Particles(x=[0.0, 1.0], y=[0.0, 0.0], z=[0.0, 0.0], radius=[0.1, 0.1])
    with pytest.raises(ConfigError, match="need a 'type' attribute"):
        mixing.lacey(untyped)
