"""analysis.imaging: the original module's functions on images whose answer is known."""

from __future__ import annotations

import itertools
import os

import numpy as np
import pytest
from PIL import Image

from pygran_core.analysis import Particles, imaging
from pygran_core.errors import ConfigError, ReadError


def sphere(x, y, z, r):
    return Particles(x=[x], y=[y], z=[z], radius=[r], type=[1])


def save(array, path):
    """Write a [i, j] array as a grayscale image (PIL stores rows = j)."""
    Image.fromarray(np.ascontiguousarray(np.asarray(array, dtype=np.uint8).T), mode="L").save(path)


def test_slice_draws_the_cross_section_at_the_slab_mid_plane(tmp_path):
    r, resol = 1.0, 0.05
    ball = sphere(3.0, 2.0, 5.0, r)
    origin = (0.0, 0.0, 0.0)
    image = imaging.slice(
        ball, 5.25, 5.35, "z", resol, size=(80, 60), output=tmp_path / "s.png", origin=origin
    )
    rc2 = r**2 - 0.3**2  # the mid-plane z = 5.3 cuts at 0.3 from the centre
    expected = np.zeros((80, 60), dtype=np.uint8)
    for i, j in itertools.product(range(80), range(60)):
        if ((i + 0.5) * resol - 3.0) ** 2 + ((j + 0.5) * resol - 2.0) ** 2 <= rc2:
            expected[i, j] = 255
    np.testing.assert_array_equal(image, expected)
    assert expected.sum() / 255 * resol**2 == pytest.approx(np.pi * rc2, rel=0.02)
    np.testing.assert_array_equal(imaging.readImg(str(tmp_path / "s.png")), expected)
    # across x the image is the (y, z) plane
    side = imaging.slice(ball, 2.9, 3.1, "x", resol, size=(60, 120), origin=origin)
    assert side.shape == (60, 120) and side[40, 100] == 255 and side[40, 60] == 0
    # without resol: the particles that cut the mid-plane (the original's return value)
    assert len(imaging.slice(ball, 5.25, 5.35, "z", origin=origin)) == 1
    assert len(imaging.slice(ball, 7.0, 7.2, "z", origin=origin)) == 0


def test_slice_default_size_and_origin_enclose_the_spheres():
    pair = Particles(x=[1.0, 3.0], y=[1.0, 1.0], z=[1.0, 1.0], radius=[1.0, 1.0], type=[1, 2])
    image = imaging.slice(pair, 0.95, 1.05, "z", 0.1)
    assert image.shape == (40, 20)  # spheres span 0..4 x 0..2 from their lower corner
    assert image[10, 10] == image[30, 10] == 255 and image[20, 0] == 0


def test_slice_mistakes_are_named():
    ball = sphere(0, 0, 0, 1)
    with pytest.raises(ConfigError, match="axis must be 'x', 'y' or 'z'"):
        imaging.slice(ball, 0, 1, "w", 0.1)
    with pytest.raises(ConfigError, match="zmax"):
        imaging.slice(ball, 1, 0, "z", 0.1)
    with pytest.raises(ConfigError, match="resol"):
        imaging.slice(ball, 0, 1, "z", -0.1)


def test_readimg_stacks_in_numeric_or_chronological_order(tmp_path):
    for k in range(12):
        save(np.full((5, 3), 10 * k), tmp_path / f"img{k}.png")
        stamp = 1_000_000 + (11 - k)  # written last-first
        os.utime(tmp_path / f"img{k}.png", (stamp, stamp))
    stack = imaging.readImg(str(tmp_path / "img*"))
    assert stack.shape == (5, 3, 12) and stack[0, 0].tolist() == [10 * k for k in range(12)]
    chronological = imaging.readImg(str(tmp_path / "img*"), order=True)
    assert chronological[0, 0].tolist() == [10 * k for k in reversed(range(12))]
    listed = imaging.readImg([str(tmp_path / "img3.png"), str(tmp_path / "img1.png")], ncores=2)
    assert listed[0, 0].tolist() == [10, 30]  # a list is sorted too
    assert imaging.readImg(str(tmp_path / "img2.png"), flip=True).shape == (3, 5)


def test_readimg_fills_holes(tmp_path):
    ring = np.zeros((9, 9), dtype=np.uint8)
    ring[2:7, 2:7] = 255
    ring[3:6, 3:6] = 0
    save(ring, tmp_path / "ring.png")
    filled = imaging.readImg(str(tmp_path / "ring.png"), fillHoles=True)
    np.testing.assert_array_equal(filled, (ring > 0) | np.pad(np.ones((3, 3), bool), 3))


def test_readimg_mistakes_are_named(tmp_path):
    with pytest.raises(ReadError, match="No image file matches"):
        imaging.readImg(str(tmp_path / "none*"))
    with pytest.raises(ReadError, match="not found"):
        imaging.readImg(str(tmp_path / "missing.png"))
    with pytest.raises(ConfigError, match="ncores"):
        imaging.readImg(str(tmp_path / "none*"), ncores=0)


