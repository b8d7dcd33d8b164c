"""STL surface meshes: ASCII and binary, scale, the example meshes, damaged files."""

import shutil

import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.io import Frame, open_trajectory
from pygran_core.testing.formats import FormatConformance


def write_stl(path, points, cells, binary):
    """An STL file of ``points[cells]``, as CAD programs write them."""
    vertices = points[cells]
    if binary:
        records = np.zeros(len(cells), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
        records["v"] = vertices
        path.write_bytes(b"binary STL".ljust(80) + np.uint32(len(cells)).tobytes() + records.tobytes())
        return
    facets = "".join(
        "facet normal 0 0 0\n outer loop\n"
        + "".join(f"  vertex {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in v)
        + " endloop\nendfacet\n"
        for v in vertices
    )
    path.write_text(f"solid test\n{facets}endsolid test\n")


def triangles(n):
    points = np.array([[i, i % 2, 0.5 * i] for i in range(n + 2)], dtype=np.float64)
    return points, np.array([[i, i + 1, i + 2] for i in range(n)])


class TestSTLBinary(FormatConformance):
    reader = "stl"
    suffix = ".stl"
    test_empty_frame = None  # a VTK/STL file cannot hold an empty mesh
    binary = True

    def make_sample(self, tmp_path):
        frames = []
        for k, n in enumerate((1, 4, 7)):
            points, cells = triangles(n)
            if self.binary:
                points = points.astype(np.float32).astype(np.float64)  # binary STL holds float32
            write_stl(tmp_path / f"wall{k}.stl", points, cells, self.binary)
            frames.append(Frame({"points": points, "cells": cells, "cell_types": np.full(n, 5)}))
        return str(tmp_path / "wall*.stl"), frames

    def open(self, pattern):
        return open_trajectory(pattern, format="stl")


class TestSTLASCII(TestSTLBinary):
    binary = False


def test_example_meshes_with_scale(data_dir, tmp_path):
    shutil.copy(data_dir / "meshes" / "silo.stl", tmp_path)
    text = (tmp_path / "silo.stl").read_text()
    first = [float(v) for v in text.split("vertex", 1)[1].split("\n", 1)[0].split()]
    assert first == [0, 0.825, 2.25]
    silo_mm = open_trajectory(tmp_path / "silo.stl")[0]
    silo = open_trajectory(tmp_path / "silo.stl", scale=1e-3)[0]
    assert silo.arrays["cells"].shape == (text.count("facet normal"), 3)
    np.testing.assert_allclose(silo.arrays["points"], silo_mm.arrays["points"] * 1e-3)
    assert any(np.allclose(p, np.array(first) * 1e-3) for p in silo.arrays["points"])
    assert silo.attrs["scale"] == 1e-3


@pytest.mark.parametrize("name", ["square.stl", "tumbler.stl", "valve.stl", "wall-2D-side.stl"])
def test_every_example_mesh_reads(data_dir, tmp_path, name):
    shutil.copy(data_dir / "meshes" / name, tmp_path)
    mesh = open_trajectory(tmp_path / name)[0]
    text = (tmp_path / name).read_text()
    assert len(mesh.arrays["cells"]) == text.count("facet normal") > 0


def test_binary_file_whose_header_starts_with_solid(tmp_path):
    points, cells = triangles(3)
    write_stl(tmp_path / "a.stl", points, cells, binary=True)
    data = (tmp_path / "a.stl").read_bytes()
    (tmp_path / "a.stl").write_bytes(b"solid exported by CAD".ljust(80) + data[80:])
    mesh = open_trajectory(tmp_path / "a.stl")[0]
    np.testing.assert_array_equal(mesh.arrays["cells"], cells)


BAD_ASCII = {
    "no vertices": (
        "solid x\nfacet normal 0 0 1\n outer loop\n endloop\nendfacet\nendsolid x\n",
        "frame 0, line 5: a facet has 0 vertices, not 3",
    ),
    "a word for a number": (
        "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 oops\n"
        "  vertex 0 1 0\n endloop\nendfacet\nendsolid x\n",
        "frame 0, line 5: a vertex coordinate is not a number: 'vertex 1 0 oops'",
    ),
    "cut after a keyword": (
        "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex",
        "frame 0, line 6: a vertex needs 3 finite coordinates: 'vertex'",
    ),
    "not finite": (
        "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 nan\n"
        "  vertex 0 1 0\n endloop\nendfacet\nendsolid x\n",
        "frame 0, line 5: a vertex needs 3 finite coordinates: 'vertex 1 0 nan'",
    ),
    "not UTF-8": (
        "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 \xe9\n",
        "frame 0, line 4: neither",
    ),
    "empty solid": ("solid x\nendsolid x\n", "frame 0: the file holds no triangle"),
    "not an stl": ("hello world\n", "frame 0, line 1: not an STL file"),
}


@pytest.mark.parametrize("case", sorted(BAD_ASCII))
def test_damaged_ascii_is_a_read_error_naming_file_frame_and_line(tmp_path, case):
    text, message = BAD_ASCII[case]
    path = tmp_path / "bad.stl"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(ReadError) as info:
        open_trajectory(path, format="stl")[0]
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


def test_truncated_binary_is_a_read_error(tmp_path):
    points, cells = triangles(4)
    write_stl(tmp_path / "a.stl", points, cells, binary=True)
    (tmp_path / "a.stl").write_bytes((tmp_path / "a.stl").read_bytes()[:-7])
    with pytest.raises(ReadError, match=r"a\.stl: frame 0, line 1: neither a binary STL \(by its size\)"):
        open_trajectory(tmp_path / "a.stl", format="stl")[0]


def test_binary_with_a_coordinate_not_finite(tmp_path):
    points, cells = triangles(4)
    points[5, 1] = np.inf  # point 5 is a vertex of the last triangle only: [3, 4, 5]
    write_stl(tmp_path / "a.stl", points, cells, binary=True)
    with pytest.raises(
        ReadError, match=r"a\.stl: frame 0: binary triangle 3 has a coordinate that is not finite"
    ):
        open_trajectory(tmp_path / "a.stl", format="stl")[0]
