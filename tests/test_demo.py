"""The hopper study at reduced size: it runs, measures physical numbers and writes its files."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pygran_core import analysis
from pygran_core.apps import demo
from pygran_core.io import open_trajectory

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "hopper_demo.py"


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    output = tmp_path_factory.mktemp("hopper")
    result = subprocess.run(
        [
            sys.executable,
            str(EXAMPLE),
            "--particles",
            "700",
            "--output",
            str(output),
            "--settle-time",
            "0.2",
            "--discharge-time",
            "0.5",
        ],
        capture_output=True,
        text=True,
        env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin"},
    )
    assert result.returncode == 0, result.stderr
    return output, result.stdout


def test_numbers_are_physical(study):
    output, stdout = study
    results = json.loads((output / "summary.json").read_text())["results"]
    assert results["particles"] == 700
    assert 0.55 < results["packing_fraction"] < 0.66
    assert 3.0 < results["mean_coordination"] < 7.0
    assert 0.97 < results["rdf_first_peak"] <= 1.0  # soft spheres overlap slightly
    assert 0.7 < results["discharge_rate"] / results["beverloo_rate"] < 1.6
    assert results["discharged_fraction"] > 0.95
    assert "discharge rate (Beverloo)" in stdout and (output / "summary.txt").read_text() in stdout


def test_files_are_readable(study):
    output, _ = study
    assert (output / "hopper.png").stat().st_size > 20_000
    assert [p.name for p in output.glob("walls*.vtk")] == ["walls0.vtk"]  # the hopper stands still
    system = analysis.System(Particles=str(output / "traj.h5md"), Mesh=str(output / "walls.pvd"))
    assert len(system) == 36  # a frame every 0.02 s over 0.7 s, and the first
    system.goto(0)
    assert len(system.Particles) == 700 and system.Mesh.nCells() == 3 * 2 * 64 - 2 * 64
    system.goto(-1)
    assert len(system.Particles) < 35


def test_beverloo_and_geometry():
    study = demo.HopperStudy()
    # W = C rho_b sqrt(g) (D - k d)^(5/2) for D = 12 mm, d = 2 mm, rho_b = 0.6 * 2500
    assert demo.beverloo(study, 0.6) == pytest.approx(0.58 * 1500 * math.sqrt(9.81) * 0.009**2.5)
    triangles = demo.hopper_triangles(study, segments=32)
    radii = np.hypot(triangles[..., 0], triangles[..., 1]).ravel()
    z = triangles[..., 2].ravel()
    expected = np.minimum(0.006 + z * math.tan(math.radians(30)), study.top_radius)
    np.testing.assert_allclose(radii, expected, rtol=1e-12)


def test_stl_round_trip(tmp_path):
    triangles = demo.hopper_triangles(demo.HopperStudy(), segments=16)
    frame = open_trajectory(demo.write_stl(tmp_path / "h.stl", triangles), format="stl").read_frame(0)
    np.testing.assert_allclose(frame.arrays["points"][frame.arrays["cells"]], triangles)


def test_unknown_engine_is_a_clear_error(tmp_path):
    result = subprocess.run(
        [
            str(Path(sys.executable).with_name("pygran")),
            "demo",
            "--engine",
            "nativ",
            "--output",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 1
    assert "No engine named 'nativ' is installed. Did you mean 'native'?" in result.stderr


def test_the_study_runs_on_liggghts_under_mpi(tmp_path):
    """`pygran demo --engine liggghts --nprocs 2`: the same study on two MPI ranks."""
    from pygran_core import registry
    from pygran_core.cli import main
    from pygran_core.testing.solvers import require_solver

    require_solver(registry.get_engine("liggghts").locate_solver)
    argv = ["demo", "--engine", "liggghts", "--nprocs", "2", "--particles", "600"]  # a deep bed
    assert main([*argv, "--output", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "summary.json").read_text())["results"]
    assert results["engine"] == "liggghts" and results["particles"] == 600
    assert 0.55 < results["packing_fraction"] < 0.66
    assert results["discharged_fraction"] > 0.9
    assert "1 by 1 by 2 MPI processor grid" in (tmp_path / "liggghts.log").read_text()
