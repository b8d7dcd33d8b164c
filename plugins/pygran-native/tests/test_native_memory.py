"""The native engine's memory per particle, loosely (issue 45; the tight figures, at 10^6 and
10^7 particles, are ``benchmarks/native_memory.py``'s): 10^5 spheres of the settle scenario's
lattice created and run through ``simulation.DEM`` in a fresh interpreter, whose resident memory
(the high-water mark from when the simulation starts, less the memory before it) and the
solver's own allocations are measured per particle."""

from __future__ import annotations

import json
import subprocess
import sys

SCRIPT = r"""
import json, sys, tempfile
from pathlib import Path
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.validation import GRAVITY, RADIUS, SETTLE_SPACING, SOFT
from pygran_core.testing.validation import one_species, settle_positions

def status(field):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(field + ":"))

def settle(shape, steps, folder):
    nx, ny, nz = shape
    box = (0.0, nx * SETTLE_SPACING, 0.0, ny * SETTLE_SPACING, 0.0, (nz + 3) * SETTLE_SPACING)
    with one_species("native", Path(folder), SOFT, RADIUS, model=HertzMindlin, box=box,
                     boundary=("p", "p", "f"), gravity=GRAVITY, dt=1e-5, nns_skin=4e-4, threads=2) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", settle_positions(shape))
        sim.run(steps)
        sim.extractCoords()
        return sim.engine.solver.memory_bytes, sim.engine.solver.list_entries[0]

with tempfile.TemporaryDirectory() as folder:
    settle((10, 10, 2), 20, folder)  # loads what the run imports
baseline = status("VmRSS")
with open("/proc/self/clear_refs", "w") as refs:
    refs.write("5")  # the high-water mark from now on
n = 100_000
with tempfile.TemporaryDirectory() as folder:
    solver, pairs = settle((100, 100, 10), int(sys.argv[1]), folder)
print(json.dumps({"peak": (status("VmHWM") - baseline) / n, "solver": solver / n, "pairs": pairs / n}))
"""


def test_memory_per_particle_of_a_settle_at_10_5():
    done = subprocess.run([sys.executable, "-c", SCRIPT, "600"], capture_output=True, text=True, check=True)
    found = json.loads(done.stdout.splitlines()[-1])
    assert 2.5 < found["pairs"] < 3.5  # the lattice's listed pairs per particle, about 2.9
    # about 315 and 400 bytes per particle; before the contact table and the other savings
    # of issue 45, 545 and 700
    assert found["solver"] < 400, found
    assert found["peak"] < 600, found
