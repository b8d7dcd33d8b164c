"""Checkpoints: a whole simulation in one HDF5 file, and where to find the one to resume.

A checkpoint holds the clock (step, time, dt), the journal of the calls that led there (so
a resumed script can be checked against the one that wrote it), the monitor samples so
far, and the engine's own state as named numpy arrays (``Engine._state``). It is written
to a temporary file and renamed, so a crash while writing leaves the previous one intact,
and sealed with the SHA-256 of its bytes, so a damaged one is refused rather than resumed.

Names: ``fname`` with a ``*`` writes a file per checkpoint with the step in its place
(``restart.*.h5`` -> ``restart.5000.h5``), as LIGGGHTS does; otherwise each checkpoint
replaces the last.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError, ReadError
from pygran_core.formats.hdf5 import HDF5_SIGNATURE, load_h5py, open_hdf5
from pygran_core.simulation.specs import RestartSpec

FORMAT = "pygran-checkpoint"
#: 2: sealed with the SHA-256 of its bytes (in the HDF5 user block)
VERSION = 2


@dataclass
class Checkpoint:
    """The state of a simulation after every event of step :attr:`step`."""

    engine: str
    step: int
    time: float
    dt: float | None
    #: One ``[call, result]`` pair per journaled call, the run in progress last.
    journal: list[list[Any]]
    #: Monitor samples by the monitor handle's id.
    monitors: dict[int, np.ndarray] = field(default_factory=dict)
    #: The engine's arrays (``Engine._state``), by name; names may contain ``/``.
    state: dict[str, np.ndarray] = field(default_factory=dict)
    #: Facts that must match on resume for a bitwise continuation (e.g. thread count).
    facts: dict[str, Any] = field(default_factory=dict)


def encode_text(text: str) -> np.ndarray:
    """Text as a uint8 array, for state dictionaries that hold arrays only."""
    return np.frombuffer(text.encode(), dtype=np.uint8).copy()


def decode_text(array: np.ndarray) -> str:
    """The inverse of :func:`encode_text`."""
    return np.asarray(array, dtype=np.uint8).tobytes().decode()


#: What :func:`state_entry` calls the dtype kinds it is asked for (any other: numbers).
KIND_NAMES = {"iu": "integers", "u": "text (UTF-8 bytes, see encode_text)"}


def state_entry(
    path: Path, state: dict[str, np.ndarray], key: str, kinds: str, shape: tuple[int | None, ...]
) -> np.ndarray:
    """``state[key]`` for an engine restoring a checkpoint, checked before anything of it is
    used: present, of a numpy dtype kind among ``kinds`` (``"iu"``: integers, ``"biuf"``: any
    number) and of ``shape`` (``None``: any length along that axis); else a :class:`ReadError`
    naming the file and the key."""
    value = state.get(key)
    if value is None:
        raise ReadError(f"{path}: the checkpoint has no state entry {key!r}")
    fits = value.ndim == len(shape) and all(n is None or n == m for n, m in zip(shape, value.shape))
    if value.dtype.kind not in kinds or not fits:
        expected = " x ".join("any" if n is None else str(n) for n in shape) or "a scalar"
        raise ReadError(
            f"{path}: the checkpoint's state entry {key!r} is {value.dtype} of shape {value.shape}, "
            f"not {KIND_NAMES.get(kinds, 'numbers')} of shape {expected}"
        )
    return value


def state_json(path: Path, state: dict[str, np.ndarray], key: str, kind: type) -> Any:
    """The JSON value (a ``kind``) of a state entry made with :func:`encode_text`, checked as
    :func:`state_entry` checks arrays."""
    value = state_entry(path, state, key, "u", (None,))
    return _json(lambda message: ReadError(f"{path}: {message}"), value, f"state entry {key!r}", kind)


def checkpoint_path(restart: RestartSpec, step: int) -> Path:
    """Where the checkpoint of ``step`` goes."""
    return restart.directory / restart.fname.replace("*", str(step))


def latest_checkpoint(restart: RestartSpec) -> Path:
    """The checkpoint to resume from: ``lastfile``, else the newest in the directory."""
    if restart.lastfile is not None:
        if not restart.lastfile.is_file():
            raise ConfigError(f"restart lastfile {restart.lastfile} does not exist")
        return restart.lastfile
    if "*" not in restart.fname:
        path = restart.directory / restart.fname
        if not path.is_file():
            raise ConfigError(
                f"restart resume=True but there is no checkpoint {path}; run once without resume "
                "to write one, or pass lastfile"
            )
        return path
    pattern = re.compile(re.escape(restart.fname).replace(r"\*", r"(\d+)") + "$")
    found = {
        int(m.group(1)): p for p in restart.directory.glob(restart.fname) if (m := pattern.match(p.name))
    }
    if not found:
        raise ConfigError(
            f"restart resume=True but {restart.directory} holds no checkpoint {restart.fname}; "
            "run once without resume to write one, or pass lastfile"
        )
    return found[max(found)]


def write_checkpoint(path: Path, checkpoint: Checkpoint) -> None:
    """Write ``checkpoint`` to ``path`` atomically (temporary file, then rename), sealed with
    the SHA-256 of its bytes."""
    h5py = load_h5py()

    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    with h5py.File(partial, "w", userblock_size=_SEAL_SIZE) as f:
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        f.attrs["engine"] = checkpoint.engine
        f.attrs["step"] = checkpoint.step
        f.attrs["time"] = checkpoint.time
        f.attrs["dt"] = np.nan if checkpoint.dt is None else checkpoint.dt
        # datasets, not attributes: an attribute holds at most 64 KiB
        f.create_dataset("journal", data=encode_text(json.dumps(checkpoint.journal)))
        f.create_dataset("facts", data=encode_text(json.dumps(checkpoint.facts)))
        for position, samples in checkpoint.monitors.items():
            f.create_dataset(f"monitors/{position}", data=samples)
        for name, value in checkpoint.state.items():
            f.create_dataset(f"state/{name}", data=value)
    with open(partial, "r+b") as handle:
        seal = _SEAL + _sha256(handle).encode() + b"\n"
        handle.seek(0)
        handle.write(seal.ljust(_SEAL_SIZE, b"\0"))
    os.replace(partial, path)


#: The HDF5 user block that starts a checkpoint: this text and the SHA-256 of every byte
#: after the block, checked before HDF5 reads anything (a damaged HDF5 file can crash or
#: hang libhdf5 itself: its default metadata carries no checksum).
_SEAL, _SEAL_SIZE = b"PyGran checkpoint sha256 ", 512
_KINDS = {str: "text", int: "an integer", float: "a number"}
#: What h5py, UTF-8 and JSON decoding raise on a damaged file.
_DAMAGE = (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError)


def _sha256(handle: Any) -> str:
    """The SHA-256 of an open file's bytes after its user block."""
    digest = hashlib.sha256()
    handle.seek(_SEAL_SIZE)
    while chunk := handle.read(1 << 20):
        digest.update(chunk)
    return digest.hexdigest()


