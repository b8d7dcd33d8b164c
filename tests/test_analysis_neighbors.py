"""equilibrium.Neighbors: pairs, overlaps, coordination numbers, filter and force chains."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from pygran_core.analysis import Particles, _neighbors, equilibrium
from pygran_core.errors import ConfigError
from pygran_core.testing.solvers import kernel_path

R = 0.5


@pytest.fixture(params=["compiled", "numpy"])
def pair_search(request, monkeypatch):
    """Each test runs on the core's compiled sweep (required under CI) and on the numpy path."""
    return kernel_path(request.param, _neighbors, monkeypatch)


def make(positions, radius=R, **extra):
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    n = len(positions)
    return Particles(
        id=np.arange(1, n + 1),
        x=positions[:, 0],
        y=positions[:, 1],
        z=positions[:, 2],
        radius=np.broadcast_to(np.asarray(radius, dtype=float), n),
        **extra,
    )


def fcc(cells, periodic):
    a = 2 * R * np.sqrt(2)
    grid = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing="ij"), -1).reshape(-1, 3)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    positions = ((grid[:, None, :] + basis + 0.25) * a).reshape(-1, 3)
    box = {"box": [[0, cells * a]] * 3, "boundary": ("pp", "pp", "pp")} if periodic else {}
    return make(positions, **box)


@pytest.mark.usefixtures("pair_search")
def test_fcc_in_contact_has_coordination_twelve():
    periodic = equilibrium.Neighbors(fcc(4, periodic=True))
    np.testing.assert_array_equal(periodic.coon, 12)
    assert len(periodic.pairs) == 6 * 256
    np.testing.assert_allclose(periodic.distances, 2 * R)
    assert periodic.overlaps.shape == (0, 3)  # touching, not overlapping
    open_lattice = fcc(4, periodic=False)
    coon = equilibrium.Neighbors(open_lattice).coon
    lower, upper = open_lattice.positions.min(axis=0), open_lattice.positions.max(axis=0)
    interior = ((open_lattice.positions > lower + 0.1) & (open_lattice.positions < upper - 0.1)).all(axis=1)
    np.testing.assert_array_equal(coon[interior], 12)
    assert coon[~interior].max() < 12


def test_coordination_per_type_pair_on_a_rock_salt_lattice():
    grid = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    types = 1 + grid.sum(axis=1) % 2
    particles = make(grid * 2 * R, box=[[-R, 8 * R - R]] * 3, boundary=("pp", "pp", "pp"), type=types)
    neighbors = equilibrium.Neighbors(particles)
    np.testing.assert_array_equal(neighbors.coon, 6)
    np.testing.assert_array_equal(neighbors.coordination(1, 2), 6)
    np.testing.assert_array_equal(neighbors.coordination(2, 2), 0)
    assert len(neighbors.coordination(1, 2)) == (types == 1).sum()
    with pytest.raises(TypeError):
        neighbors.coordination(1)


def test_overlaps_give_integer_indices_and_coon_is_also_the_original_method():
    particles = make([[0, 0, 0], [0.9, 0, 0], [1.8, 0, 0], [5, 0, 0]], radius=[0.5] * 4, type=[1, 2, 1, 2])
    neighbors = equilibrium.Neighbors(particles)
    overlaps = neighbors.overlaps
    assert overlaps.shape == (2, 3) and overlaps.i.dtype.kind == "i"
    np.testing.assert_array_equal(overlaps.i, [0, 1])
    np.testing.assert_array_equal(overlaps.j, [1, 2])
    np.testing.assert_allclose(overlaps.d, [0.1, 0.1])
    rows = [(d, i, j) for d, i, j in overlaps]
    assert [(i, j) for _, i, j in rows] == [(0, 1), (1, 2)] and all(type(i) is int for _, i, _ in rows)
    assert int(overlaps[1][2]) == 2 and particles[overlaps[:, 1]].x.tolist() == [0.0, 0.9]
    np.testing.assert_array_equal(neighbors.coon, [1, 2, 1, 0])
    np.testing.assert_array_equal(neighbors.coon(), [1, 2, 1, 0])
    np.testing.assert_array_equal(neighbors.coon(1, 2), [1, 1])
    with pytest.raises(ConfigError, match="needs both types"):
        neighbors.coon(1)


