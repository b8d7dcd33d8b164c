"""Conformance tests every trajectory format passes, in the style of MDAnalysis' reader tests.

A format's test module subclasses :class:`FormatConformance` once per case::

    class TestDump(FormatConformance):
        reader = "dump"
        writer = "dump"
        suffix = ".dump"

A writable format is tested by writing :meth:`sample_frames` and reading them back; a
read-only one overrides :meth:`make_sample` to create files with another tool and return
the frames they hold. :meth:`bad_files` lists damaged files and how many leading frames
must stay readable. For fuzz tests, :func:`damaged_copies` damages files at random
(:func:`mutate`) and :func:`fuzz_check` reads each in a child process (:func:`fuzz_read`).
Requires pytest.
"""

from __future__ import annotations

import importlib.util
import os
import random
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, NoReturn

import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.io import Frame, Trajectory, expand_paths, open_trajectory, open_writer
from pygran_core.registry import lookup
from pygran_core.testing.solvers import in_ci


def require_reader(module: str) -> None:
    """Check that ``module``, a tool users open our files with (MDAnalysis, pyvista, meshio,
    ovito), is installed (without importing it); if not, fail under CI, else skip naming the fix."""
    if importlib.util.find_spec(module) is None:
        message = f"{module} is not installed: pip install {module}"
        if in_ci():
            pytest.fail(f"CI=true and a reader is missing: {message}", pytrace=False)
        pytest.skip(message)


def particle_frames() -> list[Frame]:
    """Frames with a varying particle count, an empty frame and awkward float values."""
    rng = np.random.default_rng(7)
    frames = []
    for k, n in enumerate((5, 0, 12, 3)):
        ids = rng.permutation(100)[:n].astype(np.int64) + 1
        arrays: dict[str, np.ndarray] = {"id": ids, "type": rng.integers(1, 4, n).astype(np.int64)}
        for name in ("x", "y", "z", "radius", "vx", "vy", "vz", "fx", "fy", "fz", "c_stress[2]"):
            arrays[name] = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
        arrays["radius"] = np.abs(arrays["radius"])  # physically sane: radii are positive
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


def insane_samples() -> dict[str, list[Frame]]:
    """:func:`particle_frames` made physically impossible in one way each, by name."""

    def changed(change) -> list[Frame]:
        frames = particle_frames()
        change(frames)
        return frames

    def duplicate(frames: list[Frame]) -> None:
        frames[2].arrays["id"][1] = frames[2].arrays["id"][0]

    def zero_radius(frames: list[Frame]) -> None:
        frames[0].arrays["radius"][0] = 0.0

    def negative_radius(frames: list[Frame]) -> None:
        frames[3].arrays["radius"][1] *= -1

    def step_back(frames: list[Frame]) -> None:
        frames[2].timestep = 500

    return {
        "duplicate ids": changed(duplicate),
        "zero radius": changed(zero_radius),
        "negative radius": changed(negative_radius),
        "step back": changed(step_back),
    }


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


def mutate(rng: random.Random, original: bytes, alphabet: bytes) -> bytes:
    """``original`` with 1 to 4 random edits (a byte flipped, deleted or inserted from
    ``alphabet``, or the rest cut), drawn from ``rng``: input for fuzz tests."""
    mutated = bytearray(original)
    for _ in range(rng.randint(1, 4)):
        where = rng.randrange(len(mutated))
        action = rng.choice(("flip", "delete", "insert", "cut"))
        byte = rng.choice(alphabet)
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


@dataclass
class FuzzReport:
    """What reading each damaged file gave: a clean read, a ReadError, or a failure (another
    exception, a signal, a hang or a memory blow-up), by file."""

    clean: list[Path] = field(default_factory=list)
    read_errors: list[Path] = field(default_factory=list)
    failures: dict[Path, str] = field(default_factory=dict)

    def summary(self) -> str:
        return f"{len(self.clean)} clean, {len(self.read_errors)} ReadError, {len(self.failures)} failures"


