"""Conformance tests every trajectory format passes, in the style of MDAnalysis' reader tests.

A format's test module subclasses :class:`FormatConformance` once per case::

    class TestDump(FormatConformance):
        reader = "dump"
        writer = "dump"
        suffix = ".dump"

A writable format is tested by writing :meth:`sample_frames` and reading them back; a
read-only one overrides :meth:`make_sample` to create files with another tool and return
the frames they hold. :meth:`bad_files` lists damaged files and how many leading frames
must stay readable. Requires pytest.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.io import Frame, Trajectory, expand_paths, open_trajectory, open_writer


def particle_frames() -> list[Frame]:
    """Frames with a varying particle count, an empty frame and awkward float values."""
    rng = np.random.default_rng(7)
    frames = []
    for k, n in enumerate((5, 0, 12, 3)):
        ids = rng.permutation(100)[:n].astype(np.int64) + 1
        arrays: dict[str, np.ndarray] = {"id": ids, "type": rng.integers(1, 4, n).astype(np.int64)}
        for name in ("x", "y", "z", "radius", "vx", "vy", "vz", "fx", "fy", "fz", "c_stress[2]"):
            arrays[name] = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
        if n:
            arrays["x"][0] = 1 / 3
            arrays["vx"][-1] = -0.0
        frames.append(
            Frame(
                arrays,
                timestep=1000 * k,
                box=np.array([[-1.0, 1.0], [-2.0, 2.0], [0.0, 0.1 * (k + 1)]]),
                boundary=("pp", "ff", "fm"),
            )
        )
    return frames


def assert_frames_equal(
    actual: Frame,
    expected: Frame,
    exact: bool = True,
    meta: tuple[str, ...] = ("timestep", "boundary", "box"),
) -> None:
    """Same columns in the same order, integer columns equal, floats bitwise (or close), and the
    metadata named in ``meta`` equal."""
    assert list(actual.arrays) == list(expected.arrays), (list(actual.arrays), list(expected.arrays))
    for name, want in expected.arrays.items():
        got = np.asarray(actual.arrays[name])
        want = np.asarray(want)
        assert got.shape == want.shape, (name, got.shape, want.shape)
        if want.dtype.kind in "iu":
            assert got.dtype.kind in "iu", (name, got.dtype)
            np.testing.assert_array_equal(got, want, err_msg=name)
        elif exact:
            same = got.astype(np.float64).view(np.int64) == want.astype(np.float64).view(np.int64)
            assert same.all(), f"{name}: {got[~same]} != {want[~same]}"
        else:
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=0, err_msg=name)
    if "timestep" in meta:
        assert actual.timestep == expected.timestep
    if "time" in meta:
        assert actual.time == expected.time
    if "boundary" in meta:
        assert actual.boundary == expected.boundary
    if "box" in meta:
        if expected.box is None:
            assert actual.box is None
        else:
            np.testing.assert_array_equal(actual.box, expected.box)


def mutate(data: Any, original: bytes, alphabet: bytes) -> bytes:
    """``original`` with 1 to 4 random edits (a byte flipped, deleted or inserted from
    ``alphabet``, or the rest cut), drawn with hypothesis' ``data``: input for fuzz tests."""
    from hypothesis import strategies as st

    mutated = bytearray(original)
    for _ in range(data.draw(st.integers(1, 4))):
        where = data.draw(st.integers(0, len(mutated) - 1))
        action = data.draw(st.sampled_from(["flip", "delete", "insert", "cut"]))
        byte = data.draw(st.sampled_from(list(alphabet)))
        if action == "flip":
            mutated[where] = byte
        elif action == "delete":
            del mutated[where]
        elif action == "insert":
            mutated.insert(where, byte)
        else:
            del mutated[where:]
        if not mutated:
            mutated = bytearray(b" ")
    return bytes(mutated)


def frame_size(frame: Frame) -> int:
    """Particles (or mesh points) in a frame."""
    if "points" in frame.arrays:
        return len(frame.arrays["points"])
    return len(next(iter(frame.arrays.values()))) if frame.arrays else 0


