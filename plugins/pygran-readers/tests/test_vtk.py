"""VTK: legacy files written by the vtk package (ASCII/binary, polydata/unstructured), XML
.vtu and .vtp written by meshio and by vtk in each of its encodings, particles as points, the
hopper mesh sequence, damaged XML files, and fuzzing of every VTK format."""

import base64
import re
import shutil
import zlib

import meshio
import numpy as np
import pytest
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData, vtkUnstructuredGrid
from vtkmodules.vtkIOLegacy import vtkPolyDataWriter, vtkUnstructuredGridWriter
from vtkmodules.vtkIOXML import (
    vtkXMLPolyDataWriter,
    vtkXMLUnstructuredGridReader,
    vtkXMLUnstructuredGridWriter,
)

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.testing.formats import (
    BYTES,
    FormatConformance,
    damaged_copies,
    fuzz_check,
    particle_frames,
    read_every_frame,
)

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


def write_series(tmp_path, name, frames, suffix):
    """Particle frames as PyGran's writer of ``suffix`` lays them out: one file a frame, named
    by its step (so a glob orders them and steps cannot go back)."""
    pattern = tmp_path / f"insane-{name.replace(' ', '-')}-*{suffix}"
    with open_writer(pattern) as out:
        for frame in frames:
            out.write_frame(frame)
    return str(pattern)


class _VTKCase(FormatConformance):
    reader = "vtk"
    test_empty_frame = None  # a VTK/STL file cannot hold an empty mesh
    exact = False  # vtk's ASCII writer prints fewer digits than a float64 needs
    unstructured = False
    binary = False
    physical_checks = True
    steps_from_file_names = True

    def make_insane(self, tmp_path, name, frames):
        return write_series(tmp_path, name, frames, self.suffix)

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
    """.vtp as vtk writes it by default: appended base64 data, zlib-compressed, UInt32 headers."""

    suffix = ".vtp"
    exact = True

    def configure(self, writer):
        """How the vtk writer encodes the data; subclasses vary it."""

    def write(self, path, mesh):
        writer = vtkXMLPolyDataWriter() if self.suffix == ".vtp" else vtkXMLUnstructuredGridWriter()
        writer.SetFileName(str(path))
        writer.SetInputData(vtk_dataset(*mesh, self.suffix == ".vtu"))
        self.configure(writer)
        assert writer.Write() == 1


class TestXMLPolyDataAscii(TestXMLPolyData):
    exact = False  # vtk's ASCII writer prints fewer digits than a float64 needs

    def configure(self, writer):
        writer.SetDataModeToAscii()


class TestXMLPolyDataRawLZMABigEndian(TestXMLPolyData):
    def configure(self, writer):
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOff()
        writer.SetCompressorTypeToLZMA()
        writer.SetByteOrderToBigEndian()


class TestXMLUnstructuredInlineBinary(TestXMLPolyData):
    suffix = ".vtu"

    def configure(self, writer):
        writer.SetDataModeToBinary()
        writer.SetHeaderTypeToUInt64()


class TestXMLUnstructuredUncompressed(TestXMLPolyData):
    suffix = ".vtu"

    def configure(self, writer):
        writer.SetDataModeToBinary()
        writer.SetCompressorTypeToNone()


class TestXMLUnstructuredRawUncompressed(TestXMLPolyData):
    suffix = ".vtu"

    def configure(self, writer):
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOff()
        writer.SetCompressorTypeToNone()


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
    physical_checks = True
    steps_from_file_names = True  # one file a frame, named by its step: a glob orders them

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

    def make_insane(self, tmp_path, name, frames):
        return write_series(tmp_path, name, frames, self.suffix)


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


class TestWriterParticlesVTP(TestWriterParticles):
    """The XML polydata writer: particles as vertices, every value exact."""

    reader, writer, suffix = "vtk", "vtp", ".vtp"
    options: dict = {}

    def make_sample(self, tmp_path):
        frames = self.sample_frames()
        with open_writer(tmp_path / "p*.vtp") as out:
            for frame in frames:
                out.write_frame(frame)
        return str(tmp_path / "p*.vtp"), frames


