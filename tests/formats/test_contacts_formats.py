"""Contact records in files: LIGGGHTS-style ``dump local`` and H5MD's ``/contacts`` group
written and read back exactly; the columns of LIGGGHTS' own ``compute pair/gran/local`` and
``wall/gran/local`` dumps mapped to the schema; damaged files give a ReadError."""

from __future__ import annotations

import numpy as np
import pytest

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.formats.contacts import COLUMNS, INT_COLUMNS
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.testing.formats import BYTES, damaged_copies, fuzz_check, particle_frames

TEXT = b"0123456789 .-+eE\n\tx:ITEMENTRIS"


def contact_frames() -> list[Frame]:
    """Contacts frames of varying size (one empty), wall rows, awkward floats."""
    rng = np.random.default_rng(3)
    frames = []
    for k, n in enumerate((6, 0, 40, 3)):
        arrays = {
            name: rng.integers(-4, 90, n)
            if name in INT_COLUMNS
            else rng.normal(size=n) * 10.0 ** rng.integers(-9, 9, n)
            for name in COLUMNS
        }
        if n:
            arrays["fx"][0] = 1 / 3
            arrays["id2"][-1] = -1
        frames.append(
            Frame(
                arrays,
                timestep=1000 * k,
                time=1e-4 * k,
                box=np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 3.0]]),
                boundary=("pp", "pp", "ff"),
                attrs={"kind": "contacts"},
            )
        )
    return frames


def assert_same_contacts(written: list[Frame], read: list[Frame]) -> None:
    assert len(read) == len(written)
    for a, b in zip(written, read):
        assert b.attrs["kind"] == "contacts"
        assert list(b.arrays) == list(COLUMNS)
        assert b.timestep == a.timestep
        for name in COLUMNS:
            assert b.arrays[name].dtype == (np.int64 if name in INT_COLUMNS else np.float64)
            np.testing.assert_array_equal(b.arrays[name], a.arrays[name], err_msg=name)


def pairs_first(frames: list[Frame]) -> list[Frame]:
    """The frames as a contacts dump gives them back: the pair rows, then the wall rows."""
    out = []
    for frame in frames:
        order = np.argsort(frame.arrays["id2"] < 0, kind="stable")
        out.append(Frame({k: v[order] for k, v in frame.arrays.items()}, frame.timestep, attrs=frame.attrs))
    return out


def test_dump_local_round_trip(tmp_path):
    """Pair contacts in ``contacts.dump``, wall contacts beside it in ``wall-contacts.dump``
    (LIGGGHTS' two dump local files); read back as one frame each, pairs first."""
    frames = contact_frames()
    with open_writer(tmp_path / "contacts.dump") as out:
        for frame in frames:
            out.write_frame(frame)
    text = (tmp_path / "contacts.dump").read_text()
    assert text.count("ITEM: NUMBER OF ENTRIES") == 4 and "ITEM: ATOMS" not in text
    assert "ITEM: ENTRIES id1 id2 fx fy fz cx cy cz bx by bz\n" in text
    with open_trajectory(tmp_path / "contacts.dump") as read:
        assert_same_contacts(pairs_first(frames), list(read))
        assert read[2].boundary == ("pp", "pp", "ff")
    with open_trajectory(tmp_path / "wall-contacts.dump") as walls:
        for frame, written in zip(walls, frames):
            wall = written.arrays["id2"] < 0
            assert frame.timestep == written.timestep
            np.testing.assert_array_equal(frame.arrays["id2"], written.arrays["id2"][wall])
    with open_writer(tmp_path / "step*.dump") as out:  # a file per frame
        for frame in frames:
            out.write_frame(frame)
    assert sorted(p.name for p in tmp_path.glob("wall-step*.dump")) == [
        f"wall-step{1000 * k}.dump" for k in range(4)
    ]
    assert_same_contacts(pairs_first(frames), list(open_trajectory(tmp_path / "step*.dump", contacts=True)))


