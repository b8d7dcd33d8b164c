"""The solver's thread team (team.h) alone: 10^5 phases of two stages with random numbers of
blocks and random delays (tests/team_stress.c), built under ThreadSanitizer with and without
the team's heuristics, and optimised with more threads than this machine has CPUs. Every block
runs once in its phase, every second-stage block sees the values of the first-stage blocks it
awaits, and ThreadSanitizer reports no race."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

HERE = Path(__file__).parent
SOURCE = HERE.parent / "src" / "pygran_native"
PHASES = 100_000


@pytest.mark.parametrize(
    ("flags", "threads", "heuristics"),
    [
        (["-O1", "-g", "-fsanitize=thread"], 3, 1),
        (["-O1", "-g", "-fsanitize=thread"], 3, 0),
        (["-O2"], 5, 1),
    ],
    ids=["tsan", "tsan-no-heuristics", "optimised-5-threads"],
)
def test_every_block_runs_once_per_phase_without_races(tmp_path, flags, threads, heuristics):
    compiler = shutil.which("cc") or shutil.which("gcc")
    assert compiler, "a C compiler is needed (it builds the plugin too)"
    binary = tmp_path / "team_stress"
    build = [compiler, *flags, "-pthread", f"-DPG_TEAM_HEURISTICS={heuristics}", f"-I{SOURCE}"]
    subprocess.run([*build, str(HERE / "team_stress.c"), "-o", str(binary)], check=True)
    run = subprocess.run(
        [str(binary), str(threads), str(PHASES), "7"], capture_output=True, text=True, timeout=120
    )
    assert "ThreadSanitizer" not in run.stderr, run.stderr[:4000]
    assert run.returncode == 0, run.stdout + run.stderr[:4000]
    found = re.fullmatch(r"(\d+) phases, (\d+) blocks, 0 missed, 0 wrong values\n", run.stdout)
    assert found, run.stdout
    assert int(found[1]) == PHASES
    assert int(found[2]) > 10 * PHASES  # 1 to 16 blocks in the first stage, 0 to 16 in the second
