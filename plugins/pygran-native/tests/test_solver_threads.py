"""The native solver's threads: the same bits whichever thread runs a block, the choice
between the team and one thread, the loops' CPU timers, the default thread count, and its
limit."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from pygran_native._solver import TEAM_HEURISTICS
from pygran_native.solver import Solver

from pygran_core.errors import ConfigError

# A bed of 512 spheres on a floor, with the threads given (on one CPU when told to), then what
# run_bed is given to do with it.
BED = """
import os, sys
import numpy as np
from pygran_native.solver import Solver

cpus = os.sched_getaffinity(0)
if sys.argv[3] == "one-cpu":
    os.sched_setaffinity(0, {min(cpus)})
a, n_side, R = 2.2e-3, 8, 1e-3
s = Solver(box=[[0, 0, 0], [n_side * a, n_side * a, (n_side + 3) * a]], periodic=(True, True, False),
           gravity=(0, 0, -9.81), skin=4e-4, threads=int(sys.argv[2]))
s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
s.add_plane((0, 0, 0), (0, 0, 1))
grid = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3)
x = (grid + 0.5) * a + np.random.default_rng(5).uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * R)
s.add_particles(x, R, densities=2500)
"""
# 1500 steps in two runs; saves positions, velocities, angular velocities and forces (argv[1])
SETTLE = """
for steps in (700, 800):
    s.run(steps, 1e-5)
np.save(sys.argv[1], np.stack([s.positions, s.velocities, s.omegas, s.forces]))
"""
# argv[1] steps; prints the timings as JSON
TIMINGS = """
import json
s.run(int(sys.argv[1]), 1e-5)
print(json.dumps({k: getattr(v, "tolist", lambda: v)() for k, v in s.timings.items()}))
"""
# argv[1] steps; prints the steps the master ran without the team, and the threads' moves
SOLO_STEPS = """
s.run(int(sys.argv[1]), 1e-5)
print(s.timings["solo_steps"], s.timings["moves"])
"""
# started on one CPU, the team runs 10 steps; then this thread (only) may use every CPU again,
# and the team runs argv[1] more steps; prints the threads' moves
MOVES = """
s.run(10, 1e-5)
os.sched_setaffinity(0, cpus)
s.run(int(sys.argv[1]), 1e-5)
print(s.timings["moves"])
"""


def run_bed(then: str, arg: str, threads: int, cpus: str) -> str:
    """The output of BED followed by ``then`` in a fresh process (argv: arg, threads, cpus)."""
    return subprocess.run(
        [sys.executable, "-c", BED + then, arg, str(threads), cpus],
        check=True,
        capture_output=True,
        text=True,
    ).stdout


def settle(tmp_path, threads: int, cpus: str = "all") -> np.ndarray:
    out = tmp_path / f"{threads}-{cpus}.npy"
    run_bed(SETTLE, str(out), threads, cpus)
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


def test_the_loops_cpu_times_and_their_span():
    # forces_span sums each step's busiest thread's CPU time in the pair and particle loops:
    # alone, that thread's whole time; with four threads (on this machine's CPUs, waiting for
    # each other's pair blocks), between the busiest thread's total and all threads' total
    one = json.loads(run_bed(TIMINGS, "500", 1, "all"))
    assert one["forces_span"] == pytest.approx(one["pairs_cpu"][0] + one["particles_cpu"][0], rel=1e-12)
    t = json.loads(run_bed(TIMINGS, "1500", 4, "all"))
    per_thread = np.add(t["pairs_cpu"], t["particles_cpu"])
    assert len(per_thread) == 4
    assert min(t["pairs_cpu"]) > 0 and min(t["particles_cpu"]) > 0
    assert per_thread.max() <= t["forces_span"] * (1 + 1e-9) <= per_thread.sum() * (1 + 1e-9)
    assert t["pairs"] > 0 and t["particles"] > 0


HEURISTICS = pytest.mark.skipif(not TEAM_HEURISTICS, reason="built with PYGRAN_NATIVE_TEAM_HEURISTICS=0")


@HEURISTICS
@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this system")
def test_a_team_that_shares_one_cpu_runs_alone():
    # three threads on one CPU could only take turns: the master runs most steps alone
    # (85-95 % of 60,000 measured; the tuner times the team in a window every 2 s at most,
    # and one where the team seemed faster costs a few thousand steps); no CPU to move to
    steps = 60000
    solo, moves = map(int, run_bed(SOLO_STEPS, str(steps), 3, "one-cpu").split())
    assert solo > 0.6 * steps
    assert moves == 0
    assert run_bed(SOLO_STEPS, "2000", 1, "all").split() == ["0", "0"]


@HEURISTICS
@pytest.mark.skipif(
    not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs"
)
def test_a_thread_woken_on_the_masters_cpu_moves_to_a_free_one():
    # the worker, started on the master's one CPU, stays there when the master may use all
    # again: at its first phase it finds itself next to the master and moves (once, measured)
    assert int(run_bed(MOVES, "2000", 2, "one-cpu")) >= 1


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
