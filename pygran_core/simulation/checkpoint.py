"""Checkpoints: a whole simulation in one HDF5 file, and where to find the one to resume.

A checkpoint holds the clock (step, time, dt), the journal of the calls that led there (so
a resumed script can be checked against the one that wrote it), the monitor samples so
far, and the engine's own state as named numpy arrays (``Engine._state``). It is written
to a temporary file and renamed, so a crash while writing leaves the previous one intact.

Names: ``fname`` with a ``*`` writes a file per checkpoint with the step in its place
(``restart.*.h5`` -> ``restart.5000.h5``), as LIGGGHTS does; otherwise each checkpoint
replaces the last.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError, ReadError
from pygran_core.simulation.specs import RestartSpec

FORMAT = "pygran-checkpoint"
VERSION = 1


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
    """Write ``checkpoint`` to ``path`` atomically (temporary file, then rename)."""
    import h5py

    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    with h5py.File(partial, "w") as f:
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
    os.replace(partial, path)


def read_checkpoint(path: Path) -> Checkpoint:
    """Read a checkpoint written by :func:`write_checkpoint`, with a clear error if it is not one."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise ReadError(f"{path}: not a PyGran checkpoint (no format={FORMAT!r} attribute)")
            if int(f.attrs["version"]) > VERSION:
                raise ReadError(
                    f"{path}: checkpoint version {int(f.attrs['version'])} is newer than this "
                    f"PyGran reads ({VERSION}); upgrade pygran-core"
                )
            state: dict[str, np.ndarray] = {}

            def collect(name: str, item: Any) -> None:
                if isinstance(item, h5py.Dataset):
                    state[name] = item[()]

            if "state" in f:
                f["state"].visititems(collect)
            dt = float(f.attrs["dt"])
            return Checkpoint(
                engine=str(f.attrs["engine"]),
                step=int(f.attrs["step"]),
                time=float(f.attrs["time"]),
                dt=None if np.isnan(dt) else dt,
                journal=json.loads(decode_text(f["journal"][()])),
                monitors={int(k): v[()] for k, v in f.get("monitors", {}).items()},
                state={k: np.asarray(v) for k, v in state.items()},
                facts=json.loads(decode_text(f["facts"][()])),
            )
    except (OSError, KeyError) as exc:
        raise ReadError(f"{path}: unreadable checkpoint ({exc})") from None
