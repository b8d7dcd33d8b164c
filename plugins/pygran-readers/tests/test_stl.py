"""STL surface meshes through meshio: ASCII and binary, scale, the example meshes."""

import shutil

import meshio
import numpy as np
import pytest

from pygran_core.io import Frame, open_trajectory
from pygran_core.testing import FormatConformance


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
            meshio.write(
                tmp_path / f"wall{k}.stl", meshio.Mesh(points, [("triangle", cells)]), binary=self.binary
            )
            frames.append(Frame({"points": points, "cells": cells, "cell_types": np.full(n, 5)}))
        return str(tmp_path / "wall*.stl"), frames

    def open(self, pattern):
        return open_trajectory(pattern, format="stl")


class TestSTLASCII(TestSTLBinary):
    binary = False
    exact = False  # meshio's ASCII writer prints 16 significant digits


def test_example_meshes_with_scale(fixtures, tmp_path):
    shutil.copy(fixtures / "meshes" / "silo.stl", tmp_path)
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
def test_every_example_mesh_reads(fixtures, tmp_path, name):
    shutil.copy(fixtures / "meshes" / name, tmp_path)
    mesh = open_trajectory(tmp_path / name)[0]
    text = (tmp_path / name).read_text()
    assert len(mesh.arrays["cells"]) == text.count("facet normal") > 0
