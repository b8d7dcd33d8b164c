"""The native solver's threads: the same bits whichever thread runs a block, the default
thread count, and its limit."""

import os
import subprocess
import sys

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core.errors import ConfigError

# A bed of 512 spheres settling on a floor for 1500 steps, with the threads given (on one CPU
# when told to); saves positions, velocities, angular velocities and forces to a .npy file.
SCRIPT = """
import os, sys
import numpy as np
from pygran_native.solver import Solver

if sys.argv[3] == "one-cpu":
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
a, n_side, R = 2.2e-3, 8, 1e-3
s = Solver(box=[[0, 0, 0], [n_side * a, n_side * a, (n_side + 3) * a]], periodic=(True, True, False),
           gravity=(0, 0, -9.81), skin=4e-4, threads=int(sys.argv[2]))
s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
s.add_plane((0, 0, 0), (0, 0, 1))
grid = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3)
x = (grid + 0.5) * a + np.random.default_rng(5).uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * R)
s.add_particles(x, R, densities=2500)
for steps in (700, 800):
    s.run(steps, 1e-5)
np.save(sys.argv[1], np.stack([s.positions, s.velocities, s.omegas, s.forces]))
"""


def settle(tmp_path, threads: int, cpus: str = "all") -> np.ndarray:
    out = tmp_path / f"{threads}-{cpus}.npy"
    subprocess.run([sys.executable, "-c", SCRIPT, str(out), str(threads), cpus], check=True)
    return np.load(out)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this system")
def test_the_bits_do_not_depend_on_which_thread_runs_a_block(tmp_path):
    # three threads take the blocks as they come free: on one CPU they take turns (one runs
    # the blocks of those waiting for the CPU), on several they run side by side
    three = settle(tmp_path, 3)
    np.testing.assert_array_equal(settle(tmp_path, 3, "one-cpu"), three)
    assert np.abs(three[3]).max() > 0
    one = settle(tmp_path, 1)
    assert not np.array_equal(one, three)  # another thread count sums in another order
    assert np.abs(one[0] - three[0]).max() < 1e-4


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this system")
def test_default_threads_are_the_cpus_this_process_may_use():
    code = (
        "import os, sys\n"
        "from pygran_native.solver import Solver\n"
        "if len(sys.argv) > 1: os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})\n"
        "print(len(os.sched_getaffinity(0)), Solver(box=[[0, 0, 0], [1, 1, 1]], skin=1e-3).threads)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}

    def threads(*args: str, **extra: str) -> list[int]:
        out = subprocess.run(
            [sys.executable, "-c", code, *args], env=env | extra, capture_output=True, text=True, check=True
        )
        return [int(k) for k in out.stdout.split()]

    cpus, default = threads()
    assert default == cpus == len(os.sched_getaffinity(0))
    assert threads("pinned") == [1, 1]
    assert threads("pinned", OMP_NUM_THREADS="3") == [1, 3]


def test_more_threads_than_the_limit_are_refused():
    with pytest.raises(ConfigError, match="threads: must be an integer from 1 to 1024"):
        Solver(box=[[0, 0, 0], [1, 1, 1]], skin=1e-3, threads=1025)
