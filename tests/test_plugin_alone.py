"""Each plugin works alone: a fresh virtual environment with ``pygran-core`` and that one plugin
runs a small real job (engines: insert into a box with a floor and an STL hopper, run, read
the trajectory back; readers: read a dump, convert it to H5MD, read a VTK mesh).

The module builds the core's wheel once, and installs the core's third-party requirements
(numpy, scipy, h5py...) once in an environment of their own that each fresh environment sees
through a ``.pth`` file: each then installs the core's wheel and its plugin, and pip resolves
the plugin's requirements there, so nothing of the repository but those two is importable.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pygran_core import registry
from pygran_core.testing.solvers import require_solver

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"

ENGINE_JOB = """
import json, sys
import numpy as np
from pygran_core import analysis, params, simulation
from pygran_core._compiled import kernels

engine, silo, out = sys.argv[1:4]
material = dict(params.stearicAcid, cohesionEnergyDensity=0.0)  # YADE has no cohesion model
with simulation.DEM(
    engine=engine,
    box=(-1.2e-3, 1.2e-3, -1.2e-3, 1.2e-3, 0.0, 4e-3),
    boundary=("f", "f", "f"),
    gravity=(9.81, 0, 0, -1),
    dt=5e-7,
    output=out,
    progress=False,
    species=({"material": material, "radius": 1e-4},),
    mesh={"hopper": {"file": silo, "mtype": "mesh/surface", "material": material, "args": ("scale 1e-3",)}},
    traj={"pfile": "traj.dump", "freq": 10000},
) as sim:
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    sim.setupWall(wtype="mesh", species=1, mesh="hopper")
    sim.insert(species=1, value=40, region=("cylinder", "z", 0, 0, 6e-4, 2.4e-3, 3.6e-3))
    sim.run(40000)
    z = sim.extractCoords()[:, 2]
    ids = sorted(sim.extractIds().tolist())
system = analysis.System(Particles=out + "/traj.dump")
system.goto(-1)
print(json.dumps({
    "n": len(ids),
    "zmin": float(z.min()),
    "zmax": float(z.max()),
    "frames": len(system),
    "last_timestep": int(system.Particles.timestep),
    "read_ids": sorted(system.Particles.id.astype(int).tolist()) == ids,
    "read_z": bool(np.allclose(np.sort(system.Particles.z), np.sort(z), rtol=1e-5, atol=0)),
    "compiled": kernels is not None,
}))
"""

READERS_JOB = """
import json, sys
from pygran_core import analysis
from pygran_core.io import open_trajectory, open_writer

hopper, out = sys.argv[1:3]
dump = open_trajectory(hopper + "/particles*.dump")
with open_writer(out + "/hopper.h5") as h5:
    for frame in dump:
        h5.write_frame(frame)
system = analysis.System(Particles=out + "/hopper.h5", Mesh=hopper + "/mesh*.vtk")
system.goto(-1)
print(json.dumps({
    "frames": len(system),
    "last_count": len(system.Particles),
    "last_timestep": int(system.Particles.timestep),
    "cells": int(system.Mesh.nCells()),
}))
"""


def pip(python: Path, *args: str) -> None:
    """``python -m pip args``: a failure shows pip's error."""
    command = [str(python), "-m", "pip", *args, "-q", "--disable-pip-version-check"]
    result = subprocess.run(command, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-4000:]


def site_packages(python: Path) -> Path:
    query = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    return Path(
        subprocess.run([str(python), "-c", query], capture_output=True, text=True, check=True).stdout.strip()
    )


@pytest.fixture(scope="module")
def core_wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``pygran-core`` built once (compiled kernels included) for every environment of the module."""
    folder = tmp_path_factory.mktemp("wheel")
    pip(Path(sys.executable), "wheel", "--no-deps", "-w", str(folder), str(ROOT))
    (wheel,) = folder.glob("pygran_core-*.whl")
    return wheel


@pytest.fixture(scope="module")
def requirements(tmp_path_factory: pytest.TempPathFactory, core_wheel: Path) -> Path:
    """The site-packages of an environment holding the core's third-party requirements only."""
    folder = tmp_path_factory.mktemp("requirements")
    subprocess.run([sys.executable, "-m", "venv", str(folder)], check=True)
    python = folder / "bin" / "python"
    pip(python, "install", str(core_wheel))
    pip(python, "uninstall", "-y", "pygran-core")
    return site_packages(python)


def fresh_environment(path: Path, plugin: str, core_wheel: Path, requirements: Path) -> Path:
    """A virtual environment holding ``pygran-core`` and ``plugin`` only, above the shared
    third-party ``requirements``; its Python."""
    subprocess.run([sys.executable, "-m", "venv", str(path)], check=True)
    python = path / "bin" / "python"
    (site_packages(python) / "pygran-requirements.pth").write_text(f"{requirements}\n")
    pip(python, "install", str(core_wheel), str(ROOT / "plugins" / plugin))
    return python


def run_job(python: Path, script: str, *args: str, cwd: Path) -> dict:
    environment = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    environment["OMP_NUM_THREADS"] = "1"
    result = subprocess.run(
        [str(python), "-c", textwrap.dedent(script), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=environment,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def installed(python: Path) -> set[str]:
    listing = subprocess.run(
        [str(python), "-m", "pip", "list", "--format=json"], capture_output=True, text=True, check=True
    )
    return {p["name"] for p in json.loads(listing.stdout) if p["name"].startswith("pygran")}


@pytest.mark.slow
@pytest.mark.parametrize("plugin", ["pygran-native", "pygran-liggghts", "pygran-yade"])
def test_engine_plugin_alone_runs_a_mesh_job(tmp_path, plugin, core_wheel, requirements):
    engine = plugin.removeprefix("pygran-")
    locate = registry.available("engine")[engine].spec.locate_solver
    if locate is not None:
        require_solver(locate)  # LIGGGHTS and YADE come from Debian: missing is a failure under CI=true
    python = fresh_environment(tmp_path / "venv", plugin, core_wheel, requirements)
    assert installed(python) == {"pygran-core", plugin}
    result = run_job(
        python, ENGINE_JOB, engine, str(DATA / "meshes" / "silo.stl"), str(tmp_path / "out"), cwd=tmp_path
    )
    assert result["n"] == 40, "particles were lost"
    assert 0 < result["zmin"] and result["zmax"] < 3.6e-3, "particles left the box or did not fall"
    assert result["frames"] == 5 and result["last_timestep"] == 40000
    assert result["read_ids"] and result["read_z"], "the trajectory read back differs from the engine's state"
    # the core's own compiled kernels (built with the core where a compiler is, as here)
    assert result["compiled"], "pygran-core was installed without its compiled analysis kernels"


@pytest.mark.slow
def test_readers_plugin_alone_converts_and_reads_meshes(tmp_path, core_wheel, requirements):
    python = fresh_environment(tmp_path / "venv", "pygran-readers", core_wheel, requirements)
    assert installed(python) == {"pygran-core", "pygran-readers"}
    listing = subprocess.run([str(python.with_name("pygran")), "plugins"], capture_output=True, text=True)
    assert "readers          pygran-readers 0.1.0" in listing.stdout
    for absent in ("pygran-native", "pygran-liggghts", "pygran-yade"):
        assert absent not in listing.stdout
    result = run_job(python, READERS_JOB, str(DATA / "liggghts-hopper"), str(tmp_path), cwd=tmp_path)
    assert result == {"frames": 31, "last_count": 423, "last_timestep": 30000, "cells": 320}
