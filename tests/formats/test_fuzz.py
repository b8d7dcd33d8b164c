"""Damaged files never crash or hang a reader: each of the core's formats (dump, .dump.gz,
H5MD, STL) and checkpoints, damaged at random 320 times from a fixed seed, read in a child
process with a time limit; every read gives a clean result or a ReadError."""

from __future__ import annotations

import gzip
import os
import random
from pathlib import Path

import h5py
import numpy as np
import pytest

from pygran_core.formats.dump import format_frame
from pygran_core.io import open_trajectory, open_writer
from pygran_core.simulation.checkpoint import Checkpoint, encode_text, read_checkpoint, write_checkpoint
from pygran_core.testing.formats import (
    BYTES,
    damaged_copies,
    fuzz_check,
    mutate,
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


def sample_checkpoint() -> Checkpoint:
    """A checkpoint shaped like an engine's: journal, facts, monitors, per-particle state."""
    rng = np.random.default_rng(3)
    n = 40
    journal = [[f"create CreateSpec(species=1, n={n}, region='µ-box')", n], ["run 1000 1e-06", None]]
    return Checkpoint(
        engine="native",
        step=1000,
        time=1e-3,
        dt=1e-6,
        journal=journal,
        monitors={0: rng.random((11, 4))},
        state={
            "clock": np.array([1000, 1e-3]),
            "solver/core_x": rng.random(3 * n),
            "solver/core_r": np.full(n, 1e-3),
            "solver/core_type": np.ones(n, np.int32),
            "solver/core_id": np.arange(n, dtype=np.int64),
            "solver/core_nb_s": np.zeros(7, np.uint8),
            "solver/rng": encode_text('{"state": 12}'),
        },
        facts={"threads": 2},
    )


def structural_damage(path: Path, rng: random.Random) -> None:
    """Rewrite one part of a checkpoint with h5py: a broken journal or facts text, a state
    array of another dtype or shape, a bad attribute; half of the time as a version-1 file
    (no digest), so that the structural checks alone must refuse it."""
    with h5py.File(path, "r+") as f:
        part = rng.choice(["journal", "facts", "state", "attr", "monitor"])
        if part in ("journal", "facts"):
            text = f[part][()].tobytes()
            del f[part]
            f[part] = np.frombuffer(mutate(rng, text, b'[]{}",:\xc3\xa9\xff0a'), np.uint8)
        elif part == "state":
            name = rng.choice(_state_names(f))
            old = f["state"][name][()]
            del f["state"][name]
            f["state"][name] = rng.choice(
                [
                    old.astype(np.int8),
                    np.concatenate([old, old]),
                    old.reshape(1, -1),
                    np.array(["text"] * max(len(old), 1), dtype=h5py.string_dtype()),
                    np.zeros(len(old), dtype=[("a", "<f8"), ("b", "<i4")]),
                    np.float64(3.0),
                ]
            )
        elif part == "attr":
            key = rng.choice(["step", "time", "dt", "engine", "version", "format"])
            f.attrs[key] = rng.choice([-5, 1.5, "abc", np.nan, 2**40, np.array([1, 2])])
        else:
            del f["monitors/0"]
            f["monitors/0"] = rng.choice([np.arange(3.0), np.array(["x"], dtype=h5py.string_dtype())])
        if rng.random() < 0.5:  # as a version-1 checkpoint, written before digests
            f.attrs.pop("digest", None)
            f.attrs["version"] = 1


def _state_names(f: h5py.File) -> list[str]:
    names: list[str] = []
    f["state"].visititems(lambda name, item: names.append(name) if isinstance(item, h5py.Dataset) else None)
    return sorted(names)


def test_checkpoint(tmp_path):
    """Byte damage to the HDF5 file, and structural damage written with h5py."""
    original = tmp_path / "restart.h5"
    write_checkpoint(original, sample_checkpoint())
    assert read_checkpoint(original).journal == sample_checkpoint().journal
    paths = damaged_copies(tmp_path, "checkpoint", [(".h5", original.read_bytes(), BYTES)], 160)
    rng = random.Random(11)
    for k in range(160):
        path = tmp_path / f"structural-{k}.h5"
        path.write_bytes(original.read_bytes())
        structural_damage(path, rng)
        paths.append(path)
    fuzz_check("checkpoint", paths, read_checkpoint, original)
