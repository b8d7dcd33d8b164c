"""LIGGGHTS/LAMMPS text dumps: conformance, the real hopper run, column handling and errors."""

import gzip
import os
import shutil
import signal
import threading
import types

import numpy as np
import pytest

from pygran_core.errors import ReadError, UnsupportedFeature, WriteError
from pygran_core.formats import dump
from pygran_core.formats.dump import DumpTrajectory, format_frame
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.testing.formats import FormatConformance, assert_frames_equal, particle_frames
from pygran_core.testing.solvers import kernel_path

HEADER = "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp ff\n0 1\n0 2\n0 3\n"


@pytest.fixture(params=["compiled", "numpy"])
def table_parser(request, monkeypatch):
    """Each test runs on the core's compiled parser (required under CI) and on the numpy path."""
    return kernel_path(request.param, dump, monkeypatch)


def dump_text(rows_per_frame, columns="id type x y z", step=100, first=0):
    """Frames at steps ``first + step * k`` whose row r of frame k is ``r+1 1 k r 0.5 ...`` (one
    value per column)."""
    out = []
    for k, n in enumerate(rows_per_frame):
        out.append(HEADER.format(step=first + step * k, n=n) + f"ITEM: ATOMS {columns}\n")
        for r in range(n):
            out.append(
                " ".join(
                    [str(r + 1), "1", str(k), str(r), "0.5"][: len(columns.split())]
                    + ["0.25"] * (len(columns.split()) - 5)
                )
                + "\n"
            )
    return "".join(out)


class TestDump(FormatConformance):
    reader = "dump"
    writer = "dump"
    suffix = ".dump"
    physical_checks = True

    def bad_files(self, tmp_path):
        good = dump_text([3, 2])
        cases = {
            "truncated": (good + dump_text([4])[:-12], 2),
            "lying": (good + dump_text([4]).replace("\n4\n", "\n6\n", 1), 2),
            "lying-more": (dump_text([3]).replace("\n3\n", "\n2\n", 1) + good, 0),
            "nonnumeric": (good + dump_text([4]).replace("0.5\n", "O.5\n", 1) + good, 2),
            "unknown-column": (good + dump_text([2], "id type x y zz"), 2),
            "bad-int": (good + dump_text([2]).replace("\n1 1 0", "\n1.5 1 0", 1), 2),
            "no-atoms-item": (good + "ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n1\n", 2),
            "not-dump": ("hello\n", 0),
        }
        paths = []
        for name, (text, readable) in cases.items():
            path = tmp_path / f"{name}{self.suffix}"
            path.write_text(text)
            paths.append((path, readable))
        return paths


class TestDumpGzip(TestDump):
    suffix = ".dump.gz"

    def make_sample(self, tmp_path):
        frames = particle_frames()
        with open_writer(tmp_path / "plain.dump") as out:
            for frame in frames:
                out.write_frame(frame)
        target = tmp_path / "sample.dump.gz"
        target.write_bytes(gzip.compress((tmp_path / "plain.dump").read_bytes()))
        return target, frames

    def bad_files(self, tmp_path):
        out = []
        for path, readable in super().bad_files(tmp_path):
            target = path.with_name(path.name.replace(".dump.gz", "-z.dump.gz"))
            target.write_bytes(gzip.compress(path.read_bytes()))
            out.append((target, readable))
        cut = tmp_path / "cut.dump.gz"
        cut.write_bytes(gzip.compress(dump_text([50, 50, 50]).encode())[:-40])
        return [*out, (cut, 2), (damaged_gzip(tmp_path), 2)]


def damaged_gzip(tmp_path):
    """Three frames of 20,000 particles compressed, with bytes of the deflate stream in the
    third frame overwritten (zlib: "invalid block type")."""
    text = dump_text([20000, 20000, 20000]).encode()
    packed = bytearray(gzip.compress(text, mtime=0))
    middle = len(packed) * 3 // 4
    packed[middle : middle + 8] = b"\xff" * 8
    path = tmp_path / "damaged.dump.gz"
    path.write_bytes(bytes(packed))
    return path


def test_damaged_gzip_names_the_frame_and_line(tmp_path):
    trajectory = open_trajectory(damaged_gzip(tmp_path))
    assert [len(trajectory[k].arrays["id"]) for k in (0, 1)] == [20000, 20000]
    with pytest.raises(
        ReadError, match=r"damaged\.dump\.gz: frame 2, line 40019: the compressed stream is damaged"
    ):
        trajectory[2]


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"ITEM: TIMESTEP\n0\n", "Not a gzipped file"),
        (
            gzip.compress(b"ITEM: TIMESTEP\n0\n", mtime=0)[:15],
            "Compressed file ended before the end-of-stream",
        ),
    ],
)
def test_a_gzip_file_damaged_at_its_start(tmp_path, content, reason):
    (tmp_path / "a.dump.gz").write_bytes(content)
    with pytest.raises(
        ReadError, match=rf"a\.dump\.gz: frame 0, line 1: the compressed stream is damaged \({reason}"
    ):
        open_trajectory(tmp_path / "a.dump.gz")[0]