def test_coarse_discretize_sums_pixels_per_voxel():
    rng = np.random.default_rng(4)
    a = rng.integers(0, 2, (7, 6, 5)) * 255
    b = (255 - a) * rng.integers(0, 2, (7, 6, 5))
    fractions, mean, var = imaging.coarseDiscretize([a, b], 2.5)
    assert fractions[0].shape == (3, 3, 2)
    grid_a, grid_b = np.zeros((3, 3, 2)), np.zeros((3, 3, 2))
    for i, j, k in itertools.product(range(7), range(6), range(5)):
        cell = (int(i / 2.5), int(j / 2.5), int(k / 2.5))
        grid_a[cell] += a[i, j, k]
        grid_b[cell] += b[i, j, k]
    total = grid_a + grid_b
    expected = np.where(total > 0, grid_a / np.where(total > 0, total, 1), 0)
    np.testing.assert_allclose(fractions[0], expected, rtol=1e-12)
    np.testing.assert_allclose(fractions[0] + fractions[1], (total > 0).astype(float), rtol=1e-12)
    assert mean[0] == pytest.approx(expected[total > 0].mean()) and var[0] == pytest.approx(
        expected[total > 0].var()
    )


def test_intensity_of_pure_and_perfectly_mixed_voxels():
    a = np.zeros((8, 8, 8))
    a[:4] = 255
    _, _, segregated = imaging.intensitySegregation([a, 255 - a], 2)
    assert segregated == pytest.approx(1.0, rel=1e-12)  # every 2-pixel voxel is pure
    checker = 255.0 * (np.indices((8, 8, 8)).sum(axis=0) % 2)
    mean, var, mixed = imaging.intensitySegregation([checker, 255 - checker], 2)
    assert mean == [0.5, 0.5] and var == 0 and mixed == 0  # every voxel is half and half
    with pytest.raises(ConfigError, match="two species"):
        imaging.intensitySegregation([a], 2)


def brute_correlation(a, filled, edges):
    """Danckwerts' R over all ordered voxel pairs (self-pairs included), binned by distance."""
    points = np.argwhere(filled)
    values = a[filled] - a[filled].mean()
    distance = np.sqrt(((points[:, None, :] - points[None, :, :]) ** 2).sum(axis=-1)).ravel()
    products = np.outer(values, values).ravel()
    which = np.minimum(np.searchsorted(edges, distance, side="right") - 1, len(edges) - 2)
    r, R = [], []
    for b in range(len(edges) - 1):
        inside = which == b
        if inside.any():
            r.append(distance[inside].mean())
            R.append(products[inside].mean() / values.var())
    return np.array(r), np.array(R)


def test_fft_correlation_equals_the_all_pairs_sum():
    rng = np.random.default_rng(8)
    a = rng.random((5, 4, 3)) * 255
    b = 255 - a
    b[0, 0, :] = a[0, 0, :] = 0  # voids are left out
    r, R = imaging.scaleSegregation_fft([a, b], 1, 0.5, Npts=7)
    filled = (a + b) > 0
    edges = np.linspace(0, np.sqrt(4**2 + 3**2 + 2**2), 8)
    r_exact, R_exact = brute_correlation(a / (a + np.where(filled, b, 1)), filled, edges)
    np.testing.assert_allclose(r, 0.5 * r_exact, rtol=1e-9)
    np.testing.assert_allclose(R, R_exact, rtol=1e-9, atol=1e-12)


def test_scale_of_segregation_segregated_versus_random():
    halves = np.zeros((12, 12, 12))
    halves[:6] = 255
    r, R = imaging.scaleSegregation([halves, 255 - halves], 1, 800, 0.1, maxDist=6, seed=3)
    assert r.tolist() == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5]) and R[0] == 1.0
    assert np.all(np.diff(R) < 0) and R[1] > 0.85
    r_fft, R_fft = imaging.scaleSegregation_fft([halves, 255 - halves], 1, 0.1, Npts=40)
    np.testing.assert_allclose(R[1:5], np.interp(r[1:5], r_fft, R_fft), atol=0.08)  # MC vs exact
    again = imaging.scaleSegregation([halves, 255 - halves], 1, 800, 0.1, maxDist=6, seed=3)
    np.testing.assert_array_equal(again[1], R)
    noise = np.random.default_rng(5).integers(0, 2, (12, 12, 12)) * 255.0
    _, R_random = imaging.scaleSegregation([noise, 255 - noise], 1, 2000, 0.1, maxDist=5, seed=4)
    assert R_random[0] == pytest.approx(1, abs=0.05) and np.abs(R_random[1:]).max() < 0.1  # uncorrelated
    _, R_random_fft = imaging.scaleSegregation_fft([noise, 255 - noise], 1, 0.1, Npts=20)
    assert np.abs(R_random_fft[1:8]).max() < 0.05


def test_correlation_mistakes_are_named():
    uniform = np.full((4, 4, 4), 128.0)
    with pytest.raises(ConfigError, match="same fraction in every voxel"):
        imaging.scaleSegregation_fft([uniform, uniform], 2, 0.1)
    halves = np.zeros((4, 4, 4))
    halves[:2] = 255
    with pytest.raises(ConfigError, match="samplesize"):
        imaging.scaleSegregation([halves, 255 - halves], 1, 0, 0.1)
    with pytest.raises(ConfigError, match="binsize"):
        imaging.coarseDiscretize([halves], 0)
