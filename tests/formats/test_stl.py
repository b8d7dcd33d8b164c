"""STL surface meshes: ASCII and binary, scale, the example meshes, damaged files."""

import shutil

import numpy as np
import pytest

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.io import Frame, open_trajectory, open_writer
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


def test_written_stl_reads_back_exactly(data_dir, tmp_path):
    """The example hopper written by PyGran's STL writer: the same points, cells and normals."""
    (silo,) = open_trajectory(data_dir / "meshes" / "silo.stl")
    with open_writer(tmp_path / "copy.stl") as out:
        out.write_frame(silo)
    (copy,) = open_trajectory(tmp_path / "copy.stl")
    for name in ("points", "cells", "cell_types"):
        np.testing.assert_array_equal(copy.arrays[name], silo.arrays[name], err_msg=name)
    normals = [
        line.split()[2:] for line in (tmp_path / "copy.stl").read_text().splitlines() if "normal" in line
    ]
    corners = silo.arrays["points"][silo.arrays["cells"]]
    expected = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(np.array(normals, float), expected, atol=1e-15)


def test_polygons_become_fans_in_cell_order_and_a_series_needs_a_star(tmp_path):
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0.5]], float)
    # a quad, a triangle, a pentagon (padded with -1), as VTK readers give mixed cells
    cells = np.array([[0, 1, 2, 3, -1], [1, 4, 5, -1, -1], [0, 1, 4, 5, 3]])
    mesh = Frame(
        {"points": points, "cells": cells, "cell_types": np.array([9, 5, 7])}, attrs={"kind": "mesh"}
    )
    with open_writer(tmp_path / "walls*.stl") as out:
        for step in (0, 10):
            mesh.timestep = step
            out.write_frame(mesh)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walls0.stl", "walls10.stl"]
    (back,) = open_trajectory(tmp_path / "walls10.stl")
    got = back.arrays["points"][back.arrays["cells"]]
    fans = [[0, 1, 2], [0, 2, 3], [1, 4, 5], [0, 1, 4], [0, 4, 5], [0, 5, 3]]
    np.testing.assert_array_equal(got, points[fans])
    with open_writer(tmp_path / "one.stl") as out:
        out.write_frame(mesh)
        with pytest.raises(UnsupportedFeature, match="holds one mesh; put '\\*' in the name"):
            out.write_frame(mesh)


def test_what_stl_cannot_hold_is_refused(tmp_path):
    lines = Frame(
        {"points": np.eye(3), "cells": np.array([[0, 1, -1], [0, 1, 2]]), "cell_types": np.array([3, 5])},
        attrs={"kind": "mesh"},
    )
    with (
        open_writer(tmp_path / "lines.stl") as out,
        pytest.raises(UnsupportedFeature, match="VTK type \\[3\\]"),
    ):
        out.write_frame(lines)
    particles = Frame({"x": np.zeros(2), "y": np.zeros(2), "z": np.zeros(2)})
    with (
        open_writer(tmp_path / "p.stl") as out,
        pytest.raises(UnsupportedFeature, match="not particle frames"),
    ):
        out.write_frame(particles)
    assert not list(tmp_path.iterdir())
