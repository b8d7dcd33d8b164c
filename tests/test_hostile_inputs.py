"""Strings that reach a solver's command language: a word or a path holding what LIGGGHTS
reads as a comment, a variable, a quote, a continuation or a new line is refused naming its
keyword, and every path LIGGGHTS accepts is named so that the saved ``in.pygran`` reruns with
the ``liggghts`` binary to the same trajectory, byte for byte."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pygran_core import params, registry, simulation
from pygran_core.errors import ConfigError, EngineError
from pygran_core.io import open_trajectory
from pygran_core.testing.mistakes import valid
from pygran_core.testing.solvers import require_solver

PLATE = Path(__file__).parent / "data" / "meshes" / "square.stl"  # 10 mm square at z = 3 mm
START = np.array([[-5e-4, 0, 3.2e-3], [5e-4, 0, 3.2e-3], [0, 5e-4, 3.5e-3]])
#: Folder names LIGGGHTS' input names in quotes: the live run and the rerun write there.
ACCEPTED = ["my run", "run#1", "it's", 'say "hi"', "all # ' & of them"]
#: Folder names it cannot name: '$' (a variable even in quotes), '*' and '%' in a folder (the
#: step and the processor), both kinds of quote.
REFUSED = ["run$x", "star*", "pct%d", "both ' and \""]


def liggghts_binary() -> str:
    found = shutil.which("liggghts")
    if found is None:
        raise EngineError("the liggghts binary is not installed: apt-get install -y liggghts")
    return found


def fall(output: Path) -> np.ndarray:
    """Three spheres fall for 300 steps above a mesh plate read from a folder with a space;
    frames and LIGGGHTS restarts every 100 steps."""
    require_solver(registry.get_engine("liggghts").locate_solver)
    mesh_dir = output / "mesh files"
    mesh_dir.mkdir(parents=True, exist_ok=True)
    shutil.copy(PLATE, mesh_dir / "plate.stl")
    with simulation.DEM(
        engine="liggghts",
        model=simulation.HertzMindlin,
        box=(-1e-3, 1e-3, -1e-3, 1e-3, 0, 4e-3),
        gravity=(9.81, 0, 0, -1),
        dt=1e-6,
        output=str(output),
        species=({"material": params.cohesionless, "radius": 1e-4},),
        mesh={"plate": {"file": str(mesh_dir / "plate.stl"), "args": ("scale 1e-3",)}},
        traj={"freq": 100, "pfile": "traj.dump", "mfile": "plate*.vtk", "args": ("id", "x", "y", "z")},
        restart=(100, "restart", "restart.h5"),
        progress=False,
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="plate")
        sim.createParticles(1, "single", START)
        sim.run(300)
        return sim.extractCoords()


@pytest.mark.parametrize("name", ACCEPTED)
def test_the_saved_input_reruns_to_the_same_trajectory(tmp_path, name):
    output = tmp_path / name
    x = fall(output)
    assert x[:, 2] == pytest.approx(START[:, 2] - 0.5 * 9.81 * 3e-4**2, rel=1e-6)
    written = {p.name: p.read_bytes() for p in [output / "traj.dump", *output.glob("plate*.vtk")]}
    assert sorted(written) == ["plate0.vtk", "traj.dump"]  # the plate stands still: one file, indexed
    for path in [output / "traj.dump", *output.glob("plate*.vtk")]:
        path.unlink()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    rerun = subprocess.run(
        [require_solver(liggghts_binary), "-in", str(output / "in.pygran"), "-log", "none"],
        cwd=elsewhere,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert rerun.returncode == 0, rerun.stdout[-2000:]
    assert {name: (output / name).read_bytes() for name in written} == written
    # LIGGGHTS alone writes the standing plate at every frame: each the frame PyGran kept once
    plate = open_trajectory(output / "plate0.vtk")[0].arrays
    for step in (100, 200, 300):
        copy = open_trajectory(output / f"plate{step}.vtk")[0].arrays
        assert all(np.array_equal(copy[key], plate[key]) for key in plate)
    assert sorted(p.name for p in (output / "restart").glob("*.restart")) == [
        f"restart.{step}.restart" for step in (100, 200, 300)
    ]
    assert list(elsewhere.iterdir()) == []  # nothing written where it ran


@pytest.mark.parametrize("name", REFUSED)
def test_a_folder_liggghts_cannot_name_is_refused_before_it_starts(tmp_path, name):
    with pytest.raises(ConfigError, match=r"^output '.*' holds .*: choose a name without it"):
        simulation.DEM(**valid(tmp_path / name, "liggghts"))
    assert not (tmp_path / name / "in.pygran").exists()


@pytest.mark.parametrize(
    ("settings", "named"),
    [
        (
            {"dump_modify": ("sort id #\nshell touch X",)},
            r"dump_modify: 'sort id #\\nshell touch X' holds '\\n', '#'",
        ),
        ({"dump_modify": ("every ${n}",)}, r"dump_modify: 'every \$\{n\}' holds '\$'"),
        ({"dump_modify": ('format "%d"',)}, "dump_modify: 'format \"%d\"' holds '\"'"),
        ({"traj": {"pfile": "t.dump", "margs": "id stress &"}}, "traj margs: '&' holds '&'"),
        ({"traj": {"pfile": "t.dump", "args": ("id", "x\nshell")}}, r"traj args: 'x\\nshell' holds '\\n'"),
        ({"traj": {"pfile": "t$HOME.dump"}}, r"traj pfile '.*t\$HOME.dump' holds '\$'"),
        ({"traj": {"pfile": "t\n.dump"}}, r"traj pfile 't\\n.dump' holds the control character"),
        ({"output": "out\rput"}, r"output 'out\\rput' holds the control character"),
        ({"restart": (10, "re*start")}, r"restart dir '.*re\*start' holds '\*' or '%' in a folder name"),
        ({"restart": (10, "restart", "a'b\".h5")}, "restart fname .* holds both kinds of quote"),
    ],
)
def test_a_word_or_path_liggghts_would_misread_is_refused(tmp_path, settings, named):
    """The audit's case first: a ``shell`` line smuggled after a comment into dump_modify."""
    base = valid(tmp_path / "out", "liggghts") | {"traj": {"pfile": "t.dump"}}
    with pytest.raises(ConfigError, match=named):
        simulation.DEM(**base | settings)
    assert not (tmp_path / "X").exists()


def test_a_raw_command_is_one_line(tmp_path):
    """A line break in command() would be a second command in the saved input (and lost live)."""
    with simulation.DEM(**valid(tmp_path / "out", "liggghts")) as sim:
        with pytest.raises(ConfigError, match=r"command 'variable a equal 1\\nshell touch X' holds '\\n'"):
            sim.command("variable a equal 1\nshell touch X")
        sim.command("variable a equal 1")
    assert "shell" not in (tmp_path / "out" / "in.pygran").read_text()
    assert not (tmp_path / "X").exists()


def test_a_mesh_file_liggghts_cannot_name_is_refused(tmp_path):
    folder = tmp_path / "mesh$dir"
    folder.mkdir()
    shutil.copy(PLATE, folder / "plate.stl")
    mesh = {"plate": {"file": str(folder / "plate.stl"), "scale": 1e-3, "move": (0.01, 0.01, 0.01)}}
    with pytest.raises(ConfigError, match=r"mesh 'plate' file '.*mesh\$dir/plate.stl' holds '\$'"):
        simulation.DEM(**valid(tmp_path / "out", "liggghts") | {"mesh": mesh})