class TestDumpPerFrameFiles(TestDump):
    """Writing ``out*.dump`` gives one file per frame named by timestep, read back as a glob."""

    def make_sample(self, tmp_path):
        frames = particle_frames()
        with open_writer(tmp_path / "out*.dump") as out:
            for frame in frames:
                out.write_frame(frame)
        assert sorted(p.name for p in tmp_path.glob("out*.dump")) == [
            "out0.dump",
            "out1000.dump",
            "out2000.dump",
            "out3000.dump",
        ]
        return str(tmp_path / "out*.dump"), frames


def test_hopper_fixture(data_dir, tmp_path):
    for path in (data_dir / "liggghts-hopper").glob("particles*.dump"):
        shutil.copy(path, tmp_path)
    trajectory = open_trajectory(str(tmp_path / "particles*.dump"))
    assert len(trajectory) == 31
    counts = [len(frame.arrays["id"]) for frame in trajectory]
    # NUMBER OF ATOMS of each file, in natural order (checked against the text)
    text_counts = [
        int(p.read_text().split("\n")[3])
        for p in sorted(tmp_path.glob("particles*.dump"), key=lambda p: int(p.stem[9:]))
    ]
    assert counts == text_counts and counts[0] == 0 and max(counts) == 571 and counts[-1] == 423
    last = trajectory[-1]
    assert last.timestep == 30000 and trajectory[5].timestep == 5000
    assert list(last.arrays) == "id type x y z radius vx vy vz fx fy fz".split()
    assert last.arrays["id"].dtype == np.int64 and last.arrays["type"].dtype == np.int64
    # the first atom row of particles30000.dump
    assert last.arrays["id"][0] == 204
    assert last.arrays["x"][0] == -3.00853e-05 and last.arrays["y"][0] == -0.000250325
    assert last.arrays["vz"][0] == -0.100362 and last.arrays["fz"][0] == -5.1365e-09
    assert np.all(last.arrays["radius"] == 5e-05)
    np.testing.assert_array_equal(last.box, [[-0.001, 0.001], [-0.001, 0.001], [0, 0.004]])
    assert last.boundary == ("ff", "ff", "ff")
    assert trajectory[0].arrays["x"].shape == (0,)


def test_scaled_triclinic_and_custom_columns(tmp_path):
    text = (
        "ITEM: UNITS\nsi\nITEM: TIME\n0.25\nITEM: TIMESTEP\n7\nITEM: NUMBER OF ATOMS\n2\n"
        "ITEM: BOX BOUNDS xy xz yz pp pp pp\n-0.5 11 1\n0 20 -0.5\n0 30 0\n"
        "ITEM: ATOMS id mol type xs ys zs c_stress[1] f_force v_var diameter\n"
        "1 3 2 0.5 0.5 0.5 1.5 2.5 3.5 0.001\n2 3 1 0 0 1 -1 -2 -3 0.002\n"
        "ITEM: TIME\n0.5\nITEM: TIMESTEP\n8\nITEM: NUMBER OF ATOMS\n0\n"
        "ITEM: BOX BOUNDS xy xz yz pp pp pp\n-0.5 11 1\n0 20 -0.5\n0 30 0\n"
        "ITEM: ATOMS id mol type xs ys zs c_stress[1] f_force v_var diameter\n"
    )
    (tmp_path / "t.dump").write_text(text)
    trajectory = open_trajectory(tmp_path / "t.dump")
    assert len(trajectory) == 2
    frame = trajectory[0]
    assert frame.timestep == 7 and frame.time == 0.25 and frame.attrs["units"] == "si"
    assert list(frame.arrays) == [
        "id",
        "mol",
        "type",
        "x",
        "y",
        "z",
        "c_stress[1]",
        "f_force",
        "v_var",
        "diameter",
    ]
    assert frame.arrays["mol"].dtype == np.int64
    # xlo = -0.5 - min(0, 1, -0.5, 0.5) = 0, lx = (11 - 1) - 0 = 10, ylo = 0 - min(0, 0) = 0 ...
    np.testing.assert_allclose(frame.arrays["x"], [0 + 5 + 0.5 * 1 + 0.5 * -0.5, -0.5])
    np.testing.assert_allclose(frame.arrays["y"], [10 + 0, 0])
    np.testing.assert_allclose(frame.arrays["z"], [15, 30])
    np.testing.assert_array_equal(frame.attrs["tilt"], [1, -0.5, 0])
    assert frame.arrays["c_stress[1]"].tolist() == [1.5, -1]
    assert trajectory[1].time == 0.5 and len(trajectory[1].arrays["id"]) == 0