class FormatConformance:
    """Base class of a format's conformance tests; see the module docstring."""

    reader: ClassVar[str]
    writer: ClassVar[str | None] = None
    suffix: ClassVar[str]
    exact: ClassVar[bool] = True  # floats read back bitwise
    #: Frame metadata the format keeps; a read-only format's samples keep none.
    metadata: ClassVar[tuple[str, ...]] = ("timestep", "boundary", "box")
    # A format that cannot hold an empty frame sets ``test_empty_frame = None``.

    # -- what a subclass provides ----------------------------------------------------------
    def sample_frames(self) -> list[Frame]:
        return particle_frames()

    def make_sample(self, tmp_path: Path) -> tuple[str | Path, list[Frame]]:
        """Create sample files; return the pattern to open and the frames it must give."""
        assert self.writer is not None, "a read-only format overrides make_sample"
        path = tmp_path / f"sample{self.suffix}"
        frames = self.sample_frames()
        with open_writer(path, format=self.writer) as out:
            for frame in frames:
                out.write_frame(frame)
        return path, frames

    def bad_files(self, tmp_path: Path) -> list[tuple[str | Path, int]]:
        """Damaged inputs, each with the number of leading frames that must stay readable."""
        garbage = tmp_path / f"garbage{self.suffix}"
        garbage.write_bytes(bytes(range(256)) * 4)
        return [(garbage, 0)]

    def open(self, pattern: str | Path) -> Trajectory:
        return open_trajectory(pattern, format=self.reader)

    # -- the tests ---------------------------------------------------------------------------
    def test_round_trip(self, tmp_path):
        pattern, frames = self.make_sample(tmp_path)
        with self.open(pattern) as trajectory:
            assert len(trajectory) == len(frames)
            for got, want in zip(trajectory, frames):
                assert_frames_equal(got, want, exact=self.exact, meta=self.metadata if self.writer else ())

    def test_random_access_equals_sequential(self, tmp_path):
        pattern, frames = self.make_sample(tmp_path)
        with self.open(pattern) as trajectory:
            sequential = list(trajectory)
            order = list(range(len(frames))) * 2
            random.Random(3).shuffle(order)
            for index in order:
                assert_frames_equal(trajectory[index], sequential[index])
            assert_frames_equal(trajectory[-1], sequential[-1])

    def test_varying_size(self, tmp_path):
        pattern, frames = self.make_sample(tmp_path)
        with self.open(pattern) as trajectory:
            sizes = [frame_size(f) for f in trajectory]
        assert sizes == [frame_size(f) for f in frames]
        assert len(set(sizes)) > 1, "the sample must vary in size"

    def test_empty_frame(self, tmp_path):
        pattern, frames = self.make_sample(tmp_path)
        empty = [i for i, f in enumerate(frames) if frame_size(f) == 0]
        assert empty, "the sample must include an empty frame"
        with self.open(pattern) as trajectory:
            for index in empty:
                frame = trajectory[index]
                assert frame_size(frame) == 0
                assert list(frame.arrays) == list(frames[index].arrays)

    def test_out_of_range(self, tmp_path):
        pattern, frames = self.make_sample(tmp_path)
        with self.open(pattern) as trajectory, pytest.raises(IndexError):
            trajectory[len(frames)]

    def test_missing_file(self, tmp_path):
        with pytest.raises(ReadError, match="not found"):
            self.open(tmp_path / f"missing{self.suffix}")

    def test_bad_input(self, tmp_path):
        for pattern, good in self.bad_files(tmp_path):
            try:
                trajectory = self.open(pattern)
            except ReadError as exc:
                assert good == 0, f"{pattern}: {exc}"
                continue
            with trajectory:
                for index in range(good):
                    trajectory[index]
                with pytest.raises(ReadError) as info:
                    for index in range(good, len(trajectory)):
                        trajectory[index]
                    pytest.fail(f"{pattern}: no ReadError after frame {good}")
                names = [p.name for p in expand_paths(pattern)]
                assert any(name in str(info.value) for name in names), (names, str(info.value))
