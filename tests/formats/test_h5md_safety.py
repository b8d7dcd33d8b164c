"""H5MD files from elsewhere cannot reach outside themselves nor lie about their contents, and
writing one survives a full disk and a second writer: each case gives one PyGranError naming
the file, and no earlier frame is lost."""

from __future__ import annotations

import random
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from pygran_core import analysis
from pygran_core.errors import ReadError, WriteError
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.simulation.checkpoint import read_checkpoint
from pygran_core.testing.formats import damaged_copies, fuzz_check, fuzz_read, read_every_frame

SECRET = b"root:x:0:0:root:/root:/bin/bash\n" * 8
VALUE = "particles/trajectory/position/value"


def _frames() -> list[Frame]:
    rng = np.random.default_rng(5)
    frames = []
    for k, ids in enumerate(([1, 2, 3, 4], [1, 2, 3, 4], [2, 3, 4, 5])):
        n = len(ids)
        arrays = {"id": np.array(ids), "type": np.ones(n, dtype=np.int64)}
        arrays |= {c: rng.random(n) for c in ("x", "y", "z", "vx", "vy", "vz")}
        arrays["radius"] = np.full(n, 1e-3)
        frames.append(Frame(arrays, timestep=100 * k, time=1e-3 * k))
    return frames


@pytest.fixture
def good(tmp_path) -> Path:
    path = tmp_path / "good.h5md"
    with open_writer(path, xdmf=False) as out:
        for frame in _frames():
            out.write_frame(frame)
    (tmp_path / "secret.bin").write_bytes(SECRET)
    return path


def _replace(f: h5py.File, name: str, **dataset) -> None:
    del f[name]
    f.create_dataset(name, **dataset)


def _external_link(f, path):
    del f[VALUE]
    f[VALUE] = h5py.ExternalLink(str(path.parent / "other.h5"), "/data")


def _external_storage(f, path):
    _replace(f, VALUE, shape=(3, 1, 3), dtype="<f8", external=[(str(path.parent / "secret.bin"), 0, 72)])


def _virtual(f, path):
    layout = h5py.VirtualLayout(shape=(3, 5, 3), dtype="<f8")
    layout[:] = h5py.VirtualSource(str(path.parent / "other.h5"), "/data", shape=(3, 5, 3))
    del f[VALUE]
    f.create_virtual_dataset(VALUE, layout)


def _soft_to_external(f, path):
    f["parameters/elsewhere"] = h5py.ExternalLink(str(path.parent / "other.h5"), "/data")
    del f[VALUE]
    f[VALUE] = h5py.SoftLink("/parameters/elsewhere")


def _unrelated_external(f, path):
    f["parameters/notes"] = h5py.ExternalLink("/etc/passwd", "/")


OUTSIDE: dict[str, Callable[[h5py.File, Path], None]] = {
    "external link": _external_link,
    "external storage": _external_storage,
    "virtual dataset": _virtual,
    "soft link to an external link": _soft_to_external,
    "an external link anywhere": _unrelated_external,
}


@pytest.mark.parametrize("case", OUTSIDE)
def test_a_file_that_reaches_outside_itself_is_refused(good, case):
    with h5py.File(good.parent / "other.h5", "w") as other:
        other["data"] = np.full((3, 5, 3), 7.0)
    with h5py.File(good, "a") as f:
        OUTSIDE[case](f, good)
    with pytest.raises(ReadError, match=r"good\.h5md: refused: the file reaches outside itself"):
        open_trajectory(good)
    with pytest.raises(ReadError, match="reaches outside"):
        analysis.System(Particles=str(good))


def test_a_checkpoint_that_reaches_outside_itself_is_refused(tmp_path):
    path = tmp_path / "restart.h5"
    with h5py.File(path, "w") as f:  # an old, unsealed checkpoint layout
        f.attrs.update({"format": "pygran-checkpoint", "version": 1, "engine": "native"})
        f.attrs.update({"step": 0, "time": 0.0, "dt": 1e-6})
        f.create_dataset("state/clock", shape=(2,), dtype="<f8", external=[(str(tmp_path / "x.bin"), 0, 16)])
    (tmp_path / "x.bin").write_bytes(np.array([0.0, 0.0]).tobytes())
    with pytest.raises(ReadError, match=r"restart\.h5: refused: the file reaches outside itself"):
        read_checkpoint(path)