def test_pairs_overlaps_and_cutoff():
    particles = make([[0, 0, 0], [0.9, 0, 0], [3.0, 0, 0]], radius=[0.5, 0.5, 0.5])
    neighbors = equilibrium.Neighbors(particles)
    np.testing.assert_array_equal(neighbors.pairs, [[0, 1]])
    np.testing.assert_allclose(neighbors.overlaps, [[0.1, 0, 1]])
    np.testing.assert_array_equal(neighbors.coon, [1, 1, 0])
    wide = equilibrium.Neighbors(particles, cutoff=2.2)
    np.testing.assert_array_equal(wide.pairs, [[0, 1], [1, 2]])
    np.testing.assert_allclose(wide.distances, [0.9, 2.1])
    np.testing.assert_allclose(wide.overlaps, [[0.1, 0, 1]])
    with pytest.raises(ValueError, match="cutoff must be positive"):
        equilibrium.Neighbors(particles, cutoff=0)


def test_periodic_pairs_use_the_minimum_image():
    box = {"box": [[0, 10], [0, 1], [0, 1]], "boundary": ("pp", "ff", "ff")}
    particles = make([[0.2, 0.5, 0.5], [9.7, 0.5, 0.5]], **box)
    neighbors = equilibrium.Neighbors(particles)
    np.testing.assert_allclose(neighbors.distances, [0.5])
    np.testing.assert_allclose(neighbors.overlaps[:, 0], [0.5])


def test_filter_removes_particles_overlapping_more_than_percent_of_their_radius():
    particles = make([[0, 0, 0], [1.9, 0, 0], [10, 0, 0], [11.5, 0, 0]], radius=[1.0, 1.0, 1.0, 1.0])
    # overlaps: 0.1 (10 % of r) for the first pair, 0.5 (50 %) for the second
    kept = equilibrium.Neighbors(particles).filter(percent=20)
    assert type(kept) is Particles
    np.testing.assert_array_equal(kept.id, [1, 2, 3])  # one of the 50 % pair goes
    np.testing.assert_array_equal(equilibrium.Neighbors(particles).filter(percent=5).id, [1, 3])
    np.testing.assert_array_equal(equilibrium.Neighbors(particles).filter(percent=60).id, [1, 2, 3, 4])
    # polydisperse: a 0.3 overlap is 30 % of r=1 but only 15 % of r=2; conflicts use the smaller
    mixed = make([[0, 0, 0], [2.7, 0, 0]], radius=[1.0, 2.0])
    assert len(equilibrium.Neighbors(mixed).filter(percent=20)) == 1
    with pytest.raises(ValueError, match="percent must be >= 0"):
        equilibrium.Neighbors(mixed).filter(-1)


def test_filter_keeps_a_maximal_conflict_free_set_of_a_dense_packing():
    rng = np.random.default_rng(6)
    particles = make(rng.random((3000, 3)) * 10, radius=rng.uniform(0.2, 0.4, 3000))
    kept = equilibrium.Neighbors(particles).filter(percent=10)
    assert 0 < len(kept) < len(particles)
    after = equilibrium.Neighbors(kept)
    i, j = after.overlaps[:, 1:].astype(int).T
    assert (after.overlaps[:, 0] <= 0.1 * np.minimum(kept.radius[i], kept.radius[j])).all()
    # maximal: every removed particle conflicts with a kept one
    removed = particles[~np.isin(particles.id, kept.id)]
    both = equilibrium.Neighbors(kept + removed)
    i, j = both.overlaps[:, 1:].astype(int).T
    radius = np.concatenate((kept.radius, removed.radius))
    conflict = both.overlaps[:, 0] > 0.1 * np.minimum(radius[i], radius[j])
    n = len(kept)
    blocked = np.zeros(len(removed), dtype=bool)
    blocked[j[conflict & (i < n) & (j >= n)] - n] = True
    assert blocked.all()


def test_empty_and_single_particle_sets():
    for particles in (make(np.zeros((0, 3))), make([[0, 0, 0]])):
        neighbors = equilibrium.Neighbors(particles)
        assert neighbors.pairs.shape == (0, 2) and neighbors.overlaps.shape == (0, 3)
        assert len(neighbors.coon) == len(particles)
        assert len(neighbors.filter(10)) == len(particles)
        assert neighbors.forceChain().chains == []