def test_triclinic_written_back(tmp_path):
    frame = Frame(
        {"id": np.array([1, 2]), "x": np.array([0.1, 0.2])},
        timestep=3,
        box=np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 3.0]]),
        boundary=("pp", "pp", "ff"),
        attrs={"tilt": np.array([0.5, 0.0, 0.0])},
    )
    text = format_frame(frame)
    assert "ITEM: BOX BOUNDS xy xz yz pp pp ff\n0.0 1.0 0.5\n" in text
    (tmp_path / "t.dump").write_text(text)
    back = open_trajectory(tmp_path / "t.dump")[0]
    assert_frames_equal(back, frame)
    np.testing.assert_array_equal(back.attrs["tilt"], [0.5, 0, 0])


@pytest.mark.parametrize(
    "case, message",
    [
        # frame 2 starts on line 24: its atom count is on line 27, ITEM: ATOMS on 32, rows from 33
        ("truncated", r"truncated\.dump: frame 2, line 27: the frame is truncated"),
        (
            "lying",
            r"lying\.dump: frame 2, line 27: the header lies about the atom count: ITEM: NUMBER OF "
            r"ATOMS says 6 but 4 rows follow",
        ),
        ("nonnumeric", r"nonnumeric\.dump: frame 2, line 34: column 'z' holds 'O\.5', not a number"),
        (
            "unknown-column",
            r"unknown-column\.dump: frame 2, line 32: unknown column 'zz'\. Did you mean 'z'\?",
        ),
        ("bad-int", r"bad-int\.dump: frame 2, line 33: integer column 'id' holds 1\.5"),
    ],
)
def test_error_names_file_frame_and_line(table_parser, tmp_path, case, message):
    good = dump_text([3, 2])
    text = {
        "truncated": good + dump_text([4])[:-12],
        "lying": good + dump_text([4]).replace("\n4\n", "\n6\n", 1) + good,
        "nonnumeric": good + dump_text([4]).replace("1 0.5\n", "1 O.5\n", 1),
        "unknown-column": good + dump_text([2], "id type x y zz"),
        "bad-int": good + dump_text([2]).replace("\n1 1 0", "\n1.5 1 0", 1),
    }[case]
    (tmp_path / f"{case}.dump").write_text(text)
    trajectory = DumpTrajectory([tmp_path / f"{case}.dump"])
    assert len(trajectory) in (3, 5)
    assert [len(f.arrays["id"]) for f in (trajectory[0], trajectory[1])] == [3, 2]
    with pytest.raises(ReadError, match=message):
        trajectory[2]


def test_extra_columns_option(tmp_path):
    (tmp_path / "e.dump").write_text(dump_text([2], "id type x y z myprop"))
    with pytest.raises(ReadError, match="unknown column 'myprop'"):
        open_trajectory(tmp_path / "e.dump")[0]
    frame = open_trajectory(tmp_path / "e.dump", extra_columns=["myprop"])[0]
    assert frame.arrays["myprop"].tolist() == [0.25, 0.25]


def test_glob_with_an_empty_last_file(tmp_path):
    (tmp_path / "p0.dump").write_text(dump_text([2]))
    (tmp_path / "p10.dump").write_text("")
    trajectory = open_trajectory(str(tmp_path / "p*.dump"))
    assert len(trajectory[0].arrays["id"]) == 2
    with pytest.raises(ReadError, match=r"p10\.dump: frame 1, line 1: not a LAMMPS dump"):
        trajectory[1]


ROWS = [
    ["1", "1", "0.1", "-0.0", "1e-5", "+.5", "5."],
    [
        "2",
        "2",
        "1.7976931348623157e308",
        "4.9e-324",
        "2.2250738585072014e-308",
        "0.30000000000000004",
        "-1e400",
    ],
    ["3", "1", "1E+22", "1e23", "9007199254740993", "0.000844828", "-7.4806e-05"],
    ["4", "2", "123456789012345678901234567890", "-0.1234567890123456789", "1e-400", "0012.50", "7"],
    ["5", "1", "0.1000000000000000055511151231257827", "-2.5E-0003", "6.02214076e23", "1.5e+10", "-0"],
]