def _set(name: str, data: Callable[[np.ndarray], np.ndarray]) -> Callable[[h5py.File], None]:
    def change(f: h5py.File) -> None:
        value = f[name][()]
        _replace(f, name, data=data(value), maxshape=(None,) * value.ndim)

    return change


def _shape(name: str, shape: tuple[int, ...], dtype="<f8", **options) -> Callable[[h5py.File], None]:
    def change(f: h5py.File) -> None:
        _replace(f, name, shape=shape, dtype=dtype, **options)

    return change


def _poke(name: str, index, value) -> Callable[[h5py.File], None]:
    """Change one value of a dataset in place (a shared step or time changes for every element)."""

    def change(f: h5py.File) -> None:
        f[name][index] = value

    return change


def _unit(name: str, unit: str) -> Callable[[h5py.File], None]:
    def change(f: h5py.File) -> None:
        f[name].attrs["unit"] = unit

    return change


P = "particles/trajectory"
#: Files that lie, as an outside audit found them accepted: what is changed, and the refusal.
LIES: dict[str, tuple[Callable[[h5py.File], None], str]] = {
    "ids for 5 of 20 particles": (
        lambda f: _replace(f, f"{P}/position/value", data=np.zeros((3, 20, 3))),
        r"position/value holds 20 particles per frame, but .* holds 5",
    ),
    "positions of 2 components": (_shape(f"{P}/position/value", (3, 5, 2)), "needs 3 components"),
    "velocities of 4 components": (_shape(f"{P}/velocity/value", (3, 5, 4)), "needs 3 components"),
    "a sparse (1, 10^8, 3) shell": (
        lambda f: [
            _shape(f"{P}/{name}/value", (3, 10**8, *tail), dtype=dtype, chunks=(1, 65536, *tail))(f)
            for name, tail, dtype in (
                ("position", (3,), "<f8"),
                ("velocity", (3,), "<f8"),
                ("radius", (), "<f8"),
                ("id", (), "<i8"),
                ("species", (), "<i8"),
                ("pygran_order", (), "<i8"),
            )
        ],
        "sparse shell",
    ),
    "an unallocated contiguous array": (_shape(f"{P}/radius/value", (3, 5)), "sparse shell"),
    "a zero radius": (
        _poke(f"{P}/radius/value", (1, 2), 0.0),
        "frame 1: 1 particles have a radius that is not positive",
    ),
    "a negative radius": (_poke(f"{P}/radius/value", (0, 0), -1e-3), "radius that is not positive"),
    "a NaN radius": (_poke(f"{P}/radius/value", (2, 1), np.nan), "radius that is not positive"),
    "duplicate ids": (
        _poke(f"{P}/id/value", (2, 1), 3),
        r"frame 2: 1 ids appear more than once \(such as 3\)",
    ),
    "decreasing steps": (_poke(f"{P}/position/step", 2, 50), "step 50 follows step 100"),
    "a repeated step": (_poke(f"{P}/position/step", 1, 0), "step 0 follows step 0"),
    "decreasing times": (_poke(f"{P}/position/time", 2, 0.0), "times decrease"),
    "float ids": (_set(f"{P}/id/value", lambda a: a.astype(float)), "id must be integers"),
    "text positions": (_shape(f"{P}/position/value", (3, 5, 3), dtype="S8"), "type"),
    "a count that disagrees with the ids": (
        _poke("observables/trajectory/particle_number/value", 1, 3),
        "3 particles counted, but 4 rows have an id",
    ),
    "positions in kilograms": (_unit(f"{P}/position/value", "kg"), r"unit 'kg' of position has dimension"),
    "an unknown unit": (_unit(f"{P}/velocity/value", "furlong fortnight-1"), "unknown unit symbol 'furlong'"),
    "an order that is no permutation": (
        _poke(f"{P}/pygran_order/value", (0, 1), 0),
        "is not an order of its 4 particles",
    ),
}


