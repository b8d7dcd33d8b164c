"""Under mpirun: nSim=2 runs one simulation per rank, each with its own parameters and output; a
LIGGGHTS error, however raised, reaches the console once, naming the run."""

import re
import subprocess
import sys
import textwrap

import pytest
from pygran_liggghts.library import find_library
from pygran_liggghts.session import mpirun_prefix

from pygran_core.testing.solvers import require_solver

SCRIPT = """
import sys

from pygran_core import simulation
from pygran_core.testing.validation import SOFT

material = dict(SOFT, coefficientFriction=[0.2, 0.7])  # one friction per run
with simulation.DEM(engine="liggghts", model="HertzMindlin", nSim=2, box=(0, 0.01, 0, 0.01, 0, 0.01),
                    gravity=(9.81, 0, 0, -1), dt=1e-6, output=OUTPUT, progress=False,
                    species=({"material": material, "radius": [5e-4, 8e-4]},)) as sim:
    sim.setupWall(species=1, plane="zplane", peq=0.0)
    sim.createParticles(1, "single", 0.005, 0.005, 0.002)
    sim.run(100)
    sys.stdout.write(f"run {sim.output.name} {sim.extractRadii()[0]}\\n")  # one write: lines stay whole
    sys.stdout.flush()
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


FAILING = """
import math
from pygran_core import simulation
from pygran_core.testing.validation import SOFT

with simulation.DEM(engine="liggghts", model="HertzMindlin", nSim=NSIM, box=(0, 0.01, 0, 0.01, 0, 0.01),
                    dt=1e-6, output=OUTPUT, progress=False,
                    species=({"material": SOFT, "radius": 1e-3},)) as sim:
    sim.createParticles(1, "single", 2e-3, 2e-3, 2e-3)
    if sim.output.name in ("run1", "study"):
        FAIL
    sim.run(10)
"""
#: How each kind of LIGGGHTS error is provoked: error->all, error->one on every rank while
#: reading a command, error->one on rank 1 only (three touching spheres in the box's upper
#: corner, more neighbours than neigh_modify one allows).
FAILURES = {
    "all": (
        'sim.command("fix_this_typo 1")',
        r"ERROR: Unknown command: fix_this_typo 1 \(\S*input\.cpp:\d+\)",
    ),
    "one-everywhere": (
        'sim.command("print $Q")',
        r"ERROR on proc 0: Substitution for illegal variable \(\S*:\d+\)",
    ),
    "one-on-rank-1": (
        "for dx, dy in ((0, 0), (2e-3, 0), (1e-3, math.sqrt(3) * 1e-3)):\n"
        '            sim.createParticles(1, "single", 6.5e-3 + dx, 6.5e-3 + dy, 7e-3)\n'
        '        sim.command("neigh_modify page 100 one 1")\n'
        "        sim.run(10)",
        r"ERROR on proc 1: Neighbor list overflow, boost neigh_modify one \(\S*neigh_gran\.cpp:\d+\)",
    ),
}


@pytest.mark.parametrize(
    ("kind", "nsim"), [("all", 1), ("one-everywhere", 1), ("one-on-rank-1", 1), ("all", 2)]
)
def test_errors_under_mpirun_are_printed_once(tmp_path, kind, nsim):
    """Under mpirun a LIGGGHTS error ends the job; its message and source line reach the
    console once, naming the run (with nSim, the run that failed)."""
    require_solver(find_library)
    command, message = FAILURES[kind]
    script = tmp_path / "fail.py"
    output = tmp_path / "study"
    text = FAILING.replace("NSIM", str(nsim)).replace("OUTPUT", repr(str(output))).replace("FAIL", command)
    script.write_text(text)
    done = subprocess.run(
        [*mpirun_prefix(2), sys.executable, str(script)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode != 0
    run = output / "run1" if nsim > 1 else output
    lines = re.findall(rf"LIGGGHTS stopped in {re.escape(str(run))}: {message}", done.stderr)
    assert len(lines) == 1 and done.stderr.count("LIGGGHTS stopped") == 1, done.stderr


LOSING = """
import sys

from pygran_core import simulation
from pygran_core.testing.validation import SOFT

with simulation.DEM(engine="liggghts", model="HertzMindlin", box=(0, 0.01, 0, 0.01, 0, 0.01),
                    gravity=(9.81, 0, 0, -1), dt=1e-5, output=OUTPUT, progress=False,
                    species=({"material": SOFT, "radius": 5e-4},)) as sim:
    for x in (0.002, 0.008):
        sim.createParticles(1, "single", x, 0.005, 0.001)
    sim.run(2000)  # 2 cm of free fall: both leave through the floor of the box
    sys.stdout.write(f"left {len(sim.extractIds())}\\n")  # one write: the ranks' lines stay whole
    sys.stdout.flush()
"""


def test_lost_particles_reported_once_under_mpirun(tmp_path):
    """One simulation on two ranks: the warning about the particles it lost, and every line of
    pygran.log, come from rank 0 only."""
    require_solver(find_library)
    script = tmp_path / "lose.py"
    script.write_text(LOSING.replace("OUTPUT", repr(str(tmp_path / "out"))))
    done = subprocess.run(
        [*mpirun_prefix(2), sys.executable, str(script)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("left 0") == 2
    assert done.stderr.count("LostParticlesWarning: 2 particles lost") == 1, done.stderr
    log = (tmp_path / "out" / "pygran.log").read_text()
    assert log.count("engine opened") == 1 and log.count("particles lost") == 2, log  # logged, warned
