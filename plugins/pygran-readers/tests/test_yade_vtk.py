"""YADE VTKRecorder output made by the installed YADE (``yade_vtkrecorder.py``): spheres files
as particles (the conformance suite and ``analysis.System``), facets and boxes as meshes, and
damaged files. YADE is required as the YADE engine's tests require it: a skip without it,
a failure under ``CI=true``."""

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import VTK_VERTEX, vtkUnstructuredGrid
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader, vtkXMLUnstructuredGridWriter

from pygran_core import analysis, registry
from pygran_core.errors import EngineError, ReadError
from pygran_core.io import Frame, open_trajectory
from pygran_core.testing.formats import FormatConformance
from pygran_core.testing.solvers import require_solver

SCRIPT = Path(__file__).with_name("yade_vtkrecorder.py")
ITERATIONS = (0, 1000, 2000, 3000)
SPHERES = (0, 12, 24, 18)


def locate_yade() -> str:
    """The YADE launcher as the YADE engine finds it: ``$PYGRAN_YADE``, else ``yade`` on PATH."""
    found = os.environ.get("PYGRAN_YADE") or shutil.which("yade")
    if found is None:
        raise EngineError("YADE is not installed (no `yade` on PATH): apt-get install -y yade")
    return found


def run_yade(tmp_path_factory, *mode: str) -> Path:
    launcher = require_solver(locate_yade)
    out = tmp_path_factory.mktemp("yade")
    run = subprocess.run(
        [launcher, "-n", "-x", "-j", "1", str(SCRIPT), str(out), *mode],
        capture_output=True,
        text=True,
        timeout=120,
    )
    made = sorted(p.name for p in out.glob("expected.*.npz"))
    assert run.returncode == 0 and len(made) == len(ITERATIONS), (
        made,
        run.stdout[-3000:],
        run.stderr[-3000:],
    )
    return out


@pytest.fixture(scope="session")
def yade_binary(tmp_path_factory) -> Path:
    return run_yade(tmp_path_factory)


@pytest.fixture(scope="session")
def yade_ascii(tmp_path_factory) -> Path:
    return run_yade(tmp_path_factory, "ascii")


def expected_frame(out: Path, iteration: int) -> Frame:
    """The frame the spheres file of ``iteration`` must give, from the state YADE saved."""
    state = np.load(out / f"expected.{iteration}.npz")
    arrays = {"id": state["id"], "type": state["material"] + 1}
    arrays.update({axis: state["position"][:, j] for j, axis in enumerate("xyz")})
    arrays["radius"] = state["radius"]
    for prefix, key in (("v", "velocity"), ("omega", "omega")):
        arrays.update({f"{prefix}{axis}": state[key][:, j] for j, axis in enumerate("xyz")})
    arrays.update({"mask": state["mask"], "clumpId": state["clump"]})
    arrays.update({f"color{axis}": state["color"][:, j] for j, axis in enumerate("xyz")})
    return Frame(arrays, timestep=iteration)


class TestYadeSpheres(FormatConformance):
    reader = "yade-vtk"
    suffix = ".vtu"
    exact = False  # VTKRecorder writes the points as float32
    physical_checks = True
    steps_from_file_names = True

    @pytest.fixture(autouse=True)
    def _output(self, yade_binary):
        self.output = yade_binary

    def make_sample(self, tmp_path):
        for path in self.output.glob("yade_spheres.*.vtu"):
            shutil.copy(path, tmp_path)
        return str(tmp_path / "yade_spheres.*.vtu"), [expected_frame(self.output, i) for i in ITERATIONS]

    def bad_files(self, tmp_path):
        pattern, _ = self.make_sample(tmp_path)
        last = tmp_path / "yade_spheres.3000.vtu"
        last.write_bytes(last.read_bytes()[:2000])
        return [*super().bad_files(tmp_path), (pattern, 3)]

    def make_insane(self, tmp_path, name, frames):
        """VTKRecorder's layout (one vertex per sphere, point data ``id`` and ``radii``) holding
        ``frames``, one file per frame named by its step."""
        folder = tmp_path / name.replace(" ", "-")
        folder.mkdir()
        for frame in frames:
            write_spheres(folder / f"yade_spheres.{frame.timestep}.vtu", frame.arrays)
        return str(folder / "yade_spheres.*.vtu")


def write_spheres(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """A spheres file as YADE's VTKRecorder lays it out, written with VTK."""
    grid = vtkUnstructuredGrid()
    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.column_stack([arrays[a] for a in "xyz"]), deep=True))
    grid.SetPoints(points)
    for i in range(len(arrays["x"])):
        grid.InsertNextCell(VTK_VERTEX, 1, [i])
    for name, values in (("id", arrays["id"].astype(np.int32)), ("radii", arrays["radius"])):
        data = numpy_to_vtk(values, deep=True)
        data.SetName(name)
        grid.GetPointData().AddArray(data)
    writer = vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(grid)
    assert writer.Write() == 1


class TestYadeSpheresAscii(TestYadeSpheres):
    @pytest.fixture(autouse=True)
    def _output(self, yade_ascii):
        self.output = yade_ascii


