"""pygran info and pygran convert on the real LIGGGHTS hopper run."""

import subprocess
import sys
from pathlib import Path

import numpy as np

from pygran_core.io import open_trajectory

PYGRAN = str(Path(sys.executable).with_name("pygran"))


def run(*args, cwd):
    return subprocess.run([PYGRAN, *args], capture_output=True, text=True, cwd=cwd)


def test_info_on_a_dump_glob(hopper):
    out = run("info", "particles*.dump", cwd=hopper)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.splitlines() == [
        "file:       particles*.dump (31 files)",
        "format:     dump",
        "frames:     31",
        "particles:  0 min, 571 max per frame",
        "columns:    id type x y z radius vx vy vz fx fy fz",
        "box:        [-0.001, 0.001] x [-0.001, 0.001] x [0, 0.004] (ff ff ff) (first frame)",
        "timesteps:  0 to 30000",
    ]
    assert out.stderr == ""  # no progress bar when not a terminal


def test_info_on_the_mesh_sequence(hopper):
    out = run("info", "mesh*.vtk", cwd=hopper)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "frames:     31" in out.stdout and "points:     960 min, 960 max per frame" in out.stdout
    assert "cells:      320 min, 320 max per frame" in out.stdout and "meshid v" in out.stdout


def test_convert_dump_glob_to_h5md_and_back(hopper, tmp_path):
    out = run(
        "convert",
        str(hopper / "particles*.dump"),
        str(tmp_path / "hopper.h5md"),
        "--units",
        "si",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip().endswith(
        "converted 31 frames from "
        + str(hopper / "particles*.dump")
        + " (dump) to "
        + str(tmp_path / "hopper.h5md")
        + " (h5md)"
    )
    assert out.stderr == ""
    info = run("info", "hopper.h5md", cwd=tmp_path)
    assert "format:     h5md" in info.stdout and "particles:  0 min, 571 max per frame" in info.stdout
    back = run("convert", "hopper.h5md", "back*.dump", cwd=tmp_path)
    assert back.returncode == 0, back.stdout + back.stderr
    assert len(list(tmp_path.glob("back*.dump"))) == 31
    original = open_trajectory(str(hopper / "particles*.dump"))
    for got, want in zip(open_trajectory(str(tmp_path / "back*.dump")), original):
        assert got.timestep == want.timestep
        for name, values in want.arrays.items():
            np.testing.assert_array_equal(got.arrays[name], values)


def test_convert_to_a_dump_with_its_time_block(hopper, tmp_path):
    """LIGGGHTS' dumps have no time; ``--option time=true`` keeps it, as LAMMPS' ``time yes``."""
    out = run(
        "convert",
        "particles1000.dump",
        str(tmp_path / "timed.dump"),
        "--dt",
        "1e-5",
        "--option",
        "time=true",
        cwd=hopper,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert (tmp_path / "timed.dump").read_text().startswith("ITEM: TIME\n0.01\nITEM: TIMESTEP\n1000\n")
    (frame,) = open_trajectory(str(tmp_path / "timed.dump"))
    assert frame.time == 0.01 and frame.timestep == 1000


def test_convert_into_a_new_folder_makes_it(hopper, tmp_path):
    out = run("convert", "particles*.dump", str(tmp_path / "frames" / "step*.dump"), cwd=hopper)
    assert out.returncode == 0, out.stdout + out.stderr
    assert len(list((tmp_path / "frames").glob("step*.dump"))) == 31


def test_errors_are_one_line_and_exit_1(hopper, tmp_path):
    missing = run("info", "nope.dump", cwd=tmp_path)
    assert missing.returncode == 1 and "pygran: error: File not found:" in missing.stderr
    (tmp_path / "bad.dump").write_text(
        (hopper / "particles1000.dump").read_text().replace(" 5e-05 ", " 5x-05 ", 1)
    )
    bad = run("convert", "bad.dump", "out.h5md", cwd=tmp_path)
    assert bad.returncode == 1
    assert "bad.dump: frame 0, line 10: column 'radius' holds '5x-05', not a number" in bad.stderr
    unknown = run("convert", "bad.dump", "out.xyz", cwd=tmp_path)
    assert unknown.returncode == 1 and "No installed writer for 'out.xyz'" in unknown.stderr
