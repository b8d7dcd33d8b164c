"""Checkpoint files: written and read back exactly, and every kind of damage refused with a
ReadError that names the file and the problem (the fuzz test damages them at random)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.simulation.checkpoint import Checkpoint, encode_text, read_checkpoint, write_checkpoint


def checkpoint() -> Checkpoint:
    return Checkpoint(
        engine="native",
        step=2000,
        time=2e-3,
        dt=1e-6,
        journal=[["create CreateSpec(species=1, n=3, region='µ-box')", 3], ["run 2000 1e-06", None]],
        monitors={4: np.array([[1000, 1e-3, 0.5], [2000, 2e-3, 0.25]])},
        state={
            "clock": np.array([2000, 2e-3]),
            "solver/core_x": np.linspace(0, 1, 9),
            "solver/core_id": np.arange(3, dtype=np.int64),
            "solver/model_kind": encode_text("hertz"),
        },
        facts={"threads": 2},
    )


def test_round_trip(tmp_path):
    write_checkpoint(tmp_path / "c.h5", checkpoint())
    got, want = read_checkpoint(tmp_path / "c.h5"), checkpoint()
    assert (got.engine, got.step, got.time, got.dt) == ("native", 2000, 2e-3, 1e-6)
    assert got.journal == want.journal and got.facts == want.facts
    np.testing.assert_array_equal(got.monitors[4], want.monitors[4])
    assert list(got.state) == sorted(want.state)
    for name, value in want.state.items():
        assert got.state[name].dtype == value.dtype
        np.testing.assert_array_equal(got.state[name], value)


def set_dataset(name, value):
    def change(f):
        del f[name]
        f[name] = value

    return change


def set_attr(name, value):
    def change(f):
        f.attrs[name] = value

    return change


def old(change):
    """The change on a version-1 checkpoint (no digest): the structural checks must see it."""

    def both(f):
        change(f)
        del f.attrs["digest"]
        f.attrs["version"] = 1

    return both


DAMAGE = {
    "value changed": (
        set_dataset("state/solver/core_x", np.linspace(0, 1, 9) + 1e-12),
        "damaged checkpoint: its contents do not match the digest written with them",
    ),
    "digest missing": (lambda f: f.attrs.__delitem__("digest"), "the digest of its contents is missing"),
    "newer version": (set_attr("version", 3), "checkpoint version 3 is newer than this PyGran reads"),
    "not a checkpoint": (lambda f: f.attrs.__delitem__("format"), "not a PyGran checkpoint"),
    "journal not JSON": (
        old(set_dataset("journal", encode_text('[["run 5", nul'))),
        "the journal is not UTF-8 JSON: Expecting value",
    ),
    "journal not UTF-8": (
        old(set_dataset("journal", np.frombuffer(b'[["\xff", 1]]', np.uint8))),
        "the journal is not UTF-8 JSON: 'utf-8' codec can't decode byte 0xff",
    ),
    "journal not pairs": (
        old(set_dataset("journal", encode_text('[["run 5", null, 1]]'))),
        "the journal is not a list of [call, result] pairs",
    ),
    "journal as floats": (
        old(set_dataset("journal", np.zeros(3))),
        "the journal is missing or not UTF-8 bytes",
    ),
    "facts a list": (old(set_dataset("facts", encode_text("[1]"))), "the facts is a list, not a dict"),
    "text state": (
        old(set_dataset("state/solver/core_id", np.array(["a", "b"], dtype=h5py.string_dtype()))),
        "dataset 'state/solver/core_id' holds object, not numbers",
    ),
    "compound state": (
        old(set_dataset("state/solver/core_x", np.zeros(9, dtype=[("a", "<f8"), ("b", "<i4")]))),
        "dataset 'state/solver/core_x' holds",
    ),
    "clock missing": (
        old(lambda f: f.__delitem__("state/clock")),
        "the state has no clock of 2 finite numbers (found None)",
    ),
    "clock of 3": (
        old(set_dataset("state/clock", np.zeros(3))),
        "the state has no clock of 2 finite numbers",
    ),
    "monitor 1-D": (old(set_dataset("monitors/4", np.zeros(3))), "monitor '4' is not a table of samples"),
    "negative step": (old(set_attr("step", -1)), "bad clock: step -1"),
    "time nan": (old(set_attr("time", np.nan)), "bad clock: step 2000, time nan"),
    "step text": (old(set_attr("step", "2000")), "attribute 'step' is '2000', not an integer"),
    "engine number": (old(set_attr("engine", 5)), "attribute 'engine' is 5, not text"),
}


@pytest.mark.parametrize("case", DAMAGE)
def test_damage_is_a_read_error_naming_the_problem(tmp_path, case):
    change, message = DAMAGE[case]
    path = tmp_path / "restart.h5"
    write_checkpoint(path, checkpoint())
    with h5py.File(path, "r+") as f:
        change(f)
    with pytest.raises(ReadError) as info:
        read_checkpoint(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value), str(info.value)


@pytest.mark.parametrize("size", [0, 20, 800, -64])
def test_truncated_file(tmp_path, size):
    path = tmp_path / "restart.h5"
    write_checkpoint(path, checkpoint())
    path.write_bytes(path.read_bytes()[:size])
    with pytest.raises(
        ReadError, match=r"restart\.h5: unreadable checkpoint \(OSError: Unable to synchronously"
    ):
        read_checkpoint(path)