def test_force_chain_finds_a_loaded_column_and_plots_it():
    # a loose square layer (touching, no force) with a compressed column through it
    grid = np.stack(np.meshgrid(np.arange(7), [0], np.arange(7), indexing="ij"), -1).reshape(-1, 3) * 2 * R
    column = np.column_stack((np.full(5, 20.0), np.zeros(5), np.arange(5) * 0.8))  # overlap 0.2
    pair = np.array([[30.0, 0, 0], [30.95, 0, 0]])  # a weak contact
    particles = make(np.vstack((grid, column, pair)))
    neighbors = equilibrium.Neighbors(particles)
    fig, ax = plt.subplots()
    result = neighbors.forceChain(plot=True, ax=ax)
    assert len(result.contacts) == 5 and result.strong.sum() == 4
    assert len(result.chains) == 1
    np.testing.assert_array_equal(result.chains[0], np.arange(49, 54))
    np.testing.assert_allclose(result.forces[result.strong], np.sqrt(R / 2) * 0.2**1.5)
    assert result.ax is ax and len(ax.collections) == 1 and len(ax.collections[0].get_segments()) == 4
    plt.close(fig)
    assert neighbors.forceChain(min_size=6).chains == []


def brute_force_squared_distances(positions, lengths):
    """d² of every ordered pair: minimum image along periodic axes (``lengths > 0``)."""
    delta = positions[None, :, :] - positions[:, None, :]
    periodic = lengths > 0
    delta[..., periodic] -= lengths[periodic] * np.round(delta[..., periodic] / lengths[periodic])
    return (delta**2).sum(axis=-1)


@pytest.mark.parametrize(
    "boundary, lengths",
    [
        (("ff", "ff", "ff"), (6.0, 5.0, 4.0)),
        (("pp", "pp", "pp"), (6.0, 5.0, 4.0)),
        (("pp", "ff", "pp"), (3.0, 5.0, 7.5)),
        (("ff", "pp", "ff"), (6.0, 2.5, 4.0)),
        (("pp", "pp", "pp"), (1.6, 2.5, 7.0)),  # under two reaches (2 x 1.0) along x and y
    ],
)
def test_pairs_distances_and_coordination_match_a_brute_force_search(pair_search, boundary, lengths):
    rng = np.random.default_rng(7)
    lengths = np.array(lengths)
    positions = rng.random((700, 3)) * lengths
    positions[:50] = np.round(positions[:50] * 4) / 4  # on a grid: ties, exact contacts
    radii = rng.uniform(0.1, 0.5, 700)
    particles = make(positions, radius=radii, box=np.column_stack(([0, 0, 0], lengths)), boundary=boundary)
    periodic = np.array([flag == "pp" for flag in boundary])
    wrapped = np.where(periodic, positions % lengths, positions)  # grid points at L wrap to 0
    distance = np.sqrt(brute_force_squared_distances(wrapped, np.where(periodic, lengths, 0.0)))
    i, j = np.triu_indices(len(positions), 1)
    for cutoff in (None, 1.3):
        neighbors = equilibrium.Neighbors(particles, cutoff)
        touch = radii[i] + radii[j]
        chosen = distance[i, j] <= (touch * (1 + equilibrium.CONTACT_TOLERANCE) if cutoff is None else cutoff)
        assert chosen.sum() > 100
        np.testing.assert_array_equal(neighbors.pairs, np.column_stack((i, j))[chosen])
        np.testing.assert_array_equal(neighbors.distances, distance[i, j][chosen])
        expected = np.bincount(np.concatenate((i[chosen], j[chosen])), minlength=len(positions))
        np.testing.assert_array_equal(neighbors.coon, expected)
        overlapping = touch - distance[i, j] > touch * equilibrium.CONTACT_TOLERANCE
        np.testing.assert_array_equal(neighbors.overlaps.i, i[overlapping])
        np.testing.assert_array_equal(neighbors.overlaps.d, (touch - distance[i, j])[overlapping])


def test_positions_outside_a_periodic_box_are_wrapped(pair_search):
    box = {"box": [[-1, 1], [-1, 1], [-1, 1]], "boundary": ("pp", "pp", "pp")}
    particles = make([[-1.1, 0, 0], [0.85, 0, 0], [1.0, 0.9, 0.5], [-3.0, 0.9, 0.5]], **box)
    neighbors = equilibrium.Neighbors(particles)
    np.testing.assert_array_equal(neighbors.pairs, [[0, 1], [2, 3]])
    np.testing.assert_allclose(neighbors.distances, [0.05, 0.0], atol=1e-12)
