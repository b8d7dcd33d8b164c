"""Particles statistics against configurations with known answers."""

import numpy as np
import pytest

from pygran_core.analysis import Particles, _neighbors
from pygran_core.errors import ConfigError
from pygran_core.testing.solvers import kernel_path

R = 0.5
NN = 2 * R  # nearest-neighbour distance of the lattices below (spheres in contact)


def make(positions, radius=R, **extra):
    positions = np.asarray(positions, dtype=float)
    n = len(positions)
    return Particles(
        id=np.arange(1, n + 1),
        x=positions[:, 0],
        y=positions[:, 1],
        z=positions[:, 2],
        radius=np.broadcast_to(radius, n),
        **extra,
    )


def fcc(cells, periodic=True):
    """FCC lattice of touching spheres (radius R) in a cubic box of ``cells``^3 unit cells."""
    a = NN * np.sqrt(2)
    grid = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing="ij"), -1).reshape(-1, 3)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    positions = ((grid[:, None, :] + basis + 0.25) * a).reshape(-1, 3)
    box = {"box": [[0, cells * a]] * 3, "boundary": ("pp", "pp", "pp")} if periodic else {}
    return make(positions, **box)


def simple_cubic(n, spacing=NN):
    grid = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return make((grid + 0.5) * spacing)


def uniform_ball(n, radius, seed=0):
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    return direction * radius * rng.random(n)[:, None] ** (1 / 3)


# -- RDF -------------------------------------------------------------------------------------


@pytest.fixture(params=["compiled", "numpy"])
def pair_search(request, monkeypatch):
    """Each test runs on the core's compiled sweep (required under CI) and on the numpy path."""
    return kernel_path(request.param, _neighbors, monkeypatch)


@pytest.mark.parametrize(
    "boundary",
    [("pp", "pp", "pp"), ("pp", "ff", "pp"), ("ff", "ff", "ff")],
)
def test_rdf_counts_every_pair_like_a_brute_force_count(pair_search, boundary):
    """On a grid of step 0.25 with dr = 0.25 many distances fall exactly on bin edges: a pair
    counts in bin k when edges[k]² < d² <= edges[k+1]²."""
    rng = np.random.default_rng(3)
    lengths = np.array([6.0, 5.0, 7.0])
    positions = np.vstack((rng.random((900, 3)) * lengths, np.round(rng.random((300, 3)) * lengths * 4) / 4))
    periodic = np.array([flag == "pp" for flag in boundary])
    positions = np.where(periodic, positions % lengths, positions)
    particles = make(positions, box=np.column_stack(([0, 0, 0], lengths)), boundary=boundary)
    rdf = particles.computeRDF(dr=0.25, rMax=1.5)
    # brute force: reference particles at least rMax from the open faces of the particles' extent
    lower, upper = positions.min(axis=0), positions.max(axis=0)
    inside = (((positions >= lower + 1.5) & (positions <= upper - 1.5)) | periodic).all(axis=1)
    np.testing.assert_array_equal(rdf.references, np.flatnonzero(inside))
    delta = positions[None, :, :] - positions[inside][:, None, :]
    delta[..., periodic] -= lengths[periodic] * np.round(delta[..., periodic] / lengths[periodic])
    squared = (delta**2).sum(axis=-1)
    edges = np.linspace(0, 1.5, 7)
    counts = np.bincount(np.searchsorted(edges**2, squared[squared > 0]), minlength=8)[1:7]
    volume = np.prod(np.where(periodic, lengths, upper - lower))
    shells = 4 / 3 * np.pi * np.diff(edges**3)
    norm = inside.sum() * (len(positions) - 1) / volume * shells
    np.testing.assert_array_equal(np.rint(rdf.g * norm), counts)
    np.testing.assert_allclose(rdf.g * norm, counts, rtol=1e-12)
    assert counts.min() > 50