_CLEAN, _READ_ERROR, _OTHER = 0, 3, 4


def _child(read: Callable[[Path], object], path: Path, report: int, memory: int) -> NoReturn:
    """In a forked child: read ``path``, write any error but ReadError to ``report``, exit."""
    code = _OTHER
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        if memory:
            import resource  # POSIX, as fork is

            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
        read(path)
        code = _CLEAN
    except ReadError:
        code = _READ_ERROR
    except BaseException as exc:  # noqa: BLE001 - every other outcome is what the test reports
        os.write(report, f"{type(exc).__name__}: {exc}"[:2000].encode("utf-8", "replace"))
    finally:
        os._exit(code)


def fuzz_read(
    read: Callable[[Path], object],
    paths: Sequence[Path],
    timeout: float = 10.0,
    workers: int = 2,
    memory: int = 2 << 30,
) -> FuzzReport:
    """Read each file with ``read`` in a child process forked from this (already imported)
    one, ``workers`` at a time: a child that raises anything but :class:`ReadError`, dies on
    a signal, runs past ``timeout`` seconds (killed) or needs ``memory`` bytes more address
    space than this process has is a failure. POSIX only (``os.fork``)."""
    base = _address_space()
    report = FuzzReport()
    todo = list(paths)
    running: dict[int, tuple[Path, float, int]] = {}
    while todo or running:
        while todo and len(running) < workers:
            path = todo.pop(0)
            read_end, write_end = os.pipe()
            pid = os.fork()
            if pid == 0:
                os.close(read_end)
                _child(read, path, write_end, base + memory if base and memory else 0)
            os.close(write_end)
            running[pid] = (path, time.monotonic() + timeout, read_end)
        finished = []
        for pid in running:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                finished.append((pid, status))
        if not finished:
            now = time.monotonic()
            for late, (path, deadline, _) in running.items():
                if now > deadline and path not in report.failures:
                    os.kill(late, signal.SIGKILL)
                    report.failures[path] = f"hung: killed after {timeout} s"
            time.sleep(0.0005)
        for pid, status in finished:
            path, _, pipe = running.pop(pid)
            text = _drain(pipe)
            if path in report.failures:
                continue
            if os.WIFSIGNALED(status):
                report.failures[path] = f"killed by signal {signal.Signals(os.WTERMSIG(status)).name}"
            elif os.WEXITSTATUS(status) == _CLEAN:
                report.clean.append(path)
            elif os.WEXITSTATUS(status) == _READ_ERROR:
                report.read_errors.append(path)
            else:
                report.failures[path] = text or f"exit status {os.WEXITSTATUS(status)}"
    return report


#: Every byte: the mutation alphabet of binary formats.
BYTES = bytes(range(256))


def damaged_copies(
    directory: Path, name: str, bases: Sequence[tuple[str, bytes, bytes]], count: int = 320
) -> list[Path]:
    """``count`` files in ``directory``, each a base file (name suffix, content, mutation
    alphabet; the bases taken in turn) damaged by :func:`mutate`, from a seed fixed by ``name``."""
    rng = random.Random(f"pygran-fuzz-{name}")
    paths = []
    for k in range(count):
        suffix, original, alphabet = bases[k % len(bases)]
        path = directory / f"{name}-{k}{suffix}"
        path.write_bytes(mutate(rng, original, alphabet))
        paths.append(path)
    return paths


def read_every_frame(path: Path) -> None:
    """What a user does with a file: open it and read every frame, each of which must be
    valid (:func:`assert_valid_frame`): a damaged file that reads cleanly must still make sense."""
    with open_trajectory(path) as trajectory:
        for frame in trajectory:
            assert_valid_frame(frame)