def read_checkpoint(path: Path) -> Checkpoint:
    """Read a checkpoint written by :func:`write_checkpoint`.

    Anything malformed is a :class:`ReadError`: bytes that do not match the checkpoint's
    seal (checked before HDF5 reads the file), a file that is not HDF5, attributes of the
    wrong type, datasets that are not numeric or whose shape is not what is stored, a journal
    or facts that are not UTF-8 JSON of the expected shape, monitors that are not tables of
    samples. What the engine's state arrays must hold is checked by the engine restoring them.
    A file that reaches outside itself (external links or storage, virtual datasets) is refused.
    """
    try:
        with open(path, "rb") as handle:
            head = handle.read(_SEAL_SIZE + 8)
            sealed = head.startswith(_SEAL)
            if sealed and head[len(_SEAL) : len(_SEAL) + 65] != _sha256(handle).encode() + b"\n":
                raise ReadError(
                    f"{path}: damaged checkpoint: its bytes do not match the SHA-256 it was sealed with"
                )
        if not sealed and not head.startswith(HDF5_SIGNATURE):
            raise ReadError(
                f"{path}: unreadable checkpoint: not a PyGran checkpoint, or its first bytes are damaged"
            )
        with open_hdf5(path) as f:  # refuses a file that reaches outside itself
            checkpoint, version = _read(path, f)
    except _DAMAGE as exc:
        raise ReadError(f"{path}: unreadable checkpoint ({type(exc).__name__}: {exc})") from None
    if version >= 2 and not sealed:
        raise ReadError(f"{path}: damaged checkpoint: version {version} without its seal")
    return checkpoint