class TestWriterMeshesVTP(TestWriterMeshes):
    reader, writer, suffix = "vtk", "vtp", ".vtp"
    options: dict = {}

    def make_sample(self, tmp_path):
        frames = self.sample_frames()
        with open_writer(tmp_path / f"m*{self.suffix}") as out:
            for frame in frames:
                out.write_frame(frame)
        return str(tmp_path / f"m*{self.suffix}"), frames


class TestWriterParticlesVTU(TestWriterParticlesVTP):
    """The XML unstructured-grid writer: particles as vertex cells, every value exact."""

    writer, suffix = "vtu", ".vtu"

    def make_sample(self, tmp_path):
        return TestWriterMeshesVTP.make_sample(self, tmp_path)


class TestWriterMeshesVTU(TestWriterMeshesVTP):
    writer, suffix = "vtu", ".vtu"


class TestPVDSeries(TestWriterMeshes):
    """``out.pvd`` written and read back: the index gives every frame its step and time."""

    reader = writer = "pvd"
    suffix = ".pvd"
    physical_checks = True

    def make_sample(self, tmp_path):
        return FormatConformance.make_sample(self, tmp_path)

    def bad_files(self, tmp_path):
        broken = tmp_path / "broken.pvd"
        broken.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection"><Collection><DataSet timestep=')
        missing = tmp_path / "missing.pvd"
        missing.write_text(
            '<?xml version="1.0"?>\n<VTKFile type="Collection"><Collection>\n'
            '<DataSet timestep="0" file="gone.vtp"/></Collection></VTKFile>\n'
        )
        return [*super().bad_files(tmp_path), (broken, 0), (missing, 0)]


def test_series_writes_an_unchanged_frame_once_and_indexes_it_at_every_step(tmp_path):
    """A static wall: one file, three entries with their own step and time; then it moves."""
    frame = expected_frame(*sample_meshes()[0])
    frame.attrs = {"kind": "mesh", "point_data": [], "cell_data": []}
    frame.arrays = {k: frame.arrays[k] for k in ("points", "cells", "cell_types")}
    moved = Frame(dict(frame.arrays, points=frame.arrays["points"] + 1.0), attrs=frame.attrs)
    with open_writer(tmp_path / "walls*.vtk") as out:
        for step, item in ((0, frame), (10, frame), (20, frame), (30, moved)):
            item.timestep, item.time = step, step * 1e-6
            out.write_frame(item)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walls.pvd", "walls0.vtk", "walls30.vtk"]
    with open_trajectory(tmp_path / "walls.pvd") as series:
        assert [f.timestep for f in series] == [0, 10, 20, 30]
        assert [f.time for f in series] == [step * 1e-6 for step in (0, 10, 20, 30)]
        np.testing.assert_array_equal(series[2].arrays["points"], frame.arrays["points"])
        np.testing.assert_array_equal(series[3].arrays["points"], frame.arrays["points"] + 1.0)


@pytest.mark.parametrize("suffix", [".vtk", ".vtp", ".vtu"])
def test_impossible_particles_are_a_read_error(tmp_path, suffix):
    """Two particles with one id, a radius of zero: a ReadError naming the file and the fault."""
    for name, arrays in (
        ("twins", {"id": np.array([1, 1]), "radius": np.array([0.1, 0.1])}),
        ("flat", {"id": np.array([1, 2]), "radius": np.array([0.1, 0.0])}),
    ):
        frame = Frame({"x": np.zeros(2), "y": np.zeros(2), "z": np.arange(2.0), **arrays}, timestep=5)
        with open_writer(tmp_path / f"{name}*{suffix}") as out:
            out.write_frame(frame)
        with pytest.raises(ReadError, match=f"{name}5\\{suffix}: frame 0: .*(more than once|not positive)"):
            open_trajectory(tmp_path / f"{name}5{suffix}")[0]