def test_dump_pair_file_holds_particle_pairs_only(tmp_path):
    """Every row of the pair file names two particles, as OVITO's bonds need; a wall file
    missing or of other frames is a ReadError naming it."""
    frames = contact_frames()
    with open_writer(tmp_path / "contacts.dump") as out:
        for frame in frames:
            out.write_frame(frame)
    text = (
        (tmp_path / "contacts.dump").read_text().split("ITEM: ENTRIES id1 id2 fx fy fz cx cy cz bx by bz\n")
    )
    rows = [line.split() for block in text[1:] for line in block.splitlines() if not line.startswith("ITEM")]
    rows = [r for r in rows if len(r) == len(COLUMNS)]
    assert len(rows) == sum(int(np.count_nonzero(f.arrays["id2"] >= 0)) for f in frames)
    assert all(int(r[1]) >= 0 for r in rows)
    lines = (tmp_path / "wall-contacts.dump").read_text().splitlines(keepends=True)
    (tmp_path / "wall-contacts.dump").write_text("".join(lines[: lines.index("ITEM: TIMESTEP\n", 1)]))
    with pytest.raises(ReadError, match="wall-contacts.dump holds 1 frames of wall contacts.*4 frames"):
        open_trajectory(tmp_path / "contacts.dump")
    (tmp_path / "wall-contacts.dump").unlink()
    with open_writer(tmp_path / "c*.dump") as out:
        for frame in frames[:2]:
            out.write_frame(frame)
    (tmp_path / "wall-c1000.dump").unlink()
    with pytest.raises(ReadError, match="wall-c1000.dump is missing"):
        open_trajectory(tmp_path / "c*.dump")


def test_h5md_round_trip_beside_particles(tmp_path):
    """One H5MD file holds the particle frames and the contacts of each, frame by frame."""
    frames, particles = contact_frames(), particle_frames()
    with open_writer(tmp_path / "run.h5", contacts=True) as out:
        for p, c in zip(particles, frames):
            out.write_frame(p)
            out.write_frame(c)
    with open_trajectory(tmp_path / "run.h5") as read:
        assert len(read) == 4 and np.array_equal(read[2].arrays["id"], particles[2].arrays["id"])
        contacts = read.contacts()
        assert contacts is not None
        assert_same_contacts(frames, list(contacts))
        assert contacts[0].boundary == particles[0].boundary
    assert_same_contacts(frames, list(open_trajectory(tmp_path / "run.h5", contacts=True)))


def test_h5md_contacts_only(tmp_path):
    frames = contact_frames()
    with open_writer(tmp_path / "contacts.h5") as out:
        for frame in frames:
            out.write_frame(frame)
        with pytest.raises(UnsupportedFeature, match="contacts only"):
            out.write_frame(particle_frames()[0])
    with open_trajectory(tmp_path / "contacts.h5") as read:
        assert_same_contacts(frames, list(read))
    with open_writer(tmp_path / "particles.h5") as out:
        out.write_frame(particle_frames()[0])
        with pytest.raises(UnsupportedFeature, match="contacts=True"):
            out.write_frame(frames[0])
    with pytest.raises(ReadError, match="no /contacts group"):
        open_trajectory(tmp_path / "particles.h5", contacts=True)
    assert open_trajectory(tmp_path / "particles.h5").contacts() is None


def test_bad_contact_columns_are_refused(tmp_path):
    frame = contact_frames()[0]
    with open_writer(tmp_path / "c.h5") as out:
        with pytest.raises(UnsupportedFeature, match="missing \\['bz'\\]"):
            out.write_frame(Frame({k: v for k, v in frame.arrays.items() if k != "bz"}, attrs=frame.attrs))
    particles = tmp_path / "p.dump"
    with open_writer(particles) as out:
        out.write_frame(particle_frames()[0])
    with pytest.raises(ReadError, match="particles, not contacts"):
        open_trajectory(particles, contacts=True)[0]


LIGGGHTS_PAIRS = """ITEM: TIMESTEP
2000
ITEM: NUMBER OF ENTRIES
2
ITEM: BOX BOUNDS pp pp ff
0 0.01
0 0.01
0 0.02
ITEM: ENTRIES c_pgl[1] c_pgl[2] c_pgl[3] c_pgl[4] c_pgl[5] c_pgl[6] c_pgl[7] c_pgl[8] c_pgl[9] \
c_pgl[10] c_pgl[11] c_pgl[12] c_pgl[13] c_pgl[14] c_pgl[15]
0.005 0.005 0.001 0.005 0.005 0.003 1 2 0 0.5 -0.25 2 0.005 0.005 0.002
0.0095 0.004 0.001 0.0005 0.004 0.001 3 4 1 -1.5 0 0 0.0105 0.004 0.001
"""


