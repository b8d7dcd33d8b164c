"""Progress off a terminal (issue 44, item 4): a script run with its output redirected to a file
gets periodic lines (step, simulated time, particle-steps per second, ETA of the run and of the
script's declared steps) on stderr and in pygran.log; none on stderr when not shown."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from pygran_core.errors import ConfigError
from pygran_core.simulation import mpi
from pygran_core.simulation.progress import Progress, duration
from pygran_core.simulation.specs import ProgressSpec, parse_progress

SCRIPT = textwrap.dedent(
    """
    from pygran_core import params, simulation

    with simulation.DEM(
        engine="native",
        box=(0, 0.01, 0, 0.01, 0, 0.01),
        gravity=(9.81, 0, 0, -1),
        dt=5e-6,
        output="out",
        species=({"material": params.organic, "radius": ("constant", 5e-4)},),
        progress={PROGRESS},
    ) as sim:
        sim.insert(species=1, value=50, region=("block", 0, 0.01, 0, 0.01, 0, 0.01))
        sim.run(1000)
        sim.run(500)
    """
)
LINE = re.compile(
    r"native: progress: step (\d+), run (\d+) of (\d+) \(\d+ %\), t = ([0-9.e+-]+) s, "
    r"([0-9.e+]+) particle-steps/s, run ETA \d+:\d\d:\d\d; script (\d+) of 1500 steps \(\d+ %\), "
    r"ETA \d+:\d\d:\d\d$"
)


def run_script(folder: Path, progress: str, env: dict[str, str] | None = None) -> tuple[str, str]:
    """Run the script with stdout and stderr redirected to files, with ``env`` added to the
    environment; returns (stderr, pygran.log)."""
    (folder / "study.py").write_text(SCRIPT.replace("{PROGRESS}", progress))
    with (folder / "stdout.txt").open("w") as out, (folder / "stderr.txt").open("w") as err:
        subprocess.run(
            [sys.executable, "study.py"],
            cwd=folder,
            stdout=out,
            stderr=err,
            check=True,
            timeout=120,
            env={**os.environ, **(env or {})},
        )
    return (folder / "stderr.txt").read_text(), (folder / "out" / "pygran.log").read_text()


def test_lines_on_stderr_and_in_the_log_when_output_goes_to_a_file(tmp_path: Path) -> None:
    # every 1 ns: a line after each piece of a run (a run goes in up to 100 pieces)
    stderr, log = run_script(tmp_path, "{'every': 1e-9, 'steps': 1500}")
    lines = [LINE.match(line) for line in stderr.splitlines() if "progress:" in line]
    assert len(lines) >= 4 and all(lines)
    values = [(int(m[1]), int(m[2]), int(m[3]), float(m[4]), float(m[5]), int(m[6])) for m in lines if m]
    steps = [v[0] for v in values]
    assert steps == sorted(steps) and steps[-1] == 1500
    for step, ran, total, simulated, speed, script in values:
        assert total == (1000 if step <= 1000 else 500)
        assert ran == (step if step <= 1000 else step - 1000)
        assert simulated == pytest.approx(step * 5e-6, rel=1e-6)
        assert speed > 0 and script == step  # the script's steps count over both runs
    assert stderr.count("native: run of ") == 2  # a summary after each run that had lines
    assert "\x1b" not in stderr and "\r" not in stderr  # no progress bar, no terminal codes
    assert log.count("progress: step ") == len(lines)


def test_a_later_rank_of_a_launcher_keeps_its_lines_in_the_log(tmp_path: Path) -> None:
    # under mpirun every rank runs the script: only the first shows progress on stderr
    stderr, log = run_script(tmp_path, "{'every': 1e-9}", env={"OMPI_COMM_WORLD_RANK": "1"})
    assert "progress:" not in stderr
    assert "progress: step " in log


@pytest.mark.parametrize(
    ("env", "rank", "size"),
    [
        ({}, 0, 1),
        ({"OMPI_COMM_WORLD_RANK": "3", "OMPI_COMM_WORLD_SIZE": "4"}, 3, 4),
        ({"PMI_RANK": "2", "PMI_SIZE": "8"}, 2, 8),
        ({"PMIX_RANK": "5"}, 5, 1),
    ],
)
def test_launch_rank_and_size_from_each_launcher(
    monkeypatch: pytest.MonkeyPatch, env: dict[str, str], rank: int, size: int
) -> None:
    for name in ("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE", "PMI_RANK", "PMI_SIZE", "PMIX_RANK"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert (mpi.launch_rank(), mpi.launch_size()) == (rank, size)


def test_no_lines_on_stderr_when_not_shown(tmp_path: Path) -> None:
    stderr, log = run_script(tmp_path, "{'show': False, 'every': 1e-9}")
    assert "progress:" not in stderr and "native: run of" not in stderr
    assert "progress: step " in log  # pygran.log keeps them


def test_progress_settings_and_durations() -> None:
    assert parse_progress(None) == ProgressSpec()
    assert parse_progress({"every": 5, "steps": 10}) == ProgressSpec(None, 5.0, 10)
    with pytest.raises(ConfigError, match="every"):
        parse_progress({"every": 0})
    with pytest.raises(ConfigError, match="Unknown progress keyword 'total'"):
        parse_progress({"total": 10})
    assert duration(3725.4) == "1:02:05" and duration(float("nan")) == "?"
    clock = iter([0.0, 10.0, 20.0])
    written: list[str] = []
    progress = Progress(ProgressSpec(every=5, steps=4000), written.append, clock=lambda: next(clock))
    progress.begin(0, 2000)
    progress.update(1000, 0.01, lambda: 100)  # 1000 steps in 10 s of 100 particles
    assert written == [
        "progress: step 1000, run 1000 of 2000 (50 %), t = 0.01 s, 1e+04 particle-steps/s, "
        "run ETA 0:00:10; script 1000 of 4000 steps (25 %), ETA 0:00:30"
    ]


def test_under_mpi_every_rank_counts_at_every_update() -> None:
    # counting is collective under MPI, and each rank's clock decides differently when a
    # line is due: every rank counts at every update, a line or not
    counted: list[int] = []

    def particles() -> int:
        counted.append(1)
        return 10

    clock = iter([0.0, 1.0, 2.0, 100.0])
    progress = Progress(ProgressSpec(every=50), [].append, clock=lambda: next(clock), collective=True)
    progress.begin(0, 30)
    for step in (10, 20, 30):
        progress.update(step, 0.0, particles)
    assert len(counted) == 3 and progress.lines == 1


#: The study above, checkpointed every 1,000 steps (resuming from the newest when there is
#: one), its second run 100,000 steps long.
#: The study above checkpointed every 1,000 steps (resuming from the newest when there is one),
#: its second run 100,000 steps long.
CHECKPOINTED = (
    "    progress={PROGRESS},\n"
    '    restart=(1000, "restart", "restart.*.h5", any(Path("out/restart").glob("restart.*.h5"))),\n'
    "    threads=1,\n"
)
RESUMED = "from pathlib import Path\n" + (
    SCRIPT.replace("    progress={PROGRESS},\n", CHECKPOINTED)
    .replace("sim.run(500)", "sim.run(100000)")
    .replace("{PROGRESS}", '{"every": 1e-9, "steps": 101000}')
)


def test_a_resumed_script_counts_the_steps_before_its_checkpoint(tmp_path: Path) -> None:
    # killed in its second run, then run again: it resumes from a checkpoint of that run, and
    # its lines count the script's steps from the script's start and the run's from the run's
    (tmp_path / "study.py").write_text(RESUMED)
    child = subprocess.Popen([sys.executable, "study.py"], cwd=tmp_path, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not (tmp_path / "out/restart/restart.3000.h5").exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    child.kill()
    child.wait()
    (tmp_path / "out/pygran.log").rename(tmp_path / "first.log")
    subprocess.run([sys.executable, "study.py"], cwd=tmp_path, check=True, timeout=120, capture_output=True)
    log = (tmp_path / "out/pygran.log").read_text()
    resumed = int(re.search(r"resumed from .* at step (\d+)", log).group(1))
    assert 3000 <= resumed < 101000
    lines = re.findall(r"progress: step (\d+), run (\d+) of (\d+) .* script (\d+) of 101000 steps", log)
    assert lines
    for step, ran, total, script in (map(int, line) for line in lines):
        assert step > resumed and (ran, total, script) == (step - 1000, 100000, step)
    summary = re.search(r"run of (\d+) steps took", log.split("resumed from")[1])
    assert int(summary.group(1)) == 101000 - resumed