def test_system_reads_the_spheres_and_walls(yade_binary):
    system = analysis.System(
        Particles=str(yade_binary / "yade_spheres.*.vtu"), Mesh=str(yade_binary / "yade_facets.*.vtu")
    )
    assert len(system) == len(ITERATIONS)
    for frame, (iteration, count) in enumerate(zip(ITERATIONS, SPHERES)):
        system.goto(frame)
        assert system.Particles.timestep == iteration and len(system.Particles) == count
        assert system.Mesh.timestep == iteration and system.Mesh.nCells() == 10  # facetBox: 5 walls
    system.goto(-1)
    particles, want = system.Particles, np.load(yade_binary / "expected.3000.npz")
    np.testing.assert_array_equal(particles.id, want["id"])
    np.testing.assert_array_equal(particles.radius, want["radius"])
    np.testing.assert_array_equal(particles.type, want["material"] + 1)
    np.testing.assert_allclose(particles.positions, want["position"], rtol=1e-6)
    np.testing.assert_array_equal(particles.omegay, want["omega"][:, 1])
    small = particles[particles.radius < particles.radius.mean()]
    assert len(small) == np.count_nonzero(want["radius"] < 0.005) > 0
    assert set(small.radius) == {0.004}
    weights = want["radius"] ** 3
    com = weights @ want["position"] / weights.sum()
    np.testing.assert_allclose(particles.computeCOM(), com, rtol=0, atol=1e-8)  # float32 positions
    np.testing.assert_allclose(
        particles.computeMass(density=2500.0).sum(), 2500.0 * 4 / 3 * np.pi * weights.sum(), rtol=1e-12
    )


def test_boxes_are_meshes_of_quads(yade_binary):
    boxes = open_trajectory(str(yade_binary / "yade_boxes.*.vtu"))
    assert [frame.timestep for frame in boxes] == list(ITERATIONS)
    frame = boxes[-1]
    assert frame.attrs["kind"] == "mesh" and frame.arrays["cells"].shape == (6, 4)
    assert (frame.arrays["cell_types"] == 9).all()
    assert (
        frame.arrays["points"][:, 2].min() == pytest.approx(-0.02) and frame.arrays["points"][:, 2].max() == 0
    )


def test_registry_picks_the_yade_reader_only_for_yade_files(yade_binary, tmp_path):
    for name in ("yade_spheres.0.vtu", "yade_spheres.3000.vtu", "yade_facets.1000.vtu", "yade_boxes.0.vtu"):
        assert registry.reader_for(yade_binary / name).name == "yade-vtk", name
    renamed = tmp_path / "run.vtu"  # a spheres file under another name: known by its radii
    shutil.copy(yade_binary / "yade_spheres.1000.vtu", renamed)
    assert registry.reader_for(renamed).name == "yade-vtk"
    assert open_trajectory(renamed)[0].timestep is None
    plain = tmp_path / "facets.vtu"  # a VTK file that is not YADE's: the generic reader
    shutil.copy(yade_binary / "yade_facets.1000.vtu", plain)
    assert registry.reader_for(plain).name == "vtk"
    # the generic reader reads YADE's empty, compressed spheres file too
    assert open_trajectory(yade_binary / "yade_spheres.0.vtu", format="vtk")[0].arrays["x"].shape == (0,)


def test_a_glob_of_several_recorders_names_each_pattern(yade_binary):
    with pytest.raises(ReadError) as info:
        analysis.System(Particles=str(yade_binary / "yade_*.vtu"))
    message = str(info.value)
    for kind in ("spheres", "facets", "boxes"):
        assert f"{kind}: '{yade_binary / f'yade_{kind}.*.vtu'}'" in message


def _rewrite(source: Path, target: Path, change) -> None:
    """``source`` read by vtk, changed by ``change(grid)``, written to ``target`` (ASCII XML)."""
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(source))
    reader.Update()
    grid = reader.GetOutput()
    change(grid)
    writer = vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(target))
    writer.SetInputData(grid)
    writer.SetDataModeToAscii()
    assert writer.Write() == 1


def test_damaged_spheres_files_name_the_file_and_the_problem(yade_binary, tmp_path):
    good = yade_binary / "yade_spheres.2000.vtu"
    shutil.copy(good, tmp_path / "a_spheres.1.vtu")

    def half_id(grid):
        ids = numpy_to_vtk(vtk_to_numpy(grid.GetPointData().GetArray("id")) + 0.5, deep=True)
        ids.SetName("id")
        grid.GetPointData().AddArray(ids)

    _rewrite(good, tmp_path / "a_spheres.2.vtu", half_id)
    _rewrite(good, tmp_path / "a_spheres.3.vtu", lambda grid: grid.GetPointData().RemoveArray("radii"))
    shutil.copy(yade_binary / "yade_facets.0.vtu", tmp_path / "a_spheres.4.vtu")
    text = good.read_bytes()
    (tmp_path / "a_spheres.5.vtu").write_bytes(text.replace(b'NumberOfPoints="24"', b'NumberOfPoints="25"'))
    trajectory = open_trajectory(str(tmp_path / "a_spheres.*.vtu"))
    assert len(trajectory[0].arrays["x"]) == 24
    problems = {
        2: r"a_spheres\.2\.vtu: frame 1: point data 'id' must hold whole numbers, found \d+\.5",
        3: r"a_spheres\.3\.vtu: frame 2: not a YADE spheres file: no 'radii' point data",
        4: r"a_spheres\.4\.vtu: frame 3: not a YADE spheres file: expected one vertex cell .* found 10 cells "
        "of types 5",
        5: r"a_spheres\.5\.vtu: frame 4, line 20: array 'Points': its compression header says 288 bytes; "
        "25 tuples of 3 Float32 need 300",
    }
    for number, message in problems.items():
        with pytest.raises(ReadError, match=message):
            trajectory[number - 1]