@pytest.mark.parametrize("suffix", [".dump", ".dump.gz"])
@pytest.mark.parametrize("odd", ["", "nan", "inf"])
def test_numbers_are_read_as_python_reads_them(table_parser, tmp_path, suffix, odd):
    """Every value is the double nearest its text (Python's float()), bit for bit: shortest
    reprs, 17+ significant digits, subnormals, overflow, signed zeros; tabs, CRLF line ends and
    blank lines; nan and inf (which the compiled parser leaves to numpy.loadtxt)."""
    rows = [row[:6] + [odd] if odd and k == 2 else row for k, row in enumerate(ROWS)]
    body = "\r\n".join("\t ".join(row) for row in rows) + "\r\n\n"
    text = HEADER.format(step=0, n=len(rows)) + "ITEM: ATOMS id type x y z radius vx\n\n" + body
    path = tmp_path / f"numbers{suffix}"
    path.write_bytes(gzip.compress(text.encode()) if suffix.endswith(".gz") else text.encode())
    frame = open_trajectory(path)[0]
    if table_parser == "compiled":  # it parses these itself, and leaves nan and inf to numpy.loadtxt
        assert (dump._accel.parse_table(body.encode(), 7, len(rows)) is None) == bool(odd)
    for column, name in enumerate("id type x y z radius vx".split()):
        expected = np.array([float(row[column]) for row in rows])
        kind = np.int64 if name in ("id", "type") else np.float64
        assert frame.arrays[name].dtype == kind
        np.testing.assert_array_equal(
            frame.arrays[name].astype(np.float64).view(np.int64), expected.view(np.int64)
        )


class CountingInflater(dump._Inflater):
    """The reader's gzip stream, counting the streams opened and the bytes decompressed."""

    opened = 0
    inflated = 0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        CountingInflater.opened += 1

    def read(self):
        out = super().read()
        CountingInflater.inflated += len(out)
        return out

    def unread(self, data):
        super().unread(data)
        CountingInflater.inflated -= len(data)  # handed out again, not decompressed again


@pytest.fixture
def counting(monkeypatch):
    monkeypatch.setattr(dump, "_Inflater", CountingInflater)
    CountingInflater.opened = CountingInflater.inflated = 0
    return CountingInflater


def gzip_sample(tmp_path, rows=(3000, 0, 2500, 4000, 1000)):
    text = dump_text(list(rows), "id type x y z radius vx").encode()
    (tmp_path / "t.dump").write_bytes(text)
    (tmp_path / "t.dump.gz").write_bytes(gzip.compress(text, mtime=0))
    return text, open_trajectory(tmp_path / "t.dump")


@pytest.mark.parametrize("cpus", [1, 2])
def test_a_gzip_dump_read_in_order_is_decompressed_once(table_parser, tmp_path, counting, monkeypatch, cpus):
    """Opening decompresses the file once and keeps its frames (parsed ahead on a second thread
    with the compiled parser and two CPUs); reading them decompresses nothing more and lets each
    go; the values are those of the plain file, bit for bit."""
    monkeypatch.setattr(dump, "_cpus", lambda: cpus)
    text, plain = gzip_sample(tmp_path)
    trajectory = DumpTrajectory([tmp_path / "t.dump.gz"])
    assert (counting.opened, counting.inflated) == (1, len(text))
    kept = trajectory._kept[0]
    assert len(kept.texts) == 5 and len(kept.tables) == (4 if cpus == 2 and table_parser == "compiled" else 0)
    for frame, expected in zip(trajectory, plain, strict=True):
        assert_frames_equal(frame, expected)
    assert (counting.opened, counting.inflated) == (1, len(text))
    assert not kept.texts and not kept.tables
    assert_frames_equal(trajectory[2], plain[2])  # read again: decompressed again
    assert counting.opened == 2 and len(text) < counting.inflated < 2 * len(text)


def test_a_gzip_dump_past_the_budget(tmp_path, counting, monkeypatch):
    """Frames past the text kept are decompressed again: in order, from where the last read
    stopped; out of order, from the nearest restart point (at most a span before the frame)."""
    monkeypatch.setattr(dump, "GZIP_KEEP_BYTES", 100_000)  # frames 0 (about 80 kB) and 1 (empty)
    monkeypatch.setattr(dump, "_RESTART_SPAN", 20_000)
    monkeypatch.setattr(dump, "_FEED", 1024)  # pieces of a few kB, so restart points that close
    text, plain = gzip_sample(tmp_path)
    trajectory = DumpTrajectory([tmp_path / "t.dump.gz"])
    assert list(trajectory._kept[0].texts) == [block.start for block in trajectory._blocks[:2]]
    for frame, expected in zip(trajectory, plain, strict=True):
        assert_frames_equal(frame, expected)
    assert counting.opened == 2 and counting.inflated < 2 * len(text)
    blocks = trajectory._blocks
    for k in (4, 0, 3, 1, 2):
        before = counting.inflated
        assert_frames_equal(trajectory[k], plain[k])
        size = blocks[k].end - blocks[k].start
        assert size <= counting.inflated - before < size + 20_000 + len(dump_text([1000]))


