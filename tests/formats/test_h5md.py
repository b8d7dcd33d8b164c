"""H5MD: conformance, the standard layout seen by plain h5py, crash safety, dump round trip."""

import shutil
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.testing.formats import (
    FormatConformance,
    assert_frames_equal,
    fuzz_read,
    particle_frames,
    read_every_frame,
)


class TestH5MD(FormatConformance):
    reader = "h5md"
    writer = "h5md"
    suffix = ".h5md"
    physical_checks = True

    def make_insane(self, tmp_path, name, frames):
        """The writer refuses insane frames: write sane ones, then put each value that differs
        in place in its particle's row (rows in the order written: ``pygran_order``)."""
        sane = particle_frames()
        path = super().make_insane(tmp_path, name, sane)
        group = "particles/trajectory"
        with h5py.File(path, "a") as f:
            order = f[f"{group}/pygran_order/value"][:]
            for k, (bad, good) in enumerate(zip(frames, sane)):
                if bad.timestep != good.timestep:
                    f[f"{group}/position/step"][k] = bad.timestep
                rows = np.flatnonzero(order[k] >= 0)[np.argsort(order[k][order[k] >= 0])]
                for column, values in bad.arrays.items():
                    for j in np.flatnonzero(values != good.arrays[column]):
                        assert column in ("id", "radius"), column  # what insane_samples changes
                        f[f"{group}/{column}/value"][k, rows[j]] = values[j]
        return path

    def bad_files(self, tmp_path):
        plain = tmp_path / "plain.h5"
        with h5py.File(plain, "w") as f:
            f["data"] = np.arange(3)
        return [*super().bad_files(tmp_path), (plain, 0)]


def test_standard_layout_in_plain_h5py(tmp_path):
    frames = particle_frames()
    with open_writer(tmp_path / "t.h5md") as out:
        for frame in frames:
            out.write_frame(frame)
    distinct = np.unique(np.concatenate([f.arrays["id"] for f in frames]))
    with h5py.File(tmp_path / "t.h5md", "r") as f:
        assert list(f["h5md"].attrs["version"]) == [1, 1]
        assert f["h5md/creator"].attrs["name"] == "PyGran"
        assert f["h5md/modules/units"].attrs["system"] == "SI"
        group = f["particles/trajectory"]
        assert {"position", "velocity", "force", "id", "species", "radius", "box"} <= set(group)
        position = group["position"]
        # one row per particle that ever appeared
        assert position["value"].shape == (4, len(distinct), 3) and position["value"].maxshape == (
            None,
            None,
            3,
        )
        assert position["value"].chunks is not None and position["value"].compression == "gzip"
        units = {
            name: group[f"{name}/value"].attrs.get("unit")
            for name in ("position", "velocity", "force", "radius")
        }
        assert units == {"position": "m", "velocity": "m s-1", "force": "N", "radius": "m"}
        assert all(group[f"{name}/time"].attrs["unit"] == "s" for name in group if name != "box")
        assert "unit" not in group["id/value"].attrs and "unit" not in group["species/value"].attrs
        assert position["step"][:].tolist() == [0, 1000, 2000, 3000]
        # step and time are one dataset, hard-linked into every element
        assert group["id/step"].id == position["step"].id
        ids = group["id/value"][:]
        assert ids.dtype == np.int64 and ids[1].tolist() == [-1] * len(distinct)
        for row in ids.T:  # row i holds one particle in every frame where it is present
            assert len(set(row[row >= 0].tolist())) == 1
        for k, frame in enumerate(frames):
            present = ids[k] >= 0
            assert present.sum() == len(frame.arrays["id"])
            where = {int(i): r for r, i in enumerate(ids[k]) if i >= 0}
            rows = [where[int(i)] for i in frame.arrays["id"]]
            np.testing.assert_array_equal(position["value"][k][rows, 0], frame.arrays["x"])
            np.testing.assert_array_equal(group["species/value"][k][rows], frame.arrays["type"])
            np.testing.assert_array_equal(group["pygran_order/value"][k][rows], np.arange(len(rows)))
            assert np.isnan(position["value"][k, ~present]).all()
        assert f["observables/trajectory/particle_number/value"][:].tolist() == [5, 0, 12, 3]
        box = group["box"]
        assert box.attrs["dimension"] == 3 and list(box.attrs["boundary"]) == ["periodic", "none", "none"]
        np.testing.assert_array_equal(box["edges/value"][0], [2.0, 4.0, 0.1])
        assert box["edges/value"].attrs["unit"] == "m"
        assert "c_stress[2]" in group


