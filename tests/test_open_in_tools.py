"""PyGran's outputs opened where users look at them: OVITO, MDAnalysis and pyvista (ParaView's
VTK readers), as a user opens them, every value compared with PyGran's own read.

One small native run, written twice (its particles as a dump per frame, then as a ``.vtp``
series): 30 particles settle on a floor between four walls under a static mesh ramp, one more
is created, the floor is removed and most fall out through the bottom, while the ramp rises
at 5 cm/s. So the particle count changes from frame to frame, the ramp's file is written once
while it stands and once per frame while it moves, and there are pair and wall contacts.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from pygran_core import analysis, cli, params, simulation
from pygran_core.apps.demo import write_stl
from pygran_core.formats.contacts import OVITO_COLUMNS
from pygran_core.io import open_trajectory
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.solvers import in_ci

DT = 1e-5
FREQ = 1000
STEPS = list(range(0, 11001, FREQ))
RAMP_MOVES_AT = 8000  # the ramp rises from here on
ARGS = ("id", "type", "x", "y", "z", "radius", "mass", "density", "vx", "vy", "vz", "fx", "fy", "fz")
ARGS += ("omegax", "omegay", "omegaz")
F32 = float(np.finfo(np.float32).eps)


def tool(name: str) -> ModuleType:
    """The reader ``name``; missing, a failure under CI, else a skip naming the fix."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        message = f"{name} is not installed ({exc}): pip install -e '.[test]'"
        if in_ci():
            pytest.fail(f"CI=true and {message}", pytrace=False)
        pytest.skip(message)


#: What ParaView's stand-in does with a .pvd series, in a process of its own (pyvista's VTK
#: must not share a process with libliggghts, which PyGran's plugin discovery loads): every
#: time step's points, polygons and point data, saved as ``k/points``, ``k/faces``, ``k/<name>``.
PARAVIEW = """
import sys, numpy as np, pyvista as pv
reader = pv.get_reader(sys.argv[1])
out = {"time": np.array(reader.time_values)}
for k, t in enumerate(reader.time_values):
    reader.set_active_time_value(t)
    mesh = reader.read()[0]
    out[f"{k}/points"] = mesh.points
    polygons = isinstance(mesh, pv.PolyData) and mesh.n_faces
    out[f"{k}/faces"] = mesh.regular_faces if polygons else np.zeros((0, 3), int)
    out.update({f"{k}/{name}": mesh.point_data[name] for name in mesh.point_data.keys()})
np.savez(sys.argv[2], **out)
"""


def paraview(series: Path, tmp_path: Path) -> tuple[list[float], list[dict[str, np.ndarray]]]:
    """The times and the datasets pyvista reads from the series ``series`` (a ``.pvd``)."""
    if importlib.util.find_spec("pyvista") is None:
        tool("pyvista")  # fails under CI, else skips
    saved = tmp_path / f"{series.stem}-paraview.npz"
    subprocess.run([sys.executable, "-c", PARAVIEW, str(series), str(saved)], check=True, timeout=300)
    with np.load(saved) as data:
        times = data["time"].tolist()
        steps: list[dict[str, np.ndarray]] = [{} for _ in times]
        for key in data.files:
            if key != "time":
                index, name = key.split("/", 1)
                steps[int(index)][name] = data[key]
    return times, steps