def test_gzip_members_and_padding(tmp_path):
    """Several gzip members with zero padding read as gzip.open reads them; bytes after the last
    member that do not start one are damage, named in the last frame's error."""
    first, second = dump_text([3, 2]), dump_text([4], first=500)
    plain = tmp_path / "t.dump"
    plain.write_text(first + second)
    packed = gzip.compress(first.encode(), mtime=0) + gzip.compress(second.encode(), mtime=0)
    (tmp_path / "m.dump.gz").write_bytes(packed + b"\0" * 7)
    for frame, expected in zip(open_trajectory(tmp_path / "m.dump.gz"), open_trajectory(plain), strict=True):
        assert_frames_equal(frame, expected)
    (tmp_path / "j.dump.gz").write_bytes(packed + b"junk")
    trajectory = open_trajectory(tmp_path / "j.dump.gz")
    assert [len(trajectory[k].arrays["id"]) for k in (0, 1)] == [3, 2]
    with pytest.raises(
        ReadError,
        match=r"j\.dump\.gz: frame 2, line 24: the compressed stream is damaged \(Not a gzipped file \(b'ju'",
    ):
        trajectory[2]


def test_a_gzip_dump_read_in_a_forked_process(table_parser, tmp_path, monkeypatch):
    """A process forked while the tables are being parsed ahead (a multiprocessing pool, say)
    reads every frame: it parses them itself rather than wait for the parent's thread."""
    monkeypatch.setattr(dump, "_cpus", lambda: 2)
    parent, forked = os.getpid(), threading.Event()
    if table_parser == "compiled":
        compiled = dump._accel

        def parse_table(*args):  # holds the parent's thread until the child is forked
            if os.getpid() == parent:
                forked.wait(10)
            return compiled.parse_table(*args)

        monkeypatch.setattr(dump, "_accel", types.SimpleNamespace(parse_table=parse_table))
    text, plain = gzip_sample(tmp_path)
    trajectory = open_trajectory(tmp_path / "t.dump.gz")
    pid = os.fork()
    if pid == 0:  # the child: exit status 0 when every frame is read right within 5 s
        signal.alarm(5)
        try:
            same = all(
                np.array_equal(frame.arrays["x"], expected.arrays["x"])
                for frame, expected in zip(trajectory, plain, strict=True)
            )
        finally:
            os._exit(0 if same else 1)
    forked.set()
    assert os.waitpid(pid, 0)[1] == 0
    assert [len(frame.arrays["id"]) for frame in trajectory] == [3000, 0, 2500, 4000, 1000]


def test_time_is_written_only_when_asked(tmp_path):
    """By default a dump is laid out as LIGGGHTS writes it, without ``ITEM: TIME`` (which
    MDAnalysis' dump reader does not take); ``time=True`` writes it first, as LAMMPS'
    ``dump_modify time yes`` does, and it reads back."""
    frames = particle_frames()
    for frame in frames:
        frame.time = 0.25 * (frame.timestep or 0)
    for time, path in ((False, tmp_path / "plain.dump"), (True, tmp_path / "timed.dump")):
        with open_writer(path, time=time) as out:
            for frame in frames:
                out.write_frame(frame)
        text = path.read_text()
        assert text.startswith("ITEM: TIME\n" if time else "ITEM: TIMESTEP\n")
        assert text.count("ITEM: TIME\n") == (len(frames) if time else 0)
        back = open_trajectory(path)
        assert [f.time for f in back] == [f.time if time else None for f in frames]
    with pytest.raises(UnsupportedFeature, match="one option, time=True"):
        open_writer(tmp_path / "x.dump", colour="red")


@pytest.mark.parametrize("name", ["series*.dump", "one.dump"])
def test_a_frame_that_cannot_be_written_is_a_write_error_naming_the_file(tmp_path, name):
    target = tmp_path / "missing-folder" / name
    written = r"missing-folder/(series\d+|one)\.dump: frame 0 could not be written"
    with pytest.raises(WriteError, match=written):
        with open_writer(target) as out:
            out.write_frame(particle_frames()[0])