@pytest.mark.usefixtures("pair_search")
def test_rdf_of_an_ideal_gas_is_one_periodic_and_open():
    rng = np.random.default_rng(1)
    points = rng.random((20000, 3))
    periodic = make(points, radius=1e-3, box=[[0, 1]] * 3, boundary=("pp", "pp", "pp"))
    rdf = periodic.computeRDF(dr=0.015, rMax=0.15)
    assert rdf.references.size == 20000
    np.testing.assert_allclose(rdf.g[3:], 1.0, atol=0.05)
    assert abs(rdf.g.mean() - 1) < 0.01
    g, r, references = make(points, radius=1e-3).rdf(dr=0.02)  # the manual's name; open box
    assert 0 < references.size < 20000 and r.max() < 0.25
    np.testing.assert_allclose(g[3:], 1.0, atol=0.06)


@pytest.mark.usefixtures("pair_search")
def test_rdf_of_fcc_peaks_at_the_lattice_shells_and_integrates_to_twelve():
    particles = fcc(5)
    rdf = particles.computeRDF(dr=0.005, rMax=2.4)
    shells = NN * np.sqrt(np.arange(1, 6))  # FCC shells at d*sqrt(m), m = 1..5 (all occupied)
    peaks = rdf.r[rdf.g > 0]
    assert np.abs(peaks[:, None] - shells[None, :]).min(axis=1).max() <= 0.005
    for shell in shells:
        assert rdf.g[np.abs(rdf.r - shell) <= 0.005].sum() > 0
    assert peaks[0] == pytest.approx(NN, abs=0.005)  # nothing closer than contact
    # coordination from the RDF: n * integral of g 4 pi r^2 dr over the first shell = 12
    density = (len(particles) - 1) / np.prod(np.ptp(np.asarray(particles.box), axis=1))
    first = rdf.r < 1.2 * NN
    dr = rdf.r[1] - rdf.r[0]
    assert density * (rdf.g[first] * 4 * np.pi * rdf.r[first] ** 2 * dr).sum() == pytest.approx(12, rel=0.01)


def test_rdf_errors_are_clear():
    with pytest.raises(ValueError, match="at least two particles"):
        make(np.zeros((1, 3))).computeRDF()
    with pytest.raises(ValueError, match="no particle lies at least rMax"):
        simple_cubic(3).computeRDF(rMax=10.0)
    with pytest.raises(ValueError, match="half of each periodic box length"):
        fcc(2).computeRDF(rMax=100.0)


# -- geometry ---------------------------------------------------------------------------------


def test_radius_of_gyration_of_a_uniform_sphere():
    particles = make(uniform_ball(200000, 2.0), radius=1e-3)
    assert particles.computeROG() == pytest.approx(np.sqrt(3 / 5) * 2.0, rel=0.01)
    assert particles.computeRadius(N=100) == pytest.approx(2.0, rel=0.01)


def test_centre_of_mass_weights_by_volume_or_mass():
    particles = make([[0, 0, 0], [3, 0, 0]], radius=[1.0, 2.0])
    np.testing.assert_allclose(particles.computeCOM(), [3 * 8 / 9, 0, 0])
    weighted = make([[0, 0, 0], [3, 0, 0]], mass=[2.0, 1.0])
    np.testing.assert_allclose(weighted.computeCOM(), [1, 0, 0])