def simulate(out: Path, pfile: str) -> Path:
    """The run described above, with particle frames written to ``pfile``."""
    ramp = np.array(
        [
            [[0.0, 0.0, 0.014], [0.012, 0.0, 0.018], [0.012, 0.012, 0.018]],
            [[0.0, 0.0, 0.014], [0.012, 0.012, 0.018], [0.0, 0.012, 0.014]],
        ]
    )
    stl = write_stl(out / "ramp.stl", ramp, "ramp")
    settle = dict(params.organic, coefficientRestitution=0.3)  # a bed that comes to rest in 0.06 s
    with simulation.DEM(
        engine="native",
        model=HertzMindlin,
        box=(0.0, 0.012, 0.0, 0.012, 0.0, 0.02),
        boundary=("f", "f", "f"),
        gravity=(9.81, 0, 0, -1),
        species=({"material": settle, "radius": 1e-3},),
        mesh={"ramp": {"file": str(stl), "material": params.organic}},
        output=str(out),
        progress=False,
        dt=DT,
        seed=7,
        threads=1,
        traj={"pfile": pfile, "mfile": "walls*.vtk", "cfile": "contacts.dump", "freq": FREQ, "args": ARGS},
    ) as sim:
        sim.setupWall(wtype="mesh", species=1, mesh="ramp")
        for plane in ("xplane", "yplane"):
            for peq in (0.0, 0.012):
                sim.setupWall(species=1, plane=plane, peq=peq)
        floor = sim.setupWall(species=1, plane="zplane", peq=0.002)
        sim.insert(species=1, value=30, region=("block", 0.001, 0.011, 0.001, 0.011, 0.003, 0.012))
        sim.run(6000)
        sim.createParticles(1, "single", 0.006, 0.006, 0.013)
        sim.run(2000)
        sim.remove(floor)
        sim.expect_outflow("z-")
        sim.moveMesh("ramp", linear=(0.0, 0.0, 0.05))
        sim.run(3000)
    return out


def simulated(out: Path, pfile: str) -> Path:
    """:func:`simulate` in a process of its own, as a user's script runs; the viewers open its
    files in this one. (In one process, VTK segfaults on import after a native simulation.)"""
    subprocess.run([sys.executable, __file__, str(out), pfile], check=True, timeout=300)
    return out


@pytest.fixture(scope="module")
def dumps(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory.mktemp("dumps"), "traj*.dump")


@pytest.fixture(scope="module")
def series(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory.mktemp("series"), "particles*.vtp")


def ours(pattern: Path) -> list:
    with open_trajectory(pattern) as trajectory:
        return list(trajectory)


def test_the_run_has_inserted_and_leaving_particles_and_contacts(dumps):
    frames = ours(dumps / "traj*.dump")
    counts = [len(f.arrays["id"]) for f in frames]
    assert [f.timestep for f in frames] == STEPS
    assert counts[0] == 30 and max(counts) == 31 and 0 < counts[-1] < 10
    contacts = ours(dumps / "contacts.dump")
    assert sum(int(np.count_nonzero(c.arrays["id2"] > 0)) for c in contacts) > 10
    assert sum(int(np.count_nonzero(c.arrays["id2"] < 0)) for c in contacts) > 10


