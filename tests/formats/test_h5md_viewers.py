"""H5MD trajectories where users look at them: MDAnalysis reads the H5MD file (each row one
particle through the frames in which others leave and arrive), ParaView's XDMF reader (VTK's
vtkXdmfReader, through pyvista) and meshio read the XDMF sidecar; every value, time and count
equals PyGran's own read."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

from pygran_core import analysis, params, simulation
from pygran_core.errors import ReadError
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.formats import FormatConformance, particle_frames, require_reader

ROOT = Path(__file__).resolve().parents[2]
ARGS = (
    "id",
    "type",
    "x",
    "y",
    "z",
    "radius",
    *("vx", "vy", "vz", "fx", "fy", "fz", "omegax", "omegay", "omegaz"),
)
VECTORS = {
    "position": "x y z",
    "velocity": "vx vy vz",
    "force": "fx fy fz",
    "angular_velocity": "omegax omegay omegaz",
}


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """A native run whose particle count varies: five spheres on a floor, three of them thrown
    out through x+ (at 1, 1.5 and 2 m/s: they leave in three different frames), then three more
    are created."""
    folder = tmp_path_factory.mktemp("viewers")
    with simulation.DEM(
        engine="native",
        model=HertzMindlin,
        box=(0, 0.02, 0, 0.02, 0, 0.02),
        gravity=(9.81, 0, 0, -1),
        species=({"material": dict(params.organic), "radius": 1e-3},),
        output=str(folder / "out"),
        traj={"pfile": "traj.h5md", "freq": 100, "args": ARGS},
        progress=False,
        dt=1e-5,
        threads=1,
        seed=3,
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        for k in range(3):
            sim.createParticles(1, "single", 0.012, 0.004 + 0.005 * k, 0.0012, vel=(1.0 + 0.5 * k, 0, 0))
        sim.createParticles(1, "single", 0.01, 0.015, 0.003)
        sim.createParticles(1, "single", 0.005, 0.005, 0.0011, vel=(0.2, 0.1, 0))
        sim.engine.expect_outflow("x+")
        sim.run(800)
        for k in range(3):
            sim.createParticles(1, "single", 0.004, 0.004 + 0.005 * k, 0.004, vel=(0.1 * k, 0, 0))
        sim.run(400)
    return folder / "out" / "traj.h5md"


@pytest.fixture(scope="module")
def frames(run) -> list[Frame]:
    with open_trajectory(run) as trajectory:
        return list(trajectory)


def test_the_run_has_particles_leaving_and_arriving(run, frames):
    ids = [f.arrays["id"].tolist() for f in frames]
    assert ids[0] == [1, 2, 3, 4, 5] and ids[-1] == [4, 5, 6, 7, 8]
    assert [1, 2, 4, 5] in ids and [1, 4, 5] in ids  # the fastest leaves first
    assert len(frames) == 13 and [f.timestep for f in frames] == list(range(0, 1300, 100))
    assert any(np.abs(f.arrays["omegax"]).max() > 0 for f in frames)  # friction with the floor spins them
    system = analysis.System(Particles=str(run))  # what analysis reads: the same frames
    assert len(system) == len(frames)
    for k, frame in enumerate(frames):
        system.goto(k)
        np.testing.assert_array_equal(system.Particles.id, frame.arrays["id"])
        np.testing.assert_array_equal(system.Particles.x, frame.arrays["x"])


def _docs_block(marker: str) -> str:
    """The Python block of docs/formats.md that contains ``marker``."""
    text = (ROOT / "docs" / "formats.md").read_text()
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, re.S) if marker in b]
    assert len(blocks) == 1, f"docs/formats.md must show one block with {marker!r}"
    return blocks[0]


def test_mdanalysis_loads_it_with_the_call_of_the_guide(run, frames, monkeypatch):
    require_reader("MDAnalysis")
    from MDAnalysis import units
    from MDAnalysis.coordinates.H5MD import H5MDReader

    # the guide's call teaches MDAnalysis the metre; undo it after the test
    monkeypatch.setitem(units.lengthUnit_factor, "m", 1e-10)
    monkeypatch.setitem(H5MDReader._unit_translation["length"], "m", "m")
    monkeypatch.chdir(run.parent)  # where the guide's traj.h5md is
    namespace: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # MDAnalysis warns that the file has no topology
        exec(_docs_block("mda.Universe("), namespace)
    universe = namespace["u"]
    with h5py.File(run) as f:
        row_ids = f["particles/trajectory/id/value"][:]
    # row i is one particle through every frame; rows of absent particles are marked with -1
    assert universe.atoms.n_atoms == 8 and len(universe.trajectory) == len(frames)
    for row in range(8):
        held = set(row_ids[:, row][row_ids[:, row] >= 0].tolist())
        assert held == {row + 1}, (row, held)
    speed = units.get_conversion_factor("speed", "m/s", "Angstrom/ps")
    force = units.get_conversion_factor("force", "N", "kJ/(mol*Angstrom)")
    for k, ts in enumerate(universe.trajectory):
        frame = frames[k]
        assert ts.frame == k and ts.data["step"] == frame.timestep
        assert ts.time == pytest.approx(frame.time * 1e12, rel=1e-12)  # ps
        assert ts.data["trajectory/particle_number"] == len(frame.arrays["id"])
        rows = frame.arrays["id"] - 1
        absent = np.setdiff1d(np.arange(8), rows)
        for name, factor, got in (
            ("x y z", 1e10, ts.positions),
            ("vx vy vz", speed, ts.velocities),
            ("fx fy fz", force, ts.forces),
        ):
            want = np.column_stack([frame.arrays[c] for c in name.split()]) * factor
            np.testing.assert_allclose(got[rows], want, rtol=2e-7, atol=1e-30 * factor, err_msg=name)
            assert np.isnan(got[absent]).all()
        np.testing.assert_allclose(ts.dimensions[:3], 0.02 * 1e10, rtol=1e-7)


def test_an_h5md_file_mdanalysis_wrote_reads_in_si(tmp_path):
    """MDAnalysis writes angstrom, ps, angstrom/ps and kJ/(mol angstrom): PyGran reads metres,
    seconds, m/s and newtons."""
    require_reader("MDAnalysis")
    import MDAnalysis as mda
    from MDAnalysis.coordinates.memory import MemoryReader

    rng = np.random.default_rng(2)
    positions, velocities, forces = (rng.random((3, 4, 3)) * 10 for _ in range(3))
    universe = mda.Universe.empty(4, trajectory=False)
    box = np.array([[20.0, 20.0, 20.0, 90.0, 90.0, 90.0]] * 3)
    universe.load_new(
        positions, format=MemoryReader, velocities=velocities, forces=forces, dimensions=box, dt=2.0
    )
    universe.trajectory.units = {
        "time": "ps",
        "length": "Angstrom",
        "velocity": "Angstrom/ps",
        "force": "kJ/(mol*Angstrom)",
    }
    with mda.Writer(str(tmp_path / "mda.h5md"), n_atoms=4, velocities=True, forces=True) as writer:
        for _ in universe.trajectory:
            writer.write(universe)
    per_mole = 1e3 / 6.02214076e23 / 1e-10  # kJ/(mol angstrom) in N
    with open_trajectory(tmp_path / "mda.h5md") as trajectory:
        assert len(trajectory) == 3
        for k, frame in enumerate(trajectory):
            assert frame.timestep == k and frame.time == pytest.approx(2e-12 * k, rel=1e-15)
            np.testing.assert_array_equal(frame.box, [[0.0, 2e-9]] * 3)
            for columns, values, factor in (("x y z", positions, 1e-10), ("vx vy vz", velocities, 100.0)):
                got = np.column_stack([frame.arrays[c] for c in columns.split()])
                np.testing.assert_allclose(got, values[k] * factor, rtol=1e-7)  # float32 in the file
            got = np.column_stack([frame.arrays[c] for c in ("fx", "fy", "fz")])
            np.testing.assert_allclose(got, forces[k] * per_mole, rtol=1e-7)


def _check_sidecar_frame(frame: Frame, time: float, points, point_data) -> None:
    """One frame of the sidecar, as a reader gave it, against PyGran's read of the H5MD file."""
    assert time == frame.time
    n = len(frame.arrays["id"])
    assert points.shape == (n, 3)
    np.testing.assert_array_equal(points, np.column_stack([frame.arrays[c] for c in "xyz"]))
    for name in ("id", "type", "radius"):
        np.testing.assert_array_equal(np.ravel(point_data[name]), frame.arrays[name], err_msg=name)
    for name, columns in VECTORS.items():
        want = np.column_stack([frame.arrays[c] for c in columns.split()])
        np.testing.assert_array_equal(point_data[name], want, err_msg=name)


