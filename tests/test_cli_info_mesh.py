"""``pygran info`` on meshes: triangles, bounds and watertightness of every STL in
tests/data/meshes, as its README says; and a quiet exit when the reader of the output leaves
(``pygran info ... | head``) (issue 44, items 1 and 4)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pygran_core.cli import main

MESHES = Path(__file__).resolve().parent / "data" / "meshes"

#: file -> (triangles, bounds line, closed line start), as tests/data/meshes/README.md gives them
EXPECTED = {
    "silo.stl": (224, "[-1, 1] x [-1, 1] x [0, 3]", "no (32 open edges"),
    "valve.stl": (96, "[-0.5, 0.5] x [-0.5, 0.5] x [0.5, 0.5]", "no (24 open edges"),
    "square.stl": (40, "[-1, 1] x [-1, 1] x [3, 3]", "no (16 open edges"),
    "tumbler.stl": (
        1780,
        "[-762, 761.092] x [-602.432, 697.992] x [-761.923, 761.923]",
        "yes (volume 1.84695e+09",
    ),
    "wall-2D-side.stl": (88, "[-2, 2] x [-1, 1] x [1, 1]", "no (24 open edges"),
}


def test_every_mesh_of_the_test_data_is_described() -> None:
    readme = (MESHES / "README.md").read_text()
    assert sorted(p.name for p in MESHES.glob("*.stl")) == sorted(EXPECTED)
    for name, (count, _, _) in EXPECTED.items():
        assert f"| `{name}` | {count} |" in readme


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_info_prints_bounds_triangles_and_closedness(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(MESHES / name)]) == 0
    lines = dict(line.split(":", 1) for line in capsys.readouterr().out.splitlines())
    count, bounds, closed = EXPECTED[name]
    assert lines["triangles"].strip() == f"{count} (first frame)"
    assert lines["bounds"].strip() == f"{bounds} (first frame)"
    assert lines["closed"].strip().startswith(closed)


def test_a_closed_pipe_ends_the_command_quietly() -> None:
    pygran = shutil.which("pygran", path=str(Path(sys.executable).parent))
    assert pygran is not None
    read, write = os.pipe()
    os.close(read)  # the reader is gone before anything is written, as after `head` exits
    try:
        done = subprocess.run(
            [pygran, "info", str(MESHES / "tumbler.stl")], stdout=write, stderr=subprocess.PIPE, timeout=60
        )
    finally:
        os.close(write)
    assert b"Traceback" not in done.stderr and b"BrokenPipeError" not in done.stderr
    assert done.returncode == 141  # 128 + SIGPIPE, as a C tool killed by the signal reports