def assert_valid_frame(frame: Frame) -> None:
    """A mesh's cells index its points and its data fits them; a particle frame's columns
    are 1-D numbers of one length."""
    arrays = frame.arrays
    if frame.attrs.get("kind") == "mesh":
        points, cells = arrays["points"], arrays["cells"]
        assert points.ndim == 2 and points.shape[1] == 3 and cells.ndim == 2
        assert cells.size == 0 or (cells.max() < len(points) and cells.min() >= -1)
        assert len(arrays["cell_types"]) == len(cells)
        for name in frame.attrs["point_data"]:
            assert len(arrays[name]) == len(points), name
        for name in frame.attrs["cell_data"]:
            assert len(arrays[name]) == len(cells), name
    else:
        assert len({len(v) for v in arrays.values()}) <= 1, {k: len(v) for k, v in arrays.items()}
        for name, values in arrays.items():
            assert values.ndim == 1 and values.dtype.kind in "iuf", (name, values.dtype)


def fuzz_check(name: str, paths: Sequence[Path], read: Callable[[Path], object], good: Path) -> FuzzReport:
    """Read at least 300 damaged files with :func:`fuzz_read` and fail on anything but a clean
    read or a :class:`ReadError`; prints the counts. ``good`` (an intact file) is read here
    first, so that the children inherit what reading imports and need not import it each."""
    assert len(paths) >= 300, f"{len(paths)} files: a fuzz test reads at least 300"
    read(good)
    report = fuzz_read(read, paths)
    print(f"\nfuzz {name}: {report.summary()}")
    shown = "\n".join(f"{p.name}: {why}" for p, why in list(report.failures.items())[:10])
    assert not report.failures, f"{len(report.failures)} of {len(paths)} files:\n{shown}"
    assert report.read_errors, "no damaged file was refused: the damage does not reach the parser"
    return report


def _drain(pipe: int) -> str:
    chunks = []
    while chunk := os.read(pipe, 65536):
        chunks.append(chunk)
    os.close(pipe)
    return b"".join(chunks).decode("utf-8", "replace")


def _address_space() -> int:
    """This process's virtual memory size in bytes (0 where /proc is missing)."""
    try:
        with open("/proc/self/statm") as handle:
            return int(handle.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return 0


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
    #: Whether the reader refuses physically impossible frames (:func:`insane_samples`) with a
    #: ReadError, as every particle reader should (:mod:`pygran_core.formats.sanity`); False
    #: marks the known gap: the test is an expected failure, shown as such in every run.
    physical_checks: ClassVar[bool] = False
    #: Whether each frame's step comes from its file's name (YADE's VTKRecorder): a glob
    #: orders the files by it, so steps cannot go back and that case is not made.
    steps_from_file_names: ClassVar[bool] = False
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

    def make_insane(self, tmp_path: Path, name: str, frames: list[Frame]) -> str | Path:
        """A file holding ``frames``, physically impossible as they are (case ``name``); by
        default written with the format's writer. A format whose writer refuses such frames
        overrides this to put the values in place itself."""
        assert self.writer is not None, "a read-only format overrides make_insane"
        path = tmp_path / f"insane-{name.replace(' ', '-')}{self.suffix}"
        with open_writer(path, format=self.writer) as out:
            for frame in frames:
                out.write_frame(frame)
        return path

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

    def test_physical_sanity(self, tmp_path):
        """Duplicate ids, a zero or negative radius, steps that go back: a ReadError naming the
        file, never frames handed to analysis."""
        if "particles" not in lookup("reader", self.reader).spec.kinds:
            pytest.skip(f"the {self.reader} reader reads no particles")
        if not self.physical_checks:
            pytest.xfail(f"the {self.reader} reader does not check physical sanity yet")
        for name, frames in insane_samples().items():
            if name == "step back" and self.steps_from_file_names:
                continue
            pattern = self.make_insane(tmp_path, name, frames)
            with pytest.raises(ReadError) as info:
                with self.open(pattern) as trajectory:
                    for _ in trajectory:
                        pass
            names = [p.name for p in expand_paths(pattern)]
            assert any(n in str(info.value) for n in names), (name, str(info.value))

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
