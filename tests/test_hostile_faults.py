"""An output folder in use by another live simulation is refused before any file in it is
opened; the audit's bare exceptions and wrong messages are PyGranErrors that say what is
wrong: an output folder that cannot be made, a numpy array for the box (taken), mesh speeds
of 1e30 m/s, a dump declaring 10^19 atoms, a VTK cell naming point -1."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from pygran_core import registry, simulation
from pygran_core.errors import ConfigError, ReadError, UnsupportedFeature
from pygran_core.formats.dump import format_frame
from pygran_core.io import open_trajectory
from pygran_core.testing.formats import particle_frames
from pygran_core.testing.mistakes import BOX, square_stl, valid
from pygran_core.testing.solvers import require_solver

ENGINES = ("native", "liggghts", "yade")

HOLDER = """
import sys
from pygran_core import simulation
from pygran_core.testing.mistakes import valid

sim = simulation.DEM(**valid(sys.argv[1], "native") | {"traj": {"pfile": "traj.dump", "freq": 10}})
sim.setupWall(species=1, plane="zplane", peq=0.0)
sim.createParticles(1, "single", 0.01, 0.01, 0.01)
sim.run(100)
print("holding", flush=True)
sys.stdin.read()  # until killed
"""


def dem(output: Path, engine: str, **changes) -> simulation.DEM:
    spec = registry.get_engine(engine)
    if spec.locate_solver is not None:
        require_solver(spec.locate_solver)
    return simulation.DEM(**valid(output, engine) | changes)


def steps(path: Path) -> list[int]:
    """The steps of the frames of the trajectory ``path``."""
    with open_trajectory(path) as trajectory:
        return [frame.timestep for frame in trajectory]


def test_a_folder_in_use_by_this_script_is_refused_until_closed(tmp_path):
    output = tmp_path / "out"
    first = dem(output, "native", traj={"pfile": "traj.dump", "freq": 1})
    first.createParticles(1, "single", 0.01, 0.01, 0.01)
    first.run(3)
    in_use = "is in use by another live simulation [(]of this script, not closed yet[)]"
    with pytest.raises(ConfigError, match=in_use):
        dem(output, "native", traj={"pfile": "traj.dump", "freq": 1})
    first.close()
    assert steps(output / "traj.dump") == [0, 1, 2, 3]  # not truncated by the refused one
    with dem(output, "native") as second:
        assert second.step == 0


@pytest.mark.parametrize("engine", ENGINES)
def test_a_refused_simulation_leaves_its_folder_free(tmp_path, engine):
    """Refused while its engine is made (nothing to resume from; a setting the engine cannot
    honour), with the error kept by the script: the folder is free for the next simulation."""
    output = tmp_path / "out"
    capabilities = registry.get_engine(engine).capabilities
    resume = ConfigError if "restart" in capabilities else UnsupportedFeature
    refusals = [(resume, {"restart": (10, "restart", "restart.h5", True)})]
    if "thornton-ning" not in capabilities:
        refusals.append((UnsupportedFeature, {"model": simulation.models.ThorntonNing}))
    kept = []
    for error, settings in refusals:
        with pytest.raises(error) as refused:
            dem(output, engine, **settings)
        kept.append(refused)  # the traceback, and the half-made engine in it, stay alive
    with dem(output, engine) as sim:
        sim.run(1)
        assert sim.step == 1 and len(kept) == len(refusals)


def test_a_folder_in_use_by_another_process_is_refused_and_freed_by_its_death(tmp_path):
    """The audit's case: two scripts on one folder, one died with a bare BlockingIOError and the
    other could find its trajectory truncated. The lock dies with its holder, kill -9 too."""
    output = tmp_path / "out"
    script = tmp_path / "holder.py"
    script.write_text(textwrap.dedent(HOLDER))
    with subprocess.Popen(
        [sys.executable, str(script), str(output)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    ) as holder:
        assert holder.stdout is not None and holder.stdout.readline() == "holding\n"
        for engine in ENGINES:
            in_use = f"in use by another live simulation [(]process {holder.pid}[)]"
            with pytest.raises(ConfigError, match=in_use):
                dem(output, engine, traj={"pfile": "traj.dump"})
        assert (output / ".pygran.lock").read_text() == str(holder.pid)
        holder.kill()
    assert steps(output / "traj.dump") == list(range(0, 101, 10))
    with dem(output, "native") as sim:
        assert (output / ".pygran.lock").read_text() == str(os.getpid())
        sim.run(1)


FULL = """
import resource, signal, sys
from pygran_core import simulation
from pygran_core.errors import PyGranError
from pygran_core.testing.mistakes import valid

signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # past the limit a write fails with EFBIG, as on a full disk
resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))
try:
    with simulation.DEM(**valid(sys.argv[1], "native") | {"traj": {"pfile": "traj.dump", "freq": 10}}) as sim:
        sim.createParticles(1, "lattice", 2e-3, region=("block", 0, 0.01, 0, 0.01, 0, 0.01))
        sim.run(2000)
except PyGranError as error:
    print(type(error).__name__, error)