def test_writer_replaces_files_atomically_and_names_them_by_timestep(tmp_path):
    frame = Frame({"x": np.zeros(2), "y": np.zeros(2), "z": np.ones(2)}, timestep=42)
    with open_writer(tmp_path / "plain.vtk") as out:
        out.write_frame(frame)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.pvd", "plain42.vtk"]
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


def polydata_of_every_section():
    """Five points; a vertex, a poly-vertex, a line, a polyline, a triangle, a quad, a strip."""
    data = vtkPolyData()
    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.arange(15, dtype=float).reshape(5, 3), deep=True))
    data.SetPoints(points)
    for setter, cells in (
        (data.SetVerts, [[4], [0, 1]]),
        (data.SetLines, [[0, 1], [1, 2, 3]]),
        (data.SetPolys, [[0, 1, 2], [0, 1, 2, 3]]),
        (data.SetStrips, [[0, 1, 2, 3, 4]]),
    ):
        array = vtkCellArray()
        for cell in cells:
            array.InsertNextCell(len(cell), cell)
        setter(array)
    ids = numpy_to_vtk(np.arange(7, dtype=np.int32) * 10, deep=True)
    ids.SetName("cid")
    data.GetCellData().AddArray(ids)
    return data


def test_polydata_sections_in_vtk_cell_order(tmp_path):
    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(tmp_path / "all.vtp"))
    writer.SetInputData(polydata_of_every_section())
    assert writer.Write() == 1
    frame = open_trajectory(tmp_path / "all.vtp", kind="mesh")[0]
    cells = [[p for p in row if p >= 0] for row in frame.arrays["cells"].tolist()]
    assert cells == [[4], [0, 1], [0, 1], [1, 2, 3], [0, 1, 2], [0, 1, 2, 3], [0, 1, 2, 3, 4]]
    assert frame.arrays["cell_types"].tolist() == [VERTEX, 2, 3, 4, TRIANGLE, QUAD, 6]
    assert frame.arrays["cid"].tolist() == [0, 10, 20, 30, 40, 50, 60]
    assert frame.arrays["points"][4].tolist() == [12.0, 13.0, 14.0]


def test_several_pieces_read_as_vtk_reads_them(tmp_path):
    points, cells, point_data, cell_data = sample_meshes()[2]
    writer = vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(tmp_path / "pieces.vtu"))
    writer.SetInputData(vtk_dataset(points, cells, point_data, cell_data, unstructured=True))
    writer.SetNumberOfPieces(3)
    assert writer.Write() == 1
    assert (tmp_path / "pieces.vtu").read_text().count("<Piece ") == 3
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(tmp_path / "pieces.vtu"))
    reader.Update()
    grid = reader.GetOutput()
    frame = open_trajectory(tmp_path / "pieces.vtu")[0]
    np.testing.assert_array_equal(frame.arrays["points"], vtk_to_numpy(grid.GetPoints().GetData()))
    offsets = vtk_to_numpy(grid.GetCells().GetOffsetsArray())
    connectivity = vtk_to_numpy(grid.GetCells().GetConnectivityArray())
    want = [connectivity[a:b].tolist() for a, b in zip(offsets[:-1], offsets[1:])]
    assert [[p for p in row if p >= 0] for row in frame.arrays["cells"].tolist()] == want
    np.testing.assert_array_equal(frame.arrays["temperature"], vtk_to_numpy(grid.GetPointData().GetArray(0)))
    np.testing.assert_array_equal(frame.arrays["v"], vtk_to_numpy(grid.GetCellData().GetArray("v")))


