"""Damaged files never crash or hang a reader: each of the core's formats (dump, .dump.gz,
H5MD, STL), damaged at random 320 times from a fixed seed, read in a child process with a
time limit; every read gives a clean result or a ReadError. Checkpoints are fuzzed in
test_checkpoint.py, VTK formats in the pygran-readers tests."""

from __future__ import annotations

import gzip
import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from pygran_core.formats.dump import format_frame
from pygran_core.io import open_trajectory, open_writer
from pygran_core.testing.formats import (
    BYTES,
    damaged_copies,
    fuzz_check,
    particle_frames,
    read_every_frame,
)

TEXT = b"0123456789 .-+eE\n\tx:ITEMATOMS"


def dump_bytes() -> bytes:
    return "".join(format_frame(frame, k) for k, frame in enumerate(particle_frames())).encode()


def test_dump(tmp_path):
    good = tmp_path / "good.dump"
    good.write_bytes(dump_bytes())
    fuzz_check(
        "dump", damaged_copies(tmp_path, "dump", [(".dump", dump_bytes(), TEXT)]), read_every_frame, good
    )


def test_dump_gz(tmp_path):
    """Damaged compressed bytes, and damaged text compressed intact."""
    good = tmp_path / "good.dump.gz"
    good.write_bytes(gzip.compress(dump_bytes(), mtime=0))
    paths = damaged_copies(tmp_path, "dump.gz", [(".dump.gz", good.read_bytes(), BYTES)], 160)
    for path in damaged_copies(tmp_path, "dump-text", [(".dump.gz", dump_bytes(), TEXT)], 160):
        path.write_bytes(gzip.compress(path.read_bytes(), mtime=0))
        paths.append(path)
    fuzz_check("dump.gz", paths, read_every_frame, good)


def h5md_files(tmp_path: Path) -> list[Path]:
    """An H5MD trajectory closed properly, and one whose writer was killed mid-run (the file
    is still marked open for writing, and is read in SWMR mode)."""
    closed, killed = tmp_path / "closed.h5", tmp_path / "killed.h5"
    with open_writer(closed) as out:
        for frame in particle_frames():
            out.write_frame(frame)
    pid = os.fork()
    if pid == 0:  # the killed writer: exits without closing the file
        out = open_writer(killed)
        for frame in particle_frames():
            out.write_frame(frame)
        os._exit(0)
    os.waitpid(pid, 0)
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(killed, "r")
    return [closed, killed]


def test_h5md(tmp_path):
    closed, killed = h5md_files(tmp_path)
    bases = [(".h5", path.read_bytes(), BYTES) for path in (closed, killed)]
    report = fuzz_check("h5md", damaged_copies(tmp_path, "h5md", bases), read_every_frame, killed)
    killed = [p for p in report.clean if int(p.stem.split("-")[1]) % 2]
    assert killed, "no damaged killed-writer file was still read"


def stl_files(data_dir: Path) -> list[tuple[str, bytes, bytes]]:
    text = (data_dir / "meshes" / "square.stl").read_bytes()
    frame = open_trajectory(data_dir / "meshes" / "square.stl")[0]
    vertices = frame.arrays["points"][frame.arrays["cells"]]
    records = np.zeros(len(vertices), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    records["v"] = vertices
    binary = b"solid binary".ljust(80) + np.uint32(len(records)).tobytes() + records.tobytes()
    return [(".stl", text, TEXT + b"solidfacetvrx"), (".stl", binary, BYTES)]


def test_stl(tmp_path, data_dir):
    fuzz_check(
        "stl",
        damaged_copies(tmp_path, "stl", stl_files(data_dir)),
        read_every_frame,
        data_dir / "meshes" / "square.stl",
    )