"""


def test_a_full_disk_under_a_dump_is_one_error_naming_the_file(tmp_path):
    """A file-size limit of 60 kB stands for the full disk: one PyGranError naming traj.dump,
    the frames before it readable, and the interpreter ends cleanly."""
    script = tmp_path / "full.py"
    script.write_text(textwrap.dedent(FULL))
    done = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "out")], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith(f"WriteError {tmp_path / 'out' / 'traj.dump'}: frame ")
    assert "Traceback" not in done.stderr
    written = int(done.stdout.split(": frame ")[1].split()[0])  # frames before the one that failed
    with open_trajectory(tmp_path / "out" / "traj.dump") as trajectory:
        frames = [trajectory[k] for k in range(written)]
    assert written >= 2 and [frame.timestep for frame in frames] == list(range(0, 10 * written, 10))
    assert all(len(frame.arrays["id"]) == 125 for frame in frames)  # the 5^3 lattice, whole


@pytest.mark.parametrize(
    ("place", "named"),
    [
        ("a-file", "a file is in its place or in a parent's"),
        ("a-file/out", "a file is in its place or in a parent's"),
        ("/proc/pygran-out", "No such file or directory"),
        ("/dev/null/out", "a file is in its place or in a parent's"),
    ],
)
def test_an_output_folder_that_cannot_be_made_is_a_config_error(tmp_path, place, named):
    (tmp_path / "a-file").touch()
    output = tmp_path / place
    with pytest.raises(ConfigError, match=rf"^output '{output}' cannot be made or written: {named}"):
        dem(output, "native")


@pytest.mark.parametrize("engine", ENGINES)
def test_a_numpy_box_is_the_same_box(tmp_path, engine):
    with dem(tmp_path / "array", engine, box=np.array(BOX)) as sim:
        assert sim.spec.domain.box == ((0.0, 0.02), (0.0, 0.02), (0.0, 0.02))
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.01, 0.01, 0.0011)
        sim.run(20)
        array = sim.extractCoords()
    with dem(tmp_path / "tuple", engine) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.01, 0.01, 0.0011)
        sim.run(20)
        np.testing.assert_array_equal(sim.extractCoords(), array)
    with pytest.raises(ConfigError, match=r"box must be a sequence of 6 numbers"):
        dem(tmp_path / "square", engine, box=np.array(BOX).reshape(2, 3))


@pytest.mark.parametrize("engine", ENGINES)
def test_absurd_mesh_speeds_are_refused_with_their_limits(tmp_path, engine):
    """1e30 m/s was accepted on native. The limits: 1e4 m/s, and half the skin (by default half
    the smallest radius, 0.5 mm) per step of 5e-6 s: 50 m/s."""
    params = valid(tmp_path / "out", engine)
    plate = {"file": str(square_stl(params)), "scale": 1e-3, "move": (0.01, 0.01, 0.01)}
    with dem(tmp_path / "out", engine, mesh={"plate": plate}) as sim:
        with pytest.raises(ConfigError, match=r"reaches 1e\+30 m/s, above 1e\+04 m/s \(faster than sound"):
            sim.moveMesh("plate", linear=(0, 0, 1e30))
        with pytest.raises(ConfigError, match=r"reaches 51 m/s, above 50 m/s \(skin / \(2 dt\)"):
            sim.moveMesh("plate", linear=(0, 0, 51))
        # the square's corners are sqrt(2) mm from the axis through its centre (0.01, 0.01)
        with pytest.raises(ConfigError, match="moveMesh 'plate' rotate: the mesh reaches 141 m/s"):
            sim.moveMesh("plate", rotate=True, axis=(0, 0, 1), origin=(0.01, 0.01, 0), omega=1e5)
        with pytest.raises(ConfigError, match=r"wiggle: the mesh reaches 1\.26e\+04 m/s"):
            sim.moveMesh("plate", wiggle=True, amplitude=(0.002, 0, 0), period=1e-6)
        sim.moveMesh("plate", linear=(0, 0, 49))
        assert len(sim.engine.handles) >= 2


def test_a_dump_declaring_1e19_atoms_is_a_read_error(tmp_path):
    lines = format_frame(particle_frames()[0], 0).splitlines(True)
    at = lines.index("ITEM: NUMBER OF ATOMS\n") + 1
    for count in ("10000000000000000000", "9223372036854775808", "9" * 40):
        lines[at] = count + "\n"
        path = tmp_path / "big.dump"
        path.write_text("".join(lines))
        with pytest.raises(ReadError, match=f"line {at + 1}: atom count {count} is outside 0 to {2**63 - 1}"):
            steps(path)


def test_a_vtk_cell_naming_point_minus_one_is_named_as_such(tmp_path):
    path = tmp_path / "mesh.vtk"
    path.write_text(
        "# vtk DataFile Version 3.0\nmesh\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n"
        "0 0 0\n1 0 0\n0 1 0\nPOLYGONS 1 4\n3 0 1 -1\n"
    )
    with pytest.raises(ReadError, match="a cell refers to point -1, but the points are numbered 0 to 2"):
        steps(path)
