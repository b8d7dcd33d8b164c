"""Placing spheres without overlaps, against spheres, planes and triangles; reproducibly."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pygran_core.simulation.calls import Region
from pygran_core.simulation.insertion import Obstacles, insertion_steps, place_spheres, triangle_distance

BLOCK = Region("block", (0.0, 0.01, 0.0, 0.01, 0.0, 0.01))


def _min_gap(centres, radii):
    pairs = cKDTree(centres).query_pairs(2 * radii.max(), output_type="ndarray")
    if not len(pairs):
        return np.inf
    d = np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1)
    return float(np.min(d - radii[pairs[:, 0]] - radii[pairs[:, 1]]))


def test_polydisperse_spheres_do_not_overlap_and_stay_inside():
    rng = np.random.default_rng(0)
    radii = rng.uniform(2e-4, 4e-4, 800)
    index, centres = place_spheres(BLOCK, radii, rng)
    assert len(index) == 800 and sorted(index) == list(range(800))
    assert _min_gap(centres, radii[index]) >= 0
    assert BLOCK.contains(centres, radii[index]).all()


def test_existing_spheres_and_obstacles_are_avoided():
    rng = np.random.default_rng(1)
    existing = (np.array([[0.005, 0.005, 0.005]]), np.array([0.003]))
    plane = Obstacles(np.array([[0, 0, 0.004]]), np.array([[0, 0, 1.0]]))
    index, centres = place_spheres(BLOCK, np.full(200, 3e-4), rng, existing, plane)
    assert len(index) == 200
    assert np.all(np.linalg.norm(centres - existing[0][0], axis=1) >= 0.003 + 3e-4)
    assert np.all(np.abs(centres[:, 2] - 0.004) >= 3e-4)  # planes act on both sides
    assert np.any(centres[:, 2] < 0.004) and np.any(centres[:, 2] > 0.004)


def test_same_seed_same_packing():
    radii = np.full(300, 3e-4)
    first = place_spheres(BLOCK, radii, np.random.default_rng(7))
    second = place_spheres(BLOCK, radii, np.random.default_rng(7))
    np.testing.assert_array_equal(first[1], second[1])
    third = place_spheres(BLOCK, radii, np.random.default_rng(8))
    assert not np.array_equal(first[1], third[1])


def test_a_full_region_places_what_fits():
    index, centres = place_spheres(BLOCK, np.full(2000, 1e-3), np.random.default_rng(2), attempts=20)
    assert 0 < len(index) < 2000
    assert _min_gap(centres, np.full(len(index), 1e-3)) >= 0


@pytest.mark.parametrize(
    ("point", "distance"),
    [
        ((0.2, 0.2, 1.0), 1.0),
        ((2.0, 0.0, 0.0), 1.0),
        ((-1.0, -1.0, 0.0), 2**0.5),
        ((0.5, 0.5, 0.5), 0.5),
        ((0.0, 0.5, -0.3), 0.3),
        ((1.0, 1.0, 0.0), 0.5**0.5),
    ],
)
def test_point_triangle_distance(point, distance):
    triangle = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    assert triangle_distance(np.array([point]), triangle)[0] == pytest.approx(distance)


def test_triangle_distance_matches_dense_sampling():
    rng = np.random.default_rng(3)
    triangles = rng.normal(size=(5, 3, 3))
    points = rng.normal(size=(50, 3)) * 2
    u, v = np.meshgrid(np.linspace(0, 1, 150), np.linspace(0, 1, 150))
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    samples = (
        triangles[:, None, 0]
        + u[:, None] * (triangles[:, None, 1] - triangles[:, None, 0])
        + v[:, None] * (triangles[:, None, 2] - triangles[:, None, 0])
    ).reshape(-1, 3)
    brute = cKDTree(samples).query(points)[0]
    exact = triangle_distance(points, triangles)
    assert np.all(exact <= brute + 1e-12)
    np.testing.assert_allclose(exact, brute, atol=0.02)


@pytest.mark.parametrize(
    ("first", "freq", "start", "stop", "end", "steps"),
    [
        (0, 100, 0, 300, None, [0, 100, 200]),  # a run of 300 steps: none at its last step
        (0, 100, 300, 400, None, [300]),  # the next run makes the one due at 300 as it starts
        (50, 100, 0, 400, None, [50, 150, 250, 350]),  # an insert() between multiples of freq
        (50, 100, 151, 400, None, [250, 350]),
        (0, 100, 0, 1000, 250, [0, 100, 200]),  # by rate for a duration
        (20, None, 0, 100, None, [20]),  # once
        (20, None, 20, 20, None, []),
        (20, None, 21, 100, None, []),
    ],
)
def test_insertion_steps_follow_liggghts_rule(first, freq, start, stop, end, steps):
    assert insertion_steps(first, freq, start, stop, end) == steps