ASCII_GRID = """<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
  <UnstructuredGrid>
    <Piece NumberOfPoints="3" NumberOfCells="1">
      <PointData>
        <DataArray type="Float64" Name="t" NumberOfComponents="1" format="ascii">1 2 3</DataArray>
      </PointData>
      <Points>
        <DataArray type="Float32" Name="Points" NumberOfComponents="3" format="ascii">
          0 0 0 1 0 0 0 1 0</DataArray>
      </Points>
      <Cells>
        <DataArray type="Int64" Name="connectivity" format="ascii">0 1 2</DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii">3</DataArray>
        <DataArray type="UInt8" Name="types" format="ascii">5</DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"""


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('NumberOfCells="1"', 'NumberOfCells="-1"', "line 4: NumberOfCells=-1 is negative"),
        ('NumberOfComponents="1"', 'NumberOfComponents="900000000000"', "line 6: array 't' holds 3 values"),
        (
            'NumberOfPoints="3"',
            'NumberOfPoints="4"',
            "line 9: array 'Points' holds 9 values; 4 tuples of 3 Float32 need 12",
        ),
        (">0 1 2<", ">0 1 7<", "line 13: <Cells> refers to point 7 but the piece has 3 points"),
        (">3</", ">2</", "line 13: <Cells> connectivity has 3 values, the offsets use 2"),
        (">5</", ">500</", "line 15: array 'types': a value does not fit in uint8"),
        ('format="ascii">1 2 3', 'format="ascii">1 x 3', "line 6: array 't': not a list of float64 numbers"),
        (
            'format="ascii">1 2 3',
            'format="binary">AAAA',
            "line 6: array 't': the data ends inside its 1-item",
        ),
        ('<?xml version="1.0"?>', '<!DOCTYPE x [<!ENTITY a "aaaa">]>', "line 1: a DOCTYPE declaration"),
        ("</Cells>", "", "line 17: not well-formed XML: mismatched tag"),
        (
            'byte_order="LittleEndian"',
            'compressor="vtkLZ4DataCompressor"',
            "line 2: compressor 'vtkLZ4DataCompressor' is not supported",
        ),
        (
            'type="UnstructuredGrid"',
            'type="ImageData"',
            "line 2: only UnstructuredGrid and PolyData files are read",
        ),
    ],
)
def test_damaged_xml_is_a_read_error_naming_file_frame_and_line(tmp_path, old, new, message):
    (tmp_path / "a0.vtu").write_text(ASCII_GRID)
    assert ASCII_GRID.count(old) == 1
    (tmp_path / "a1.vtu").write_text(ASCII_GRID.replace(old, new))
    trajectory = open_trajectory(str(tmp_path / "a*.vtu"), format="vtk")
    assert trajectory[0].arrays["cells"].tolist() == [[0, 1, 2]]
    with pytest.raises(ReadError, match=rf"a1\.vtu: frame 1, {re.escape(message)}"):
        trajectory[1]


def test_huge_consistent_counts_are_refused_without_allocating(tmp_path):
    """2**58 points whose UInt64 compression header agrees (6.9e18 bytes), but whose one
    block holds 10 bytes: refused after inflating what is there, nothing the size of the claim."""
    n = 2**58
    header = np.array([1, 24 * n, 0, 10], "<u8").tobytes()
    data = (base64.b64encode(header) + base64.b64encode(zlib.compress(b"x" * 10)[:10])).decode()
    (tmp_path / "huge.vtp").write_text(
        '<VTKFile type="PolyData" header_type="UInt64" compressor="vtkZLibDataCompressor">\n'
        f'<PolyData><Piece NumberOfPoints="{n}"><Points>\n'
        f'<DataArray type="Float64" NumberOfComponents="3" format="binary">{data}</DataArray>\n'
        "</Points></Piece></PolyData></VTKFile>\n"
    )
    with pytest.raises(
        ReadError, match=r"huge\.vtp: frame 0, line 3: .* inflates to 10 bytes, not 6917529027641081856"
    ):
        open_trajectory(tmp_path / "huge.vtp")[0]


