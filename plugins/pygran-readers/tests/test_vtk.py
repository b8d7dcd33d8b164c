"""VTK: legacy files written by the vtk package (ASCII/binary, polydata/unstructured), XML
.vtu (written by meshio) and .vtp (by vtk), both read by vtk, particles as points, the hopper
mesh sequence, and fuzzing."""

import shutil

import meshio
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pygran_readers.vtk import VTKTrajectory
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData, vtkUnstructuredGrid
from vtkmodules.vtkIOLegacy import vtkPolyDataWriter, vtkUnstructuredGridWriter
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.testing.formats import FormatConformance, mutate, particle_frames

TRIANGLE, QUAD, VERTEX = 5, 9, 1


def sample_meshes():
    """Three meshes of growing size: triangles (and a quad), point and cell data."""
    rng = np.random.default_rng(1)
    meshes = []
    for n in (4, 9, 16):
        points = rng.random((n, 3))
        cells = [[i, i + 1, i + 2] for i in range(n - 3)] + [[0, 1, 2, 3]]
        meshes.append(
            (
                points,
                cells,
                {"temperature": rng.random(n)},
                {"meshid": np.arange(len(cells), dtype=np.int32), "v": rng.random((len(cells), 3))},
            )
        )
    return meshes


def expected_frame(points, cells, point_data, cell_data):
    width = max(len(c) for c in cells)
    table = np.full((len(cells), width), -1)
    for i, c in enumerate(cells):
        table[i, : len(c)] = c
    arrays = {
        "points": points,
        "cells": table,
        "cell_types": np.array([TRIANGLE if len(c) == 3 else QUAD for c in cells]),
    }
    arrays.update(point_data)
    arrays.update(cell_data)
    return Frame(arrays)


def vtk_dataset(points, cells, point_data, cell_data, unstructured):
    data = vtkUnstructuredGrid() if unstructured else vtkPolyData()
    vpoints = vtkPoints()
    vpoints.SetData(numpy_to_vtk(points, deep=True))
    data.SetPoints(vpoints)
    if unstructured:
        for c in cells:
            data.InsertNextCell(TRIANGLE if len(c) == 3 else QUAD, len(c), c)
    else:
        polys = vtkCellArray()
        for c in cells:
            polys.InsertNextCell(len(c), c)
        data.SetPolys(polys)
    for target, arrays in ((data.GetPointData(), point_data), (data.GetCellData(), cell_data)):
        for name, values in arrays.items():
            array = numpy_to_vtk(values, deep=True)
            array.SetName(name)
            target.AddArray(array)
    return data