#: Reads an XDMF file with pyvista (VTK's vtkXdmfReader) in a process of its own, as ParaView
#: does, and saves every frame's time, points, vertex count and point data to an .npz: in the
#: test's process pygran-liggghts has loaded Debian's VTK libraries, which crash pip's VTK.
PYVISTA_DUMP = """
import sys
import numpy as np
import pyvista

reader = pyvista.get_reader(sys.argv[1])
assert isinstance(reader, pyvista.XdmfReader), type(reader)
saved = {"times": np.array(reader.time_values)}
for k, time in enumerate(reader.time_values):
    reader.set_active_time_value(time)
    mesh = reader.read()
    saved[f"{k}/cells"] = np.array(mesh.n_cells)
    saved[f"{k}/points"] = np.asarray(mesh.points)
    for name in mesh.point_data.keys():
        saved[f"{k}/{name}"] = np.asarray(mesh.point_data[name])
np.savez(sys.argv[2], **saved)
"""


def _read_with_pyvista(xdmf: Path) -> dict[str, np.ndarray]:
    require_reader("pyvista")
    out = xdmf.with_suffix(".pyvista.npz")
    done = subprocess.run(
        [sys.executable, "-c", PYVISTA_DUMP, str(xdmf), str(out)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    with np.load(out) as saved:
        return dict(saved)


def test_paraview_xdmf_reader_opens_the_sidecar(run, frames):
    saved = _read_with_pyvista(run.with_suffix(".xdmf"))
    assert saved["times"].tolist() == [f.time for f in frames]
    for k, frame in enumerate(frames):
        data = {name.split("/", 1)[1]: value for name, value in saved.items() if name.startswith(f"{k}/")}
        assert data["cells"] == len(frame.arrays["id"])  # a vertex per particle
        _check_sidecar_frame(frame, float(saved["times"][k]), data["points"], data)


def test_meshio_reads_the_sidecar(run, frames):
    require_reader("meshio")
    import meshio

    with meshio.xdmf.TimeSeriesReader(run.with_suffix(".xdmf")) as reader:
        points, cells = reader.read_points_cells()  # meshio takes the first frame's points
        assert cells[0].type == "vertex" and len(cells[0].data) == len(frames[0].arrays["id"])
        assert reader.num_steps == len(frames)
        for k, frame in enumerate(frames):
            time, point_data, _ = reader.read_data(k)
            _check_sidecar_frame(frame, time, point_data["position"], point_data)


def test_sidecar_of_awkward_frames(tmp_path):
    """Frames without a time (the step stands in), an empty frame, extreme values, a column
    that is no LIGGGHTS keyword: VTK reads them all."""
    frames = particle_frames()
    with open_writer(tmp_path / "awkward.h5md") as out:
        for frame in frames:
            out.write_frame(frame)
    saved = _read_with_pyvista(tmp_path / "awkward.xdmf")
    assert saved["times"].tolist() == [float(f.timestep) for f in frames]
    for k, frame in enumerate(frames):
        n = len(frame.arrays["id"])
        assert saved[f"{k}/points"].shape == (n, 3)
        if n:
            np.testing.assert_array_equal(saved[f"{k}/c_stress[2]"], frame.arrays["c_stress[2]"])
            np.testing.assert_array_equal(saved[f"{k}/id"], frame.arrays["id"])
            np.testing.assert_array_equal(saved[f"{k}/points"][:, 0], frame.arrays["x"])


def test_no_sidecar_when_asked_or_without_positions(tmp_path):
    frame = Frame({"id": np.array([1, 2]), "radius": np.array([1e-3, 2e-3])}, timestep=0)
    with open_writer(tmp_path / "radii.h5md") as out:
        out.write_frame(frame)
    with open_writer(tmp_path / "plain.h5md", xdmf=False) as out:
        out.write_frame(particle_frames()[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.h5md", "radii.h5md"]


def test_pygran_reads_its_sidecar_back(run, frames):
    with open_trajectory(run.with_suffix(".xdmf")) as sidecar:
        assert len(sidecar) == len(frames)
        for got, want in zip(sidecar, frames):
            assert (got.timestep, got.time) == (want.timestep, want.time)
            assert sorted(got.arrays) == sorted(want.arrays)
            for name, values in want.arrays.items():
                np.testing.assert_array_equal(got.arrays[name], values, err_msg=name)


@pytest.mark.parametrize("elsewhere", ["/etc/passwd", "../traj.xdmf.h5", "sub/traj.xdmf.h5"])
def test_a_sidecar_naming_data_elsewhere_is_refused(run, tmp_path, elsewhere):
    text = run.with_suffix(".xdmf").read_text().replace("traj.xdmf.h5:", f"{elsewhere}:")
    (tmp_path / "moved.xdmf").write_text(text)
    with pytest.raises(ReadError, match=r"moved\.xdmf: data in .*: only a file next to the XDMF file"):
        open_trajectory(tmp_path / "moved.xdmf")[0]


class TestXdmfSidecar(FormatConformance):
    """PyGran reads its sidecars back like any format (written through the H5MD writer)."""

    reader = "xdmf"
    suffix = ".xdmf"
    physical_checks = True

    def make_sample(self, tmp_path):
        frames = particle_frames()
        with open_writer(tmp_path / "sample.h5md") as out:
            for frame in frames:
                out.write_frame(frame)
        return tmp_path / "sample.xdmf", frames

    def make_insane(self, tmp_path, name, frames):
        """Sane frames through the writer (which refuses insane ones), then the insane values
        put in place in the sidecar: its data, and its step information."""
        folder = tmp_path / name.replace(" ", "-")
        folder.mkdir()
        path, sane = self.make_sample(folder)
        text = path.read_text()
        with h5py.File(folder / "sample.xdmf.h5", "a") as f:
            for k, (bad, good) in enumerate(zip(frames, sane)):
                if bad.timestep != good.timestep:
                    text = text.replace(
                        f'Name="step" Value="{good.timestep}"', f'Name="step" Value="{bad.timestep}"'
                    )
                for j, column in enumerate(good.arrays):  # x y z are one group: radius is group 3
                    if column in ("id", "radius"):
                        f[f"frames/{k}/{j - 2 * (column == 'radius')}"][...] = bad.arrays[column]
        path.write_text(text)
        return path


VIEWER = "import h5py, sys, time; f = h5py.File(sys.argv[1], 'r'); print('open', flush=True); time.sleep(60)"


def test_a_viewer_holding_the_sidecar_open_does_not_stop_the_writer(tmp_path):
    """ParaView keeps the sidecar's data open while the simulation runs: HDF5's own file lock
    would refuse the writer's next frame; the writer holds its own lock instead."""
    frames = particle_frames()
    out = open_writer(tmp_path / "live.h5md")
    out.write_frame(frames[0])
    viewer = subprocess.Popen(
        [sys.executable, "-c", VIEWER, str(tmp_path / "live.xdmf.h5")], stdout=subprocess.PIPE, text=True
    )
    try:
        assert viewer.stdout.readline().strip() == "open"
        for frame in frames[1:]:
            out.write_frame(frame)
        out.close()
    finally:
        viewer.kill()
        viewer.wait()
        viewer.stdout.close()
    with open_trajectory(tmp_path / "live.xdmf") as sidecar:
        assert [len(f.arrays["id"]) for f in sidecar] == [len(f.arrays["id"]) for f in frames]


def test_a_reader_holding_an_old_trajectory_open_does_not_stop_a_new_run(tmp_path):
    path = tmp_path / "traj.h5md"
    frames = particle_frames()
    with open_writer(path) as out:
        out.write_frame(frames[0])
    reader = subprocess.Popen([sys.executable, "-c", VIEWER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert reader.stdout.readline().strip() == "open"
        with open_writer(path) as out:  # the next run writes the file again
            for frame in frames[2:]:
                out.write_frame(frame)
    finally:
        reader.kill()
        reader.wait()
        reader.stdout.close()
    assert [f.timestep for f in open_trajectory(path)] == [f.timestep for f in frames[2:]]
