"""nSim=2 under mpirun -np 2: one simulation per rank, each with its own parameters and output."""

import re
import subprocess
import sys
import textwrap

from pygran_liggghts.library import find_library
from pygran_liggghts.session import mpirun_prefix

from pygran_core.testing.solvers import require_solver

SCRIPT = """
from pygran_core import simulation

material = {"youngsModulus": 5e6, "poissonsRatio": 0.45, "coefficientRestitution": 0.3,
            "coefficientFriction": [0.2, 0.7], "density": 2500.0}
with simulation.DEM(engine="liggghts", model="HertzMindlin", nSim=2, box=(0, 0.01, 0, 0.01, 0, 0.01),
                    gravity=(9.81, 0, 0, -1), dt=1e-6, output=OUTPUT, progress=False,
                    species=({"material": material, "radius": [5e-4, 8e-4]},)) as sim:
    sim.setupWall(species=1, plane="zplane", peq=0.0)
    sim.createParticles(1, "single", 0.005, 0.005, 0.002)
    sim.run(100)
    print("run", sim.output.name, sim.extractRadii()[0], flush=True)
"""


def test_nsim_two_runs_under_mpirun(tmp_path):
    require_solver(find_library)
    script = tmp_path / "nsim.py"
    script.write_text(textwrap.dedent(SCRIPT).replace("OUTPUT", repr(str(tmp_path / "study"))))
    done = subprocess.run(
        [*mpirun_prefix(2), sys.executable, str(script)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert sorted(re.findall(r"run (run\d) (\S+)", done.stdout)) == [("run0", "0.0005"), ("run1", "0.0008")]
    for run, friction, diameter in (("run0", "0.2", "0.001"), ("run1", "0.7", "0.0016")):
        text = (tmp_path / "study" / run / "in.pygran").read_text()
        assert f"coefficientFriction peratomtypepair 1 {friction}\n" in text
        assert f"set atom 1 diameter {diameter} density 2500\n" in text
        assert (tmp_path / "study" / run / "liggghts.log").is_file()
        assert (tmp_path / "study" / run / "pygran.log").is_file()