class _VTKCase(FormatConformance):
    reader = "vtk"
    test_empty_frame = None  # a VTK/STL file cannot hold an empty mesh
    exact = False  # vtk's ASCII writer prints fewer digits than a float64 needs
    unstructured = False
    binary = False

    def write(self, path, mesh):
        data = vtk_dataset(*mesh, self.unstructured)
        writer = vtkUnstructuredGridWriter() if self.unstructured else vtkPolyDataWriter()
        writer.SetFileName(str(path))
        writer.SetInputData(data)
        if self.binary:
            writer.SetFileTypeToBinary()
        assert writer.Write() == 1

    def make_sample(self, tmp_path):
        meshes = sample_meshes()
        for k, mesh in enumerate(meshes):
            self.write(tmp_path / f"mesh{k * 1000}{self.suffix}", mesh)
        return str(tmp_path / f"mesh*{self.suffix}"), [expected_frame(*m) for m in meshes]

    def bad_files(self, tmp_path):
        pattern, _ = self.make_sample(tmp_path)
        last = tmp_path / f"mesh2000{self.suffix}"
        last.write_bytes(last.read_bytes()[: len(last.read_bytes()) // 2])
        return [*super().bad_files(tmp_path), (pattern, 2)]


class TestLegacyPolyDataASCII(_VTKCase):
    suffix = ".vtk"


class TestLegacyPolyDataBinary(_VTKCase):
    suffix = ".vtk"
    binary = True
    exact = True


class TestLegacyUnstructuredASCII(_VTKCase):
    suffix = ".vtk"
    unstructured = True


class TestLegacyUnstructuredBinary(_VTKCase):
    suffix = ".vtk"
    unstructured = True
    binary = True
    exact = True


class TestXMLPolyData(_VTKCase):
    suffix = ".vtp"

    def write(self, path, mesh):
        writer = vtkXMLPolyDataWriter()
        writer.SetFileName(str(path))
        writer.SetInputData(vtk_dataset(*mesh, False))
        assert writer.Write() == 1


class TestXMLUnstructured(_VTKCase):
    suffix = ".vtu"

    def write(self, path, mesh):
        points, cells, point_data, cell_data = mesh
        # meshio groups cells by type: triangles first, then the quad, as sample_meshes has them
        blocks = [
            ("triangle", [c for c in cells if len(c) == 3]),
            ("quad", [c for c in cells if len(c) == 4]),
        ]
        meshio.write(
            path,
            meshio.Mesh(
                points,
                blocks,
                point_data=point_data,
                cell_data={k: [v[:-1], v[-1:]] for k, v in cell_data.items()},
            ),
        )


class TestWriterParticles(FormatConformance):
    """Our own legacy writer: particles as vertices; x y z come first and vectors stay together."""

    reader = writer = "vtk"
    suffix = ".vtk"
    metadata = ("timestep",)  # box and boundary flags have no place in a VTK file

    def sample_frames(self):
        frames = particle_frames()
        for frame in frames:
            order = ["x", "y", "z"] + [k for k in frame.arrays if k not in "xyz"]
            frame.arrays = {k: frame.arrays[k] for k in order}
        return frames

    def make_sample(self, tmp_path):
        frames = self.sample_frames()
        with open_writer(tmp_path / "p*.vtk", **self.options) as out:
            for frame in frames:
                out.write_frame(frame)
        return str(tmp_path / "p*.vtk"), frames

    options = {"binary": False}


class TestWriterParticlesBinary(TestWriterParticles):
    options = {"binary": True}


class TestWriterMeshes(TestWriterParticles):
    """Our own writer on meshes: triangles and quads, cell and point data, time."""

    metadata = ("timestep", "time")
    test_empty_frame = None  # the sample meshes are never empty

    def sample_frames(self):
        frames = []
        for k, mesh in enumerate(sample_meshes()):
            frame = expected_frame(*mesh)
            frame.arrays["meshid"] = frame.arrays["meshid"].astype(np.int64)
            frame.attrs = {"kind": "mesh", "point_data": ["temperature"], "cell_data": ["meshid", "v"]}
            frame.timestep, frame.time = 1000 * k, 0.5 * k
            frames.append(frame)
        return frames


class TestWriterMeshesBinary(TestWriterMeshes):
    options = {"binary": True}


def test_writer_replaces_files_atomically_and_names_them_by_timestep(tmp_path):
    frame = Frame({"x": np.zeros(2), "y": np.zeros(2), "z": np.ones(2)}, timestep=42)
    with open_writer(tmp_path / "plain.vtk") as out:
        out.write_frame(frame)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain42.vtk"]
    with pytest.raises(UnsupportedFeature, match="lacks \\['z'\\]"):
        open_writer(tmp_path / "p*.vtk").write_frame(Frame({"x": np.zeros(1), "y": np.zeros(1)}))


def test_hopper_mesh_sequence(data_dir, tmp_path):
    for path in (data_dir / "liggghts-hopper").glob("mesh*.vtk"):
        shutil.copy(path, tmp_path)
    meshes = open_trajectory(str(tmp_path / "mesh*.vtk"))
    assert len(meshes) == 31
    with_velocity = 0
    for frame in meshes:
        assert frame.arrays["points"].shape == (960, 3) and frame.arrays["cells"].shape == (320, 3)
        assert frame.attrs["kind"] == "mesh" and frame.attrs["cell_data"] in (["meshid"], ["meshid", "v"])
        if "v" in frame.arrays:
            assert frame.arrays["v"].shape == (320, 3) and frame.arrays["v"].dtype == np.float64
            with_velocity += 1
    assert with_velocity == 20  # files with a "v 3 320 double" field (the valve moving)
    frame = meshes[-1]
    # the first POINTS row and the first POLYGONS row of mesh30000.vtk
    np.testing.assert_allclose(
        frame.arrays["points"][:3],
        [[0, 0.000825, 0.00225], [0, 0.0009125, 0.002625], [0.00038118, 0.000825304, 0.00261034]],
        rtol=1e-7,
    )
    assert frame.arrays["cells"][0].tolist() == [0, 1, 2] and frame.arrays["cells"][-1].tolist() == [
        957,
        958,
        959,
    ]
    assert (frame.arrays["cell_types"] == TRIANGLE).all()
    meshid = frame.arrays["meshid"]
    assert meshid[:3].tolist() == [0, 1, 2] and meshid[223] == 223 and meshid[224] == 0 and meshid[-1] == 95


LIGGGHTS_PARTICLES = """# vtk DataFile Version 2.0
Generated by LIGGGHTS
ASCII
DATASET POLYDATA
POINTS 3 float
0 0 0 1 0 0 0 1 0.5
VERTICES 3 6
1 0
1 1
1 2
POINT_DATA 3
SCALARS id int 1
LOOKUP_TABLE default
7 8 9
SCALARS radius float 1
LOOKUP_TABLE default
0.1 0.1 0.2
VECTORS v float
1 2 3 4 5 6 7 8 9
"""


def test_particles_as_points(tmp_path):
    (tmp_path / "p.vtk").write_text(LIGGGHTS_PARTICLES)
    frame = open_trajectory(tmp_path / "p.vtk")[0]
    assert frame.attrs["kind"] == "particles"
    assert list(frame.arrays) == ["x", "y", "z", "id", "radius", "vx", "vy", "vz"]
    assert frame.arrays["id"].tolist() == [7, 8, 9] and frame.arrays["id"].dtype.kind == "i"
    assert frame.arrays["z"].tolist() == [0, 0, 0.5] and frame.arrays["vy"].tolist() == [2, 5, 8]
    mesh = open_trajectory(tmp_path / "p.vtk", kind="mesh")[0]
    assert mesh.arrays["cell_types"].tolist() == [VERTEX] * 3 and mesh.arrays["v"].shape == (3, 3)


def test_vtk51_offsets_layout(tmp_path):
    text = (
        "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n"
        "0 0 0 1 0 0 0 1 0 1 1 0\nPOLYGONS 3 7\nOFFSETS vtktypeint64\n0 3 7\n"
        "CONNECTIVITY vtktypeint64\n0 1 2 0 1 3 2\n"
    )
    (tmp_path / "m.vtk").write_text(text)
    frame = open_trajectory(tmp_path / "m.vtk")[0]
    assert frame.arrays["cells"].tolist() == [[0, 1, 2, -1], [0, 1, 3, 2]]
    assert frame.arrays["cell_types"].tolist() == [TRIANGLE, QUAD]


def test_error_names_file_frame_and_line(tmp_path):
    (tmp_path / "a0.vtk").write_text(LIGGGHTS_PARTICLES)
    (tmp_path / "a1.vtk").write_text(LIGGGHTS_PARTICLES.replace("0.1 0.1 0.2", "0.1 x 0.2"))
    trajectory = open_trajectory(str(tmp_path / "a*.vtk"))
    assert len(trajectory[0].arrays["x"]) == 3
    with pytest.raises(ReadError, match=r"a1\.vtk: frame 1, line 17: expected 3 float numbers"):
        trajectory[1]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), binary=st.booleans())
def test_fuzz_mutated_legacy_vtk_raises_only_read_error(tmp_path, data, binary):
    path = tmp_path / "fuzz.vtk"
    if binary:
        _VTKCase.binary = True
    try:
        _VTKCase().write(path, sample_meshes()[0])
    finally:
        _VTKCase.binary = False
    path.write_bytes(mutate(data, path.read_bytes(), b"0123456789 .-e\nxP\x00\xff"))
    try:
        VTKTrajectory([path])[0]
    except ReadError:
        pass