def _read(path: Path, f: Any) -> tuple[Checkpoint, int]:
    """The checkpoint in an open file, checked, and its format version."""
    h5py = load_h5py()

    def fail(message: str) -> ReadError:
        return ReadError(f"{path}: {message}")

    def attr(name: str, kind: type) -> Any:
        value = f.attrs.get(name)
        value = value.decode() if isinstance(value, bytes) else value
        value = value.item() if isinstance(value, np.generic) else value
        if kind is str:
            ok = isinstance(value, str)
        else:
            ok = isinstance(value, (int, float) if kind is float else int) and not isinstance(value, bool)
        if not ok:
            raise fail(f"attribute {name!r} is {value!r}, not {_KINDS[kind]}")
        return kind(value)

    if f.attrs.get("format") is None or attr("format", str) != FORMAT:
        raise fail(f"not a PyGran checkpoint (no format={FORMAT!r} attribute)")
    version = attr("version", int)
    if version > VERSION:
        raise fail(
            f"checkpoint version {version} is newer than this PyGran reads ({VERSION}); upgrade pygran-core"
        )
    step, time, dt = attr("step", int), attr("time", float), attr("dt", float)
    if step < 0 or not np.isfinite(time) or not (np.isnan(dt) or dt > 0):
        raise fail(f"bad clock: step {step}, time {time}, dt {dt}")
    datasets: dict[str, np.ndarray] = {}

    def collect(name: str, item: Any) -> None:
        if isinstance(item, h5py.Dataset):
            if item.dtype.kind not in "biuf":
                raise fail(f"dataset {name!r} holds {item.dtype}, not numbers")
            stored = item.id.get_storage_size()
            if item.chunks is None and item.size and stored != item.size * item.dtype.itemsize:
                raise fail(f"dataset {name!r} of shape {item.shape} has {stored} bytes stored")
            datasets[name] = item[()]

    f.visititems(collect)
    journal = _json(fail, datasets.get("journal"), "journal", list)
    if not all(isinstance(c, list) and len(c) == 2 and isinstance(c[0], str) for c in journal):
        raise fail("the journal is not a list of [call, result] pairs")
    monitors: dict[int, np.ndarray] = {}
    for name, value in datasets.items():
        if name.startswith("monitors/"):
            key = name.split("/", 1)[1]
            if not key.isdigit() or value.ndim != 2 or value.shape[1] < 2:
                raise fail(f"monitor {key!r} is not a table of samples (shape {value.shape})")
            monitors[int(key)] = value.astype(np.float64)
    state = {name[len("state/") :]: value for name, value in datasets.items() if name.startswith("state/")}
    clock = state.get("clock")
    if clock is None or clock.shape != (2,) or not np.isfinite(clock).all():
        raise fail(f"the state has no clock of 2 finite numbers (found {clock!r})")
    checkpoint = Checkpoint(
        engine=attr("engine", str),
        step=step,
        time=time,
        dt=None if np.isnan(dt) else dt,
        journal=journal,
        monitors=monitors,
        state=state,
        facts=_json(fail, datasets.get("facts"), "facts", dict),
    )
    return checkpoint, version


def _json(fail: Any, value: np.ndarray | None, name: str, kind: type) -> Any:
    """The JSON value of a text dataset ``value`` (called ``name`` in messages), which must be
    a ``kind``."""
    if value is None or value.dtype != np.uint8 or value.ndim != 1:
        raise fail(f"the {name} is missing or not UTF-8 bytes")
    try:
        decoded = json.loads(decode_text(value))
    except ValueError as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise fail(f"the {name} is not UTF-8 JSON: {exc}") from None
    if not isinstance(decoded, kind):
        raise fail(f"the {name} is a {type(decoded).__name__}, not a {kind.__name__}")
    return decoded