# -- fuzzing: legacy .vtk, XML .vtu (YADE's spheres files among them) and .vtp in each of
# their encodings, damaged at random 320 times per format from a fixed seed, each read in a
# child process with a time limit: every read gives a clean result or a ReadError (vtk's own
# XML readers segfaulted, hung or took gigabytes on such files).

FUZZ_TEXT = b'0123456789 .-+e\n<>="/_ xP'
#: the vtk writer settings of each XML encoding
ENCODINGS = {
    "ascii": lambda w: w.SetDataModeToAscii(),
    "inline": lambda w: (w.SetDataModeToBinary(), w.SetHeaderTypeToUInt64()),
    "appended": lambda w: None,
    "raw": lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff()),
    "raw-lzma": lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff(), w.SetCompressorTypeToLZMA()),
    "plain": lambda w: (w.SetDataModeToBinary(), w.SetCompressorTypeToNone()),
}


def written(path, writer, data, configure=lambda w: None):
    writer.SetFileName(str(path))
    writer.SetInputData(data)
    configure(writer)
    assert writer.Write() == 1
    return path.read_bytes()


def yade_spheres():
    """A grid like YADE's VTKRecorder spheres: a vertex per sphere, float64 point data."""
    rng = np.random.default_rng(2)
    grid = vtkUnstructuredGrid()
    points = vtkPoints()
    points.SetData(numpy_to_vtk(rng.random((6, 3)).astype(np.float32), deep=True))
    grid.SetPoints(points)
    for i in range(6):
        grid.InsertNextCell(VERTEX, 1, [i])
    for name, values in (
        ("radii", np.full(6, 0.004)),
        ("id", np.arange(6.0)),
        ("linVelVec", rng.random((6, 3))),
    ):
        array = numpy_to_vtk(values, deep=True)
        array.SetName(name)
        grid.GetPointData().AddArray(array)
    return grid


def test_fuzz_legacy_vtk(tmp_path, data_dir):
    mesh = sample_meshes()[1]
    bases = []
    for binary in (False, True):
        for writer, unstructured in ((vtkPolyDataWriter(), False), (vtkUnstructuredGridWriter(), True)):
            if binary:
                writer.SetFileTypeToBinary()
            data = written(tmp_path / "base.vtk", writer, vtk_dataset(*mesh, unstructured))
            bases.append((".vtk", data, BYTES if binary else FUZZ_TEXT))
    hopper = data_dir / "liggghts-hopper" / "mesh30000.vtk"
    bases += [(".vtk", hopper.read_bytes(), FUZZ_TEXT), (".vtk", LIGGGHTS_PARTICLES.encode(), FUZZ_TEXT)]
    fuzz_check("vtk", damaged_copies(tmp_path, "vtk", bases), read_every_frame, hopper)


def test_fuzz_xml_unstructured(tmp_path):
    mesh = vtk_dataset(*sample_meshes()[1], unstructured=True)
    bases = []
    for name, configure in ENCODINGS.items():
        data = written(tmp_path / f"{name}.vtu", vtkXMLUnstructuredGridWriter(), mesh, configure)
        bases.append((".vtu", data, FUZZ_TEXT if name == "ascii" else BYTES))
    for name in ("ascii", "appended"):
        good = tmp_path / "fz_spheres.100.vtu"
        data = written(good, vtkXMLUnstructuredGridWriter(), yade_spheres(), ENCODINGS[name])
        bases.append(("_spheres.100.vtu", data, FUZZ_TEXT if name == "ascii" else BYTES))
    fuzz_check("vtu", damaged_copies(tmp_path, "vtu", bases), read_every_frame, good)


def test_fuzz_xml_polydata(tmp_path):
    bases = []
    for name, configure in ENCODINGS.items():
        good = tmp_path / f"{name}.vtp"
        data = written(good, vtkXMLPolyDataWriter(), polydata_of_every_section(), configure)
        bases.append((".vtp", data, FUZZ_TEXT if name == "ascii" else BYTES))
    fuzz_check("vtp", damaged_copies(tmp_path, "vtp", bases), read_every_frame, good)