def test_liggghts_pair_gran_local_columns(tmp_path):
    """A dump of ``compute pgl all pair/gran/local pos id force contactPoint``: ids, force and
    contact point as LIGGGHTS wrote them, the branch vector the minimum image of its
    (wrapped) positions across the periodic x boundary."""
    path = tmp_path / "pairs.dump"
    path.write_text(LIGGGHTS_PAIRS)
    frame = open_trajectory(path, compute="pair/gran/local pos id force contactPoint")[0]
    assert frame.attrs["kind"] == "contacts" and frame.timestep == 2000
    a = frame.arrays
    assert a["id1"].tolist() == [1, 3] and a["id2"].tolist() == [2, 4]
    assert a["id1"].dtype == np.int64
    np.testing.assert_array_equal(
        np.column_stack([a["fx"], a["fy"], a["fz"]]), [[0.5, -0.25, 2], [-1.5, 0, 0]]
    )
    np.testing.assert_array_equal(a["cx"], [0.005, 0.0105])
    branch = np.column_stack([a["bx"], a["by"], a["bz"]])
    np.testing.assert_allclose(branch, [[0, 0, -0.002], [-0.001, 0, 0]], rtol=0, atol=1e-15)
    # the same layout named with keywords in another order and the default columns around
    layout = "pair/gran/local contactPoint force id pos"
    assert np.array_equal(open_trajectory(path, compute=layout)[0].arrays["bx"], a["bx"])
    with pytest.raises(ReadError, match="'pair/gran/local pos id force'.*contactPoint"):
        open_trajectory(path, compute="pair/gran/local pos id force")[0]
    with pytest.raises(ReadError, match="are not contact records"):
        open_trajectory(path, contacts=True)[0]
    local = open_trajectory(path)[0]  # without compute=: LIGGGHTS' columns as they are
    assert local.attrs["kind"] == "local" and local.arrays["c_pgl[7]"].tolist() == [1.0, 3.0]


def test_liggghts_wall_gran_local_columns(tmp_path):
    """``compute wall/gran/local pos id force``: ids are (mesh, triangle, particle), the
    first position the contact point: a wall row with id2 = -(mesh + 1)."""
    path = tmp_path / "walls.dump"
    path.write_text(
        "ITEM: TIMESTEP\n10\nITEM: NUMBER OF ENTRIES\n1\nITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n0 1\n"
        "ITEM: ENTRIES " + " ".join(f"c_w[{k}]" for k in range(1, 13)) + "\n"
        "0.5 0.5 0 0.5 0.5 0.001 1 17 42 0 0 3.5\n"
    )
    a = open_trajectory(path, compute="wall/gran/local pos id force")[0].arrays
    assert (a["id1"][0], a["id2"][0]) == (42, -2)
    assert (a["fz"][0], a["cz"][0], a["bz"][0]) == (3.5, 0.0, 0.001)


def test_damaged_contact_files_give_read_error(tmp_path):
    dump_good, h5_good = tmp_path / "good.dump", tmp_path / "good.h5"
    for path in (dump_good, h5_good):
        with open_writer(path) as out:
            for frame in contact_frames():
                out.write_frame(frame)

    def read(path):
        with open_trajectory(path, contacts=True) as trajectory:
            for frame in trajectory:
                assert list(frame.arrays) == list(COLUMNS)
                assert len({len(v) for v in frame.arrays.values()}) == 1

    bases = [(".dump", dump_good.read_bytes(), TEXT)]
    fuzz_check("contacts-dump", damaged_copies(tmp_path, "cdump", bases), read, dump_good)
    bases = [(".h5", h5_good.read_bytes(), BYTES)]
    fuzz_check("contacts-h5md", damaged_copies(tmp_path, "ch5", bases), read, h5_good)