@pytest.mark.parametrize("case", LIES)
def test_a_file_that_lies_is_refused(good, case):
    change, message = LIES[case]
    with h5py.File(good, "a") as f:
        change(f)
    with pytest.raises(ReadError, match=r"good\.h5md: ") as info:
        read_every_frame(good)
    assert info.match(message)


def test_identity_rows_read_back_as_written(good):
    """The fixture's frames: 5 arrives in the third frame while 1 leaves; rows 0-4 are ids 1-5."""
    with h5py.File(good) as f:
        assert f[f"{P}/id/value"][:].tolist() == [[1, 2, 3, 4, -1], [1, 2, 3, 4, -1], [-1, 2, 3, 4, 5]]
    for got, want in zip(open_trajectory(good), _frames()):
        assert list(got.arrays) == list(want.arrays)
        for name, values in want.arrays.items():
            np.testing.assert_array_equal(got.arrays[name], values)


def _mutations(good: Path, directory: Path, count: int) -> list[Path]:
    """``count`` copies of ``good``, each changed by one to three of the kinds above, drawn
    from a fixed seed: the H5MD mutation kinds of the fuzz."""
    kinds = [change for change, _ in LIES.values()]
    rng = random.Random("pygran-fuzz-h5md-structure")
    paths = []
    for k in range(count):
        path = directory / f"mutant-{k}.h5md"
        path.write_bytes(good.read_bytes())
        with h5py.File(path, "a") as f:
            for change in rng.sample(kinds, rng.randint(1, 3)):
                try:
                    change(f)
                except KeyError:  # an earlier change removed what this one changes
                    pass
        paths.append(path)
    return paths


def test_fuzz_structural_lies_are_read_errors(good, tmp_path):
    paths = _mutations(good, tmp_path, 48)
    read_every_frame(good)
    report = fuzz_read(read_every_frame, paths)
    assert not report.failures, report.failures
    assert not report.clean, report.clean
    assert len(report.read_errors) == len(paths)


WRITE_UNTIL_FULL = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    from pygran_core.errors import PyGranError
    from pygran_core.io import Frame, open_writer

    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))
    rng = np.random.default_rng(11)
    written = 0
    try:
        with open_writer(sys.argv[1]) as out:
            for k in range(1000):
                n = 4000
                arrays = {"id": np.arange(1, n + 1), "radius": np.full(n, 1e-3)}
                arrays |= {c: rng.random(n) for c in ("x", "y", "z", "vx", "vy", "vz")}
                out.write_frame(Frame(arrays, timestep=k, time=k * 1e-4))
                written += 1
    except PyGranError as exc:
        print(type(exc).__name__, written, exc, flush=True)
""")


def test_a_full_disk_stops_the_writer_with_one_error_and_every_earlier_frame_readable(tmp_path):
    path = tmp_path / "full.h5md"
    done = subprocess.run(
        [sys.executable, "-c", WRITE_UNTIL_FULL, str(path)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr  # no crash at exit (SIGBUS, SIGSEGV)
    kind, written, message = done.stdout.strip().split(" ", 2)
    assert kind == "WriteError" and "no space for the next frame (File too large)" in message
    assert message.startswith((str(path), str(tmp_path / "full.xdmf.h5")))  # the file that filled up
    assert int(written) >= 3 and done.stderr == ""
    rng = np.random.default_rng(11)
    with open_trajectory(path) as trajectory:
        assert len(trajectory) >= int(written)
        for k in range(int(written)):
            frame = trajectory[k]
            assert frame.timestep == k and frame.time == k * 1e-4
            for c in ("x", "y", "z", "vx", "vy", "vz"):
                np.testing.assert_array_equal(frame.arrays[c], rng.random(4000))


def test_a_second_writer_of_a_file_is_refused_and_the_first_one_keeps_its_file(tmp_path):
    path = tmp_path / "t.h5md"
    first = open_writer(path)
    frames = _frames()
    first.write_frame(frames[0])
    second = open_writer(path)
    with pytest.raises(WriteError, match=r"t\.h5md is being written by another writer"):
        second.write_frame(frames[1])
    first.write_frame(frames[1])
    first.close()
    second.close()
    assert [f.timestep for f in open_trajectory(path)] == [0, 100]


HOLD = textwrap.dedent("""
    import sys, time
    import numpy as np
    from pygran_core.io import Frame, open_writer

    with open_writer(sys.argv[1]) as out:
        out.write_frame(Frame({"id": np.array([1]), "x": np.array([0.5])}, timestep=0))
        print("written", flush=True)
        sys.stdin.readline()
        out.write_frame(Frame({"id": np.array([1]), "x": np.array([0.7])}, timestep=1))
