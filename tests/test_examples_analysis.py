"""The analysis examples (manual Part III) run as scripts on the hopper fixture and give sensible numbers."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from pygran_core.analysis import Mesh, Particles, System

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"


def run(name: str, cwd: Path, *args: str) -> str:
    path = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
    env = dict(os.environ, PYTHONPATH=path, MPLBACKEND="Agg")
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / f"{name}.py"), *args],
        cwd=cwd,
        env=env,
        check=True,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return done.stdout


def test_system_example(hopper, tmp_path):
    out = run("analysis_system", tmp_path, str(hopper / "particles*.dump"), str(hopper / "mesh*.vtk"))
    lines = out.splitlines()
    assert lines[0] == "frame 0: timestep 0, 0 particles, 320 wall cells"
    assert lines[30] == "frame 30: timestep 30000, 423 particles, 320 wall cells"
    assert "mean coordination number" in lines[-1] and "RDF maximum" in lines[-1]


def test_subsystem_example_writes_the_manuals_product(hopper, tmp_path):
    out = run("analysis_subsystem", tmp_path, str(hopper / "particles30000.dump"), "combined.dump")
    assert out.strip() == "10 + 3 x 2 -> 16 particles"
    combined = System(Particles=str(tmp_path / "combined.dump")).Particles
    source = System(Particles=str(hopper / "particles30000.dump")).Particles
    assert len(combined) == 16
    j, k = source[0:3], source[3:5]
    np.testing.assert_allclose(combined.radius[10:], np.sqrt(np.outer(j.radius, k.radius)).ravel())


def test_coarse_grained_example_removes_overlaps(hopper, tmp_path):
    out = run("analysis_coarse_grained", tmp_path, str(hopper / "particles*.dump"), "CG.dump")
    coarse = System(Particles=str(tmp_path / "CG.dump")).Particles
    assert out.strip() == f"{len(coarse)} coarse-grained particles written to CG.dump"
    assert 0 < len(coarse) < 423
    np.testing.assert_allclose(coarse.radius, 3 * 5e-5)
    from pygran_core.analysis.equilibrium import Neighbors

    overlaps = Neighbors(coarse).overlaps
    assert (overlaps[:, 0] <= 0.1 * 3 * 5e-5 * (1 + 1e-9)).all()


def test_coarse_particles_by_module_path(hopper, tmp_path):
    system = System(
        CoarseParticles=str(hopper / "particles*.dump"),
        scale=3,
        percent=10.0,
        module=str(EXAMPLES / "analysis_coarse_grained.py"),
    )
    system.goto(-1)
    assert type(system.CoarseParticles).__name__ == "CoarseParticles"
    assert isinstance(system.CoarseParticles, Particles) and 0 < len(system.CoarseParticles) < 423


def test_mesh_example(hopper, tmp_path):
    out = run("analysis_mesh", tmp_path, str(hopper / "mesh*.vtk"))
    assert out.startswith("frame 0 of 31: 320 cells on 960 points")
    assert "frame 30 of 31" in out and "cell data" in out
    assert isinstance(System(Mesh=str(hopper / "mesh0.vtk")).Mesh, Mesh)