def test_dumps_are_laid_out_as_liggghts_writes_them_with_mass_and_density(dumps):
    """No ``ITEM: TIME`` block; each frame's time is in the log; mass and density columns, so
    analysis needs no density= for the mass."""
    for step in STEPS:
        text = (dumps / f"traj{step}.dump").read_text()
        assert text.startswith(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n")
        assert "ITEM: TIME\n" not in text
    log = (dumps / "pygran.log").read_text()
    for step in STEPS:
        assert f"trajectory frame at step {step}, time {step * DT!r} s" in log
    system = analysis.System(Particles=str(dumps / "traj*.dump"))
    system.goto(3)
    particles = system.Particles
    np.testing.assert_array_equal(particles.density, 1000.0)
    expected = 1000.0 * 4 / 3 * math.pi * particles.radius**3
    np.testing.assert_allclose(particles.computeMass(), expected, rtol=1e-15)


def test_mdanalysis_reads_the_dumps(dumps):
    mda = tool("MDAnalysis")
    for frame in ours(dumps / "traj*.dump"):
        path = dumps / f"traj{frame.timestep}.dump"
        universe = mda.Universe(str(path), format="LAMMPSDUMP", dt=DT * 1e12)  # MDAnalysis counts in ps
        got = universe.atoms
        order = np.argsort(got.ids)
        arrays = frame.arrays
        assert len(got) == len(arrays["id"])
        assert universe.trajectory.ts.data["step"] == frame.timestep
        assert universe.trajectory.ts.time * 1e-12 == pytest.approx(frame.timestep * DT, rel=1e-12)
        np.testing.assert_array_equal(got.ids[order], np.sort(arrays["id"]))
        mine = np.argsort(arrays["id"])
        xyz = np.column_stack([arrays[a] for a in "xyz"])[mine]
        np.testing.assert_allclose(got.positions[order], xyz, rtol=F32, atol=0)  # float32 in MDAnalysis
        np.testing.assert_allclose(got.masses[order], arrays["mass"][mine], rtol=F32, atol=0)


def test_ovito_reads_the_dumps(dumps):
    ovito_io = tool("ovito.io")
    frames = ours(dumps / "traj*.dump")
    pipeline = ovito_io.import_file(str(dumps / "traj*.dump"))
    assert pipeline.source.num_frames == len(frames)
    for index, frame in enumerate(frames):
        data = pipeline.compute(index)
        got, arrays = data.particles, frame.arrays
        assert data.attributes["Timestep"] == frame.timestep
        assert got.count == len(arrays["id"])
        np.testing.assert_array_equal(got["Particle Identifier"][...], arrays["id"])
        # OVITO's own number parser may miss the nearest double by an ulp
        for name, want in (
            ("Position", np.column_stack([arrays[a] for a in "xyz"])),
            ("Velocity", np.column_stack([arrays[f"v{a}"] for a in "xyz"])),
            ("Angular Velocity", np.column_stack([arrays[f"omega{a}"] for a in "xyz"])),
            ("Force", np.column_stack([arrays[f"f{a}"] for a in "xyz"])),
            ("Mass", arrays["mass"]),
            ("density", arrays["density"]),
        ):
            np.testing.assert_allclose(got[name][...], want, rtol=1e-12, atol=0, err_msg=name)
        np.testing.assert_allclose(got["Radius"][...], arrays["radius"], rtol=F32, atol=0)  # float32


def test_ovito_loads_the_pair_contacts_as_bonds(dumps):
    """The pair file holds particle pairs only; with :data:`OVITO_COLUMNS` every contact is a
    bond between the right particles with its force, point and branch vector."""
    ovito_io, modifiers = tool("ovito.io"), tool("ovito.modifiers")
    pipeline = ovito_io.import_file(str(dumps / "traj*.dump"))
    bonds = modifiers.LoadTrajectoryModifier()
    bonds.source.load(str(dumps / "contacts.dump"), columns=list(OVITO_COLUMNS))
    pipeline.modifiers.append(bonds)
    contacts = ours(dumps / "contacts.dump")
    seen = 0
    for index, records in enumerate(contacts):
        pairs = records.arrays["id2"] > 0
        data = pipeline.compute(index)
        got = data.particles.bonds
        assert (got.count if got is not None else 0) == np.count_nonzero(pairs)
        if not pairs.any():
            continue
        seen += int(pairs.sum())
        ids = data.particles["Particle Identifier"][...]
        np.testing.assert_array_equal(
            ids[got.topology[...]], np.column_stack([records.arrays["id1"], records.arrays["id2"]])[pairs]
        )
        for name, columns in (("Force", "fx fy fz"), ("Contact Point", "cx cy cz"), ("Branch", "bx by bz")):
            want = np.column_stack([records.arrays[c][pairs] for c in columns.split()])
            np.testing.assert_allclose(
                got[name][...], want, rtol=1e-12, atol=0, err_msg=name
            )  # OVITO's parser
    assert seen > 10


def test_walls_index_gives_paraview_the_time_and_the_geometry(dumps, tmp_path):
    """walls.pvd: a frame per particle frame at its simulated time; the ramp's file written
    once while it stands, then once per frame while it moves; its geometry the STL's."""
    names = sorted(p.name for p in dumps.glob("walls*.vtk"))
    assert names == sorted(f"walls{s}.vtk" for s in [0, *range(RAMP_MOVES_AT + FREQ, STEPS[-1] + 1, FREQ)])
    times, meshes = paraview(dumps / "walls.pvd", tmp_path)
    walls = ours(dumps / "walls.pvd")
    assert times == [step * DT for step in STEPS] == [f.time for f in walls]
    assert [f.timestep for f in walls] == STEPS
    stl = ours(dumps / "ramp.stl")[0].arrays
    corners = stl["points"][stl["cells"]]  # (triangles, 3, 3)
    for step, frame, mesh in zip(STEPS, walls, meshes):
        np.testing.assert_array_equal(mesh["points"], frame.arrays["points"])
        np.testing.assert_array_equal(mesh["faces"], frame.arrays["cells"])
        rise = 0.05 * max(step - RAMP_MOVES_AT, 0) * DT
        np.testing.assert_allclose(mesh["points"][mesh["faces"]], corners + [0, 0, rise], rtol=0, atol=1e-15)


def test_ovito_opens_the_walls_with_their_time(dumps):
    ovito_io, ovito_data = tool("ovito.io"), tool("ovito.data")
    pipeline = ovito_io.import_file(str(dumps / "walls.pvd"))
    walls = ours(dumps / "walls.pvd")
    assert pipeline.source.num_frames == len(walls)
    for index, frame in enumerate(walls):
        data = pipeline.compute(index)
        assert data.attributes["Time"] == frame.time
        (mesh,) = [o for o in data.objects if isinstance(o, ovito_data.TriangleMesh)]
        np.testing.assert_array_equal(mesh.get_vertices(), frame.arrays["points"])
        np.testing.assert_array_equal(mesh.get_faces(), frame.arrays["cells"])


def test_particle_series_opens_in_paraview_and_ovito_with_time(dumps, series, tmp_path):
    """particles.pvd (the .vtp series): pyvista and OVITO give each frame's time, count and
    values as PyGran reads them; the run is the dump run's, value for value."""
    ovito_io = tool("ovito.io")
    frames = ours(series / "particles.pvd")
    assert [f.timestep for f in frames] == STEPS and [f.time for f in frames] == [s * DT for s in STEPS]
    for mine, dumped in zip(frames, ours(dumps / "traj*.dump")):
        for name, values in dumped.arrays.items():
            np.testing.assert_array_equal(mine.arrays[name], values, err_msg=name)
    times, datasets = paraview(series / "particles.pvd", tmp_path)
    assert times == [f.time for f in frames]
    pipeline = ovito_io.import_file(str(series / "particles.pvd"))
    assert pipeline.source.num_frames == len(frames)
    for index, frame in enumerate(frames):
        arrays = frame.arrays
        xyz = np.column_stack([arrays[a] for a in "xyz"])
        points = datasets[index]
        assert len(points["points"]) == len(arrays["id"])
        np.testing.assert_array_equal(points["points"], xyz)
        for name in ("id", "type", "radius", "mass", "density"):
            np.testing.assert_array_equal(points[name], arrays[name], err_msg=name)
        for name in ("v", "f", "omega"):
            want = np.column_stack([arrays[f"{name}{a}"] for a in "xyz"])
            np.testing.assert_array_equal(points[name], want, err_msg=name)
        data = pipeline.compute(index)
        got = data.particles
        assert data.attributes["Time"] == frame.time and got.count == len(arrays["id"])
        np.testing.assert_array_equal(got["Particle Identifier"][...], arrays["id"])
        np.testing.assert_array_equal(got["Position"][...], xyz)
        np.testing.assert_array_equal(got["Mass"][...], arrays["mass"])
        np.testing.assert_array_equal(got["Velocity"][...], np.column_stack([arrays[f"v{a}"] for a in "xyz"]))
        np.testing.assert_allclose(got["Radius"][...], arrays["radius"], rtol=F32, atol=0)  # float32


@pytest.mark.parametrize(
    ("target", "reread"),
    [
        ("out.dump", "out.dump"),
        ("out*.dump", "out*.dump"),
        ("out.h5", "out.h5"),
        ("out.xdmf", "out.h5"),  # H5MD with its XDMF sidecar
        ("out*.vtk", "out.pvd"),
        ("out*.vtp", "out.pvd"),
        ("out*.vtu", "out.pvd"),
        ("out.pvd", "out.pvd"),
    ],
)
def test_convert_writes_every_format(dumps, tmp_path, target, reread):
    """``pygran convert`` from the dumps to each writer's format; read back, every frame's
    step, count and values are the dumps' (and its time step x dt, given --dt)."""
    assert cli.main(["convert", str(dumps / "traj*.dump"), str(tmp_path / target), "--dt", str(DT)]) == 0
    frames = ours(dumps / "traj*.dump")
    back = ours(tmp_path / reread)
    assert [f.timestep for f in back] == STEPS
    if not target.endswith(".dump"):  # a dump keeps no time unless asked (--option time=true)
        assert [f.time for f in back] == [step * DT for step in STEPS]
    for mine, dumped in zip(back, frames):
        assert len(mine.arrays["x"]) == len(dumped.arrays["id"])
        order, want = np.argsort(mine.arrays["id"]), np.argsort(dumped.arrays["id"])
        for name, values in dumped.arrays.items():
            np.testing.assert_array_equal(mine.arrays[name][order], values[want], err_msg=name)
    if target == "out.xdmf":
        assert (tmp_path / "out.xdmf").is_file()
    if target in ("out*.vtk", "out*.vtu"):  # the formats no other test opens in ParaView
        times, datasets = paraview(tmp_path / reread, tmp_path)
        assert times == [step * DT for step in STEPS]
        for frame, points in zip(frames, datasets):
            np.testing.assert_array_equal(points["id"], frame.arrays["id"])
            np.testing.assert_array_equal(points["points"], np.column_stack([frame.arrays[a] for a in "xyz"]))
            np.testing.assert_array_equal(
                points["v"], np.column_stack([frame.arrays[f"v{a}"] for a in "xyz"])
            )


def test_convert_a_mesh_and_a_series_back_to_a_dump(dumps, tmp_path):
    assert cli.main(["convert", str(dumps / "ramp.stl"), str(tmp_path / "ramp.pvd")]) == 0
    (stl,) = ours(dumps / "ramp.stl")
    (mesh,) = ours(tmp_path / "ramp.pvd")
    np.testing.assert_array_equal(mesh.arrays["points"], stl.arrays["points"])
    np.testing.assert_array_equal(mesh.arrays["cells"], stl.arrays["cells"])
    assert cli.main(["convert", str(dumps / "walls.pvd"), str(tmp_path / "walls*.vtu")]) == 0
    assert [f.time for f in ours(tmp_path / "walls.pvd")] == [step * DT for step in STEPS]
    assert len(list(tmp_path.glob("walls*.vtu"))) == 4  # the ramp stands, then moves 3 frames
    assert cli.main(["convert", str(dumps / "traj*.dump"), str(tmp_path / "p.pvd")]) == 0
    assert cli.main(["convert", str(tmp_path / "p.pvd"), str(tmp_path / "t.dump")]) == 0
    for mine, dumped in zip(ours(tmp_path / "t.dump"), ours(dumps / "traj*.dump")):
        assert mine.timestep == dumped.timestep and mine.time is None  # a dump as LIGGGHTS writes it
        for name, values in dumped.arrays.items():
            np.testing.assert_array_equal(mine.arrays[name], values, err_msg=name)


def test_convert_refuses_what_it_cannot_write(dumps, tmp_path, capsys):
    for target, extra, says in (
        ("out.xyz", [], ("dump", "h5md", "vtk", "vtp", "vtu", "pvd")),
        ("out.stl", [], ("STL holds surface meshes, not particle frames",)),
        ("out.vtk", ["--option", "colour=red"], ("binary", "index")),
        ("out.vtk", ["--dt", "-1"], ("--dt",)),
    ):
        assert cli.main(["convert", str(dumps / "traj0.dump"), str(tmp_path / target), *extra]) == 1
        error = capsys.readouterr().err
        assert all(word in error for word in says), error
    assert not list(tmp_path.iterdir())


if __name__ == "__main__":
    simulate(Path(sys.argv[1]), sys.argv[2])
