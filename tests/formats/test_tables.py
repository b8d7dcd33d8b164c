"""Sphere and triangle tables: the Dosta et al. (2024) benchmark inputs, read as a user reads them."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from pygran_core.errors import PyGranWarning, ReadError
from pygran_core.formats.tables import read_spheres, read_triangles

DATA = Path(__file__).resolve().parents[2] / "benchmarks" / "dosta2024" / "data"


def test_drum_bed_has_both_sizes_in_file_order():
    bed = read_spheres(DATA / "drum_particles.txt.gz")
    assert len(bed) == 38_000 and bed.positions.shape == (38_000, 3)
    assert np.count_nonzero(bed.radius == 0.001) == 30_000
    assert np.count_nonzero(bed.radius == 0.002) == 8_000
    np.testing.assert_array_equal(bed.radius[:2], [0.002, 0.002])
    np.testing.assert_array_equal(bed.positions[0], [-0.009441591507, -0.02077494175, -0.08420070394])
    # every bead inside the drum (the wall file's radius 0.102 m, axis y)
    assert np.hypot(bed.positions[:, 0], bed.positions[:, 2]).max() + bed.radius.max() < 0.102


@pytest.mark.parametrize(("name", "rows"), [("penetration_25k", 25_000), ("penetration_50k", 50_000)])
def test_penetration_bed_reports_its_malformed_line(name, rows):
    path = DATA / f"{name}_particles.txt.gz"
    with pytest.raises(ReadError, match=rf"1 malformed line\(s\).*: {rows + 2}; pass strict=False"):
        read_spheres(path)
    with pytest.warns(PyGranWarning, match=rf"skipped 1 malformed line\(s\).*: {rows + 2}"):
        bed = read_spheres(path, strict=False)
    assert len(bed) == rows and bed.skipped == (rows + 2,)
    assert (bed.radius == 0.001).all()
    assert bed.positions[:, 2].min() - 0.001 > -0.0902431 - 1e-6  # on the box floor, within a micrometre


@pytest.mark.parametrize(
    ("name", "count", "zmin"),
    [
        ("drum", 1200, -0.101988),
        ("penetration", 56, -0.0922431),
        ("silo_small", 8636, -0.0593008),
        ("silo_large", 7632, -0.0554222),
    ],
)
def test_wall_tables(name, count, zmin):
    triangles = read_triangles(DATA / f"{name}_walls.txt.gz")
    assert triangles.shape == (count, 3, 3)
    assert triangles[..., 2].min() == pytest.approx(zmin, abs=1e-9)


def test_header_crlf_tabs_blank_lines_and_bad_values(tmp_path):
    path = tmp_path / "bed.txt"
    path.write_bytes(
        b"Radius[m]\tPosX[m] PosY[m] PosZ[m]\r\n0.5 1 2 3\r\n\r\n0.5 x 2 3\r\n0.5 1 2\r\n"
        b"0.5 inf 0 0\r\n1\t4\t5\t6\r\n"
    )
    with pytest.raises(ReadError, match=r"3 malformed line\(s\).*: 4, 5, 6;"):
        read_spheres(path)
    with pytest.warns(PyGranWarning):
        bed = read_spheres(path, strict=False)
    np.testing.assert_array_equal(bed.radius, [0.5, 1.0])
    np.testing.assert_array_equal(bed.positions, [[1, 2, 3], [4, 5, 6]])


def test_no_header_gzip_by_content_and_refusals(tmp_path):
    plain = tmp_path / "bed.dat"
    plain.write_bytes(gzip.compress(b"1e-3 0 0 0\n2e-3 1 1 1\n"))  # gzip without the .gz name
    np.testing.assert_array_equal(read_spheres(plain).radius, [1e-3, 2e-3])
    negative = tmp_path / "negative.txt"
    negative.write_text("0.001 0 0 0\n-0.001 1 1 1\n")
    with pytest.raises(ReadError, match="radius -0.001 of data row 2 is not positive"):
        read_spheres(negative)
    flat = tmp_path / "flat.txt"
    flat.write_text("0 0 0 1 1 1 2 2 2\n")
    with pytest.raises(ReadError, match="triangle of data row 1 has no area"):
        read_triangles(flat)
    with pytest.raises(ReadError, match="is a folder"):
        read_spheres(tmp_path)
    with pytest.raises(ReadError, match="File not found"):
        read_triangles(tmp_path / "missing.txt")
    damaged = tmp_path / "damaged.txt.gz"
    damaged.write_bytes(gzip.compress(b"1 2 3 4\n" * 100)[:-6])
    with pytest.raises(ReadError, match="damaged gzip"):
        read_spheres(damaged)
