"""PyGran 1.x's nSim under mpirun: every run lands in one output folder, named once."""

import subprocess
import sys
import textwrap

import pytest

SCRIPT = """
import os, sys, time
from PyGran import simulation, params

rank = int(os.environ.get("OMPI_COMM_WORLD_RANK", os.environ.get("PMI_RANK", "0")))
time.sleep(1.5 * rank)  # the ranks reach DEM() in different seconds of the clock

material = params.stearicAcid
material["cohesionEnergyDensity"] = 0.0
material["coefficientFriction"] = [0.2, 0.7]  # one per run
pDict = {
    "engine": sys.argv[1],
    "nSim": 2,
    "box": (0, 0.01, 0, 0.01, 0, 0.01),
    "gravity": (9.81, 0, 0, -1),
    "dt": 1e-6,
    "species": ({"material": material, "radius": 1e-3},),
    "traj": {"pfile": None},
    "stages": {"settle": 1e2},
}
sim = simulation.DEM(**pDict)
sim.setupWall(species=1, plane="zplane", peq=0.0)
sim.createParticles(1, "single", 0.005, 0.005, 0.002)
sim.run(pDict["stages"]["settle"], pDict["dt"])
friction = sim.engine.spec.species[0].material["coefficientFriction"]
line = f"run {sim.output.parent.name} {sim.output.name} {sim.extractVelocities()[0, 2]} {friction}"
sys.stdout.write(line + "\\n")  # one write: the ranks' lines stay whole, even unbuffered
sys.stdout.flush()
sim.close()
"""


@pytest.mark.parametrize("engine", ["native", "liggghts"])
def test_nsim_runs_share_one_output_folder(tmp_path, engine):
    """Two runs (friction 0.2 and 0.7) under mpirun -np 2: one folder, run0 and run1, each
    with its own material; the sphere falls 100 steps of 1e-6 s from rest (v = -g t)."""
    from pygran_liggghts.library import find_library
    from pygran_liggghts.session import mpirun_prefix

    from pygran_core.testing.solvers import require_solver

    if engine == "liggghts":
        require_solver(find_library)
    script = tmp_path / "study.py"
    script.write_text(textwrap.dedent(SCRIPT))
    done = subprocess.run(
        [*mpirun_prefix(2), sys.executable, str(script), engine],
        capture_output=True,
        text=True,
        timeout=180,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    folders = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(folders) == 1, folders
    (study,) = folders
    assert study.name.startswith("SpringDashpot-")
    printed = sorted(line.split()[1:] for line in done.stdout.splitlines() if line.startswith("run "))
    assert [row[:2] for row in printed] == [[study.name, "run0"], [study.name, "run1"]]
    for row, friction in zip(printed, ("0.2", "0.7")):
        assert float(row[2]) == pytest.approx(-9.81 * 100 * 1e-6, rel=1e-9)
        assert row[3] == friction  # the run's own material
    if engine == "liggghts":
        for run, friction in (("run0", "0.2"), ("run1", "0.7")):
            script = (study / run / "in.pygran").read_text()
            assert f"coefficientFriction peratomtypepair 1 {friction}\n" in script
