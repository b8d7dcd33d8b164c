"""Checkpoint files: written and read back exactly; every kind of damage refused with a
ReadError that names the file and the problem; and fuzzing: 320 files damaged at random,
byte by byte and by rewriting their parts with h5py, each read in a child process."""

from __future__ import annotations

import random

import h5py
import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.simulation.checkpoint import Checkpoint, encode_text, read_checkpoint, write_checkpoint
from pygran_core.testing.formats import BYTES, damaged_copies, fuzz_check, mutate


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


def unsealed(path, version=1):
    """``path`` rewritten without its seal, as checkpoints were before version 2."""
    copy = path.with_name("unsealed.h5")
    with h5py.File(path, "r") as source, h5py.File(copy, "w") as target:
        for name in source:
            source.copy(source[name], target, name)
        target.attrs.update(source.attrs)
        target.attrs["version"] = version
    copy.replace(path)


def set_dataset(name, value):
    def change(f):
        del f[name]
        f[name] = value

    return change


def set_attr(name, value):
    def change(f):
        f.attrs[name] = value

    return change


def seal_zeroed(path):
    with open(path, "r+b") as handle:
        handle.write(bytes(512))


#: damage -> (on a version-1 file, the change with h5py, or of the bytes, the message)
DAMAGE = {
    "value changed": (
        False,
        set_dataset("state/solver/core_x", np.linspace(0, 1, 9) + 1e-12),
        "damaged checkpoint: its bytes do not match the SHA-256 it was sealed with",
    ),
    "seal zeroed": (False, seal_zeroed, "unreadable checkpoint: not a PyGran checkpoint, or its first bytes"),
    "version 2 unsealed": (None, lambda f: None, "damaged checkpoint: version 2 without its seal"),
    "newer version": (True, set_attr("version", 3), "checkpoint version 3 is newer than this PyGran reads"),
    "not a checkpoint": (True, lambda f: f.attrs.__delitem__("format"), "not a PyGran checkpoint"),
    "journal not JSON": (
        True,
        set_dataset("journal", encode_text('[["run 5", nul')),
        "the journal is not UTF-8 JSON: Expecting value",
    ),
    "journal not UTF-8": (
        True,
        set_dataset("journal", np.frombuffer(b'[["\xff", 1]]', np.uint8)),
        "the journal is not UTF-8 JSON: 'utf-8' codec can't decode byte 0xff",
    ),
    "journal not pairs": (
        True,
        set_dataset("journal", encode_text('[["run 5", null, 1]]')),
        "the journal is not a list of [call, result] pairs",
    ),
    "journal as floats": (
        True,
        set_dataset("journal", np.zeros(3)),
        "the journal is missing or not UTF-8 bytes",
    ),
    "facts a list": (True, set_dataset("facts", encode_text("[1]")), "the facts is a list, not a dict"),
    "text state": (
        True,
        set_dataset("state/solver/core_id", np.array(["a", "b"], dtype=h5py.string_dtype())),
        "dataset 'state/solver/core_id' holds object, not numbers",
    ),
    "compound state": (
        True,
        set_dataset("state/solver/core_x", np.zeros(9, dtype=[("a", "<f8"), ("b", "<i4")])),
        "dataset 'state/solver/core_x' holds",
    ),
    "clock missing": (
        True,
        lambda f: f.__delitem__("state/clock"),
        "the state has no clock of 2 finite numbers (found None)",
    ),
    "clock of 3": (
        True,
        set_dataset("state/clock", np.zeros(3)),
        "the state has no clock of 2 finite numbers",
    ),
    "monitor 1-D": (True, set_dataset("monitors/4", np.zeros(3)), "monitor '4' is not a table of samples"),
    "negative step": (True, set_attr("step", -1), "bad clock: step -1"),
    "time nan": (True, set_attr("time", np.nan), "bad clock: step 2000, time nan"),
    "step text": (True, set_attr("step", "2000"), "attribute 'step' is '2000', not an integer"),
    "engine number": (True, set_attr("engine", 5), "attribute 'engine' is 5, not text"),
}


@pytest.mark.parametrize("case", DAMAGE)
def test_damage_is_a_read_error_naming_the_problem(tmp_path, case):
    version_1, change, message = DAMAGE[case]
    path = tmp_path / "restart.h5"
    write_checkpoint(path, checkpoint())
    if version_1 is None:
        unsealed(path, version=2)
    elif version_1:
        unsealed(path)
        read_checkpoint(path)  # a version-1 file reads
    if change is seal_zeroed:
        change(path)
    else:
        with h5py.File(path, "r+") as f:
            change(f)
    with pytest.raises(ReadError) as info:
        read_checkpoint(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value), str(info.value)


@pytest.mark.parametrize(
    ("size", "message"),
    [
        (0, "not a PyGran checkpoint, or its first bytes are damaged"),
        (20, "not a PyGran checkpoint, or its first bytes are damaged"),
        (800, "its bytes do not match the SHA-256 it was sealed with"),
        (-64, "its bytes do not match the SHA-256 it was sealed with"),
    ],
)
def test_truncated_file(tmp_path, size, message):
    path = tmp_path / "restart.h5"
    write_checkpoint(path, checkpoint())
    path.write_bytes(path.read_bytes()[:size])
    with pytest.raises(ReadError, match=rf"restart\.h5: .*{message}"):
        read_checkpoint(path)


def rewritten(path, rng):
    """One part of a checkpoint rewritten with h5py (a broken journal or facts text, a state
    array of another type or shape, a bad attribute or monitor), half of the time in a
    version-1 file, which has no seal: then the structural checks alone must see it."""
    if rng.random() < 0.5:
        unsealed(path)
    with h5py.File(path, "r+") as f:
        part = rng.choice(["journal", "facts", "state", "attr", "monitor"])
        if part in ("journal", "facts"):
            text = f[part][()].tobytes()
            del f[part]
            f[part] = np.frombuffer(mutate(rng, text, b'[]{}",:\xc3\xa9\xff0a'), np.uint8)
        elif part == "state":
            names = []
            f["state"].visititems(
                lambda name, item: names.append(name) if isinstance(item, h5py.Dataset) else None
            )
            name = rng.choice(sorted(names))
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
            del f["monitors/4"]
            f["monitors/4"] = rng.choice([np.arange(3.0), np.array(["x"], dtype=h5py.string_dtype())])


def test_fuzz(tmp_path):
    """160 checkpoints damaged byte by byte, 160 rewritten in part with h5py."""
    original = tmp_path / "restart.h5"
    write_checkpoint(original, checkpoint())
    paths = damaged_copies(tmp_path, "checkpoint", [(".h5", original.read_bytes(), BYTES)], 160)
    rng = random.Random(11)
    for k in range(160):
        path = tmp_path / f"rewritten-{k}" / "restart.h5"
        path.parent.mkdir()
        path.write_bytes(original.read_bytes())
        rewritten(path, rng)
        paths.append(path)
    fuzz_check("checkpoint", paths, read_checkpoint, original)