def test_triclinic_box(tmp_path):
    frame = Frame(
        {"id": np.array([1]), "x": np.array([0.5])},
        timestep=1,
        time=0.5,
        box=np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 3.0]]),
        attrs={"tilt": np.array([0.1, 0.2, 0.3])},
    )
    with open_writer(tmp_path / "t.h5", format="h5md") as out:
        out.write_frame(frame)
    back = open_trajectory(tmp_path / "t.h5")[0]
    assert_frames_equal(back, frame)
    assert back.time == 0.5
    np.testing.assert_array_equal(back.attrs["tilt"], [0.1, 0.2, 0.3])
    with h5py.File(tmp_path / "t.h5") as f:
        np.testing.assert_array_equal(
            f["particles/trajectory/box/edges/value"][0], [[1, 0, 0], [0.1, 2, 0], [0.2, 0.3, 3]]
        )


def test_changing_columns_is_refused(tmp_path):
    from pygran_core.errors import UnsupportedFeature

    with open_writer(tmp_path / "t.h5md") as out:
        out.write_frame(Frame({"id": np.array([1]), "x": np.array([0.5])}))
        with pytest.raises(UnsupportedFeature, match="columns"):
            out.write_frame(Frame({"id": np.array([1])}))


def test_dump_to_h5md_to_dump_preserves_every_value(data_dir, tmp_path):
    for path in (data_dir / "liggghts-hopper").glob("particles*.dump"):
        shutil.copy(path, tmp_path)
    source = open_trajectory(str(tmp_path / "particles*.dump"))
    with open_writer(tmp_path / "hopper.h5md") as out:
        for frame in source:
            out.write_frame(frame)
    with open_trajectory(tmp_path / "hopper.h5md") as h5, open_writer(tmp_path / "back.dump") as out:
        assert len(h5) == 31
        for frame in h5:
            out.write_frame(frame)
    back = open_trajectory(tmp_path / "back.dump")
    assert len(back) == 31
    for got, want in zip(back, source):
        assert_frames_equal(got, want)  # ints equal, floats bitwise
    # and the text values are the same numbers as the original text
    original = (tmp_path / "particles30000.dump").read_text().split("\n")[9].split()
    rewritten = (tmp_path / "back.dump").read_text().split("ITEM: ATOMS")[-1].split("\n")[1].split()
    assert [float(v) for v in rewritten] == [float(v) for v in original]


WRITER = textwrap.dedent("""
    import sys
    import numpy as np
    from pygran_core.io import Frame, open_writer

    out = open_writer(sys.argv[1])
    k = 0
    while True:
        n = 20000 + 1000 * (k % 7)
        frame = Frame({"id": np.arange(n), "x": np.full(n, float(k)), "vx": np.arange(n) * 0.5},
                      timestep=k)
        out.write_frame(frame)
        print(k, flush=True)
        k += 1
""")


def test_killed_writer_leaves_completed_frames_readable(tmp_path):
    path = tmp_path / "killed.h5md"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        done = [int(proc.stdout.readline()) for _ in range(6)]
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    assert done == list(range(6))
    trajectory = open_trajectory(path)
    assert len(trajectory) >= 6
    for k in range(len(trajectory)):
        frame = trajectory[k]
        n = 20000 + 1000 * (k % 7)
        assert frame.timestep == k and len(frame.arrays["id"]) == n
        np.testing.assert_array_equal(frame.arrays["id"], np.arange(n))
        assert np.all(frame.arrays["x"] == k)


def test_not_h5md(tmp_path):
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.create_group("particles")
    with pytest.raises(ReadError, match=r"other\.h5: no /particles group"):
        open_trajectory(tmp_path / "other.h5")


def test_damaged_files_are_read_errors_not_hangs(tmp_path):
    """A truncated file (the first 20 bytes of any PyGran .h5 used to hang the reader in SWMR
    mode), and a killed writer's file truncated or with a damaged metadata byte (SWMR mode,
    whose retries are bounded): each read in a child process with a time limit."""
    closed = tmp_path / "closed.h5"
    with open_writer(closed) as out:
        for frame in particle_frames():
            out.write_frame(frame)
    killed = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(killed)], stdout=subprocess.PIPE, text=True)
    try:
        assert [int(proc.stdout.readline()) for _ in range(3)] == [0, 1, 2]
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(killed, "r")
    data = killed.read_bytes()
    damaged = {
        "first-20-bytes": closed.read_bytes()[:20],
        "half": closed.read_bytes()[: closed.stat().st_size // 2],
        "killed-first-4000-bytes": data[:4000],
        "killed-cut": data[:-100],
        # a byte of the first object header after the superblock (its checksum fails)
        "killed-header-byte": data[:60] + bytes([data[60] ^ 0xFF]) + data[61:],
    }
    for name, content in damaged.items():
        (tmp_path / f"{name}.h5").write_bytes(content)
    report = fuzz_read(read_every_frame, [tmp_path / f"{name}.h5" for name in damaged], timeout=20)
    assert not report.failures and not report.clean, report
    assert len(open_trajectory(killed)) >= 3  # the intact killed file, read in SWMR mode
    read_every_frame(killed)
    with pytest.raises(ReadError, match=r"killed-cut\.h5: not a readable HDF5 file: .*truncated file"):
        open_trajectory(tmp_path / "killed-cut.h5")