""")


def test_a_writer_in_another_process_keeps_its_file(tmp_path):
    path = tmp_path / "t.h5md"
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "written"
        with pytest.raises(WriteError, match="being written by another writer"):
            with open_writer(path) as out:
                out.write_frame(Frame({"id": np.array([9]), "x": np.array([9.0])}, timestep=5))
        proc.stdin.write("\n")
        proc.stdin.flush()
        assert proc.wait(timeout=60) == 0
    finally:
        proc.kill()
        proc.stdin.close()
        proc.stdout.close()
    assert [f.arrays["x"].tolist() for f in open_trajectory(path)] == [[0.5], [0.7]]


def test_fuzz_damaged_xdmf_sidecars(tmp_path):
    """The XDMF sidecar's bytes damaged at random: each read is clean or a ReadError."""
    with open_writer(tmp_path / "good.h5md") as out:
        for frame in _frames():
            out.write_frame(frame)
    good = tmp_path / "good.xdmf"
    text = b"0123456789 .-+eE\n<>/=\"':abcdefghijklmnopqrstuvwxyz"
    copies = damaged_copies(tmp_path, "xdmf", [(".xdmf", good.read_bytes(), text)])
    fuzz_check("xdmf", copies, read_every_frame, good)


RUN_UNTIL_FULL = textwrap.dedent("""
    import resource, signal, sys, warnings
    from pygran_core import params, simulation
    from pygran_core.errors import PyGranError
    from pygran_core.simulation.models import HertzMindlin

    warnings.simplefilter("ignore")
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))
    try:
        with simulation.DEM(
            engine="native", model=HertzMindlin, box=(0, 0.02, 0, 0.02, 0, 0.02),
            species=({"material": dict(params.organic), "radius": 4e-4},), output=sys.argv[1],
            traj={"pfile": "traj.h5md", "freq": 10}, progress=False, dt=2e-6, threads=1, seed=1,
        ) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            sim.insert(species=1, value=2000, region=("block", 0.001, 0.019, 0.001, 0.019, 0.001, 0.019))
            sim.run(2000)
    except PyGranError as exc:
        print(type(exc).__name__, exc, flush=True)
""")


def test_a_simulation_filling_the_disk_stops_with_one_error_and_python_exits_cleanly(tmp_path):
    """The native engine writing H5MD until the file-size limit (a full disk's stand-in): one
    WriteError naming the file, a clean exit (once SIGBUS), every frame written readable."""
    done = subprocess.run(
        [sys.executable, "-c", RUN_UNTIL_FULL, str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    kind, message = done.stdout.strip().split(" ", 1)
    assert kind == "WriteError" and "no space for the next frame (File too large)" in message
    assert message.startswith((str(tmp_path / "out" / "traj.h5md"), str(tmp_path / "out" / "traj.xdmf.h5")))
    frames = list(open_trajectory(tmp_path / "out" / "traj.h5md"))
    assert len(frames) >= 5 and [f.timestep for f in frames] == list(range(0, 10 * len(frames), 10))
    assert all(len(f.arrays["id"]) == 2000 for f in frames)
    assert len(list(open_trajectory(tmp_path / "out" / "traj.xdmf"))) in (len(frames) - 1, len(frames))