def test_positions_is_n_by_three():
    particles = make([[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(particles.positions, [[1, 2, 3], [4, 5, 6]])
    assert make(np.zeros((0, 3))).positions.shape == (0, 3)


# -- mass, volume, density ------------------------------------------------------------------


def test_mass_from_argument_or_columns_and_clear_error():
    particles = make([[0, 0, 0], [5, 0, 0]], radius=[1.0, 2.0])
    np.testing.assert_allclose(particles.computeMass(3.0), 3.0 * 4 / 3 * np.pi * np.array([1, 8]))
    with_density = make([[0, 0, 0]], radius=1.0, density=[2.0])
    assert with_density.computeMass()[0] == pytest.approx(2.0 * 4 / 3 * np.pi)
    assert make([[0, 0, 0]], mass=[7.0]).computeMass()[0] == 7.0
    with pytest.raises(ValueError, match="pass density=... or give the particles a 'mass' or 'density'"):
        particles.computeMass()


def test_bulk_density_of_a_simple_cubic_packing_is_pi_over_six():
    particles = simple_cubic(6)
    assert particles.computeVolume() == pytest.approx((6 * NN) ** 3)
    assert particles.computeDensity(2500.0) == pytest.approx(2500 * np.pi / 6)
    assert particles.computeVolume("cylinder-z") == pytest.approx(np.pi * (3 * NN) ** 2 * 6 * NN)
    with pytest.raises(ConfigError, match="Unknown shape 'sphere'"):
        particles.computeVolume("sphere")
    assert make(np.zeros((0, 3))).computeVolume() == 0.0


def test_local_density_is_uniform_in_slabs_of_one_layer():
    centres, density = simple_cubic(5).computeDensityLocal(1000.0, dr=NN, axis="y")
    np.testing.assert_allclose(centres, (np.arange(5) + 0.5) * NN)
    np.testing.assert_allclose(density, 1000 * np.pi / 6)
    with pytest.raises(ConfigError, match="Unknown axis 'w'"):
        simple_cubic(2).computeDensityLocal(1.0, axis="w")


def test_angle_of_repose_of_a_cone():
    rng = np.random.default_rng(2)
    height, base = 1.0, 2.0  # 26.57 degrees
    points = rng.random((200000, 3))
    r = base * np.sqrt(points[:, 0])
    z = points[:, 2] * height
    keep = z <= height * (1 - r / base)
    theta = 2 * np.pi * points[:, 1]
    cone = np.vstack((np.column_stack((r * np.cos(theta), r * np.sin(theta), z))[keep], [[0, 0, height]]))
    angle = make(cone, radius=1e-6).computeAngleRepose()
    assert angle == pytest.approx(np.degrees(np.arctan(height / base)), abs=0.5)


# -- mixing -------------------------------------------------------------------------------------


def binary(types_of_cell, per_cell=27, cell=3.0):
    """Cubic cells of side ``cell`` filled with ``per_cell`` particles of one type each."""
    shape = types_of_cell.shape
    offsets = (np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * cell / 3
    assert len(offsets) == per_cell
    origin = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1).reshape(-1, 3) * cell
    positions = (origin[:, None, :] + offsets).reshape(-1, 3)
    types = np.repeat(types_of_cell.ravel(), per_cell)
    particles = make(positions, radius=0.25)
    return Particles(Particles=particles, type=types)


def test_segregated_mixture_intensity_one_lacey_zero():
    halves = np.zeros((4, 4, 4), dtype=int) + 1
    halves[2:] = 2
    particles = binary(halves)
    assert particles.computeIntensitySegregation(resol=3.0) == pytest.approx(1.0)
    assert particles.computeLaceyIndex(resol=3.0) == pytest.approx(0.0, abs=1e-12)


def test_random_mixture_lacey_near_one_intensity_near_zero():
    rng = np.random.default_rng(3)
    particles = binary(np.ones((6, 6, 6), dtype=int))
    particles = Particles(Particles=particles, type=rng.integers(1, 3, len(particles)))
    assert particles.computeLaceyIndex(resol=3.0) == pytest.approx(1.0, abs=0.15)
    assert particles.computeIntensitySegregation(resol=3.0) < 0.1


def test_scale_of_segregation_of_a_checkerboard():
    index = np.indices((6, 6, 6)).sum(axis=0)
    particles = binary(1 + index % 2)
    corr = particles.computeScaleSegregation(resol=3.0, maxDist=6.5)
    expected = {0: 1.0, 1: -1.0, 2: 1.0, 3: -1.0, 4: 1.0}  # squared cell distance -> R
    for d2, value in expected.items():
        at = np.isclose(corr.r, 3.0 * np.sqrt(d2))
        assert at.sum() == 1 and corr.R[at][0] == pytest.approx(value)


def test_mixing_needs_types():
    particles = simple_cubic(2)
    with pytest.raises(ValueError, match="need a 'type' attribute"):
        particles.computeLaceyIndex()
    three = Particles(Particles=particles, type=[1, 2, 3, 1, 2, 3, 1, 2])
    with pytest.raises(ValueError, match="pass species=<type>"):
        three.computeIntensitySegregation()
    assert 0 <= three.computeIntensitySegregation(resol=NN, species=3) <= 1
    with pytest.raises(ValueError, match="species=9 is not among"):
        three.computeLaceyIndex(species=9)


def test_statistics_of_no_particles_say_so():
    empty = make(np.zeros((0, 3)))
    for method in ("computeROG", "computeCOM", "computeRadius"):
        with pytest.raises(ValueError, match="needs at least one particle"):
            getattr(empty, method)()
