"""Damaged files never crash or hang a reader: each of the core's formats (dump, .dump.gz,
H5MD, STL), damaged at random 320 times from a fixed seed, read in a child process with a
time limit; every read gives a clean result or a ReadError. So do hostile values (counts
beyond every integer type, NaN, 1e308) put in place of each number of a header. Checkpoints
are fuzzed in test_checkpoint.py, VTK formats in the pygran-readers tests."""

from __future__ import annotations

import gzip
import os
import re
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
    fuzz_read,
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


#: Numbers an outsider's file may hold where a count, a step, a bound or a coordinate stands:
#: beyond every integer type, negative, beyond the float range, not a number.
HOSTILE = (b"10000000000000000000", b"9223372036854775808", b"18446744073709551616", b"4294967295")
HOSTILE += (b"-1", b"1e308", b"-1e400", b"nan", b"inf", b"9" * 40)
NUMBER = re.compile(rb"(?<![\w.+-])[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?(?![\w.])")


def hostile_copies(directory: Path, name: str, original: bytes, upto: int) -> dict[Path, int]:
    """The mutation kind of hostile values: each number before byte ``upto`` of ``original``
    (counts, steps, box bounds, coordinates) replaced by each of :data:`HOSTILE`; the files,
    with where the number stood."""
    paths = {}
    for k, found in enumerate(m for m in NUMBER.finditer(original) if m.start() < upto):
        for j, value in enumerate(HOSTILE):
            path = directory / f"{name}-{k}-{j}{Path(name).suffix}"
            path.write_bytes(original[: found.start()] + value + original[found.end() :])
            paths[path] = found.start()
    return paths


def test_hostile_values(tmp_path, data_dir):
    """The audit's 10^19 atoms (an OverflowError before), and the same lies in every other
    number of a dump's header and of an STL file's first facet: a ReadError or a clean read,
    in a child with a time and a memory limit, never a crash. Every lie about the atom count
    and a binary STL declaring 2^32 - 1 triangles are ReadErrors."""
    dump = dump_bytes()
    ascii_stl, binary_stl = (base for _, base, _ in stl_files(data_dir))
    header = dump.index(b"ITEM: ATOMS")
    paths = hostile_copies(tmp_path, "hostile.dump", dump, header)
    atoms = [p for p, at in paths.items() if at == dump.index(b"ITEM: NUMBER OF ATOMS\n") + 22]
    paths |= hostile_copies(tmp_path, "hostile.stl", ascii_stl, ascii_stl.index(b"endloop"))
    count = tmp_path / "hostile-count.stl"
    count.write_bytes(binary_stl[:80] + np.uint32(2**32 - 1).tobytes() + binary_stl[84:])
    report = fuzz_read(read_every_frame, [*paths, count])
    print(f"\nhostile values: {report.summary()}")
    shown = "\n".join(f"{p.name}: {why}" for p, why in list(report.failures.items())[:10])
    assert not report.failures, f"{len(report.failures)} of {len(paths) + 1} files:\n{shown}"
    assert len(atoms) == len(HOSTILE) and set(atoms) | {count} <= set(report.read_errors)
