"""Resuming a simulation from a checkpoint (:mod:`~pygran_core.simulation.checkpoint`) by
rerunning its script: the :class:`Journal` of the calls that changed the simulation, which a
resumed script is checked against and replays up to the checkpoint, the checkpoints written on
schedule, and the single-file trajectories cut back to the checkpoint's step
(:func:`cut_trajectory`, with the frame copier of whoever wrote the file).
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError, ReadError
from pygran_core.simulation.checkpoint import Checkpoint, latest_checkpoint, read_checkpoint, write_checkpoint
from pygran_core.simulation.log import EngineLog
from pygran_core.simulation.specs import RestartSpec

#: Copies the frames a resume keeps (up to the checkpoint's ``step``) from the trajectory file
#: set aside (first argument) into a new file at the trajectory's path (second argument), and
#: returns how many; a :class:`ReadError` where the file set aside is damaged.
FrameCopier = Callable[[Path, Path, int], int]


def content_digest(value: Any) -> str:
    """A SHA-256 digest (16 hex digits) of ``value``'s full content: dataclass fields (those
    shown in its ``repr``), mappings, sequences and numpy arrays (dtype, shape and bytes) all
    the way down; ``repr`` of the rest."""
    digest = hashlib.sha256()

    def feed(item: Any) -> None:
        if isinstance(item, np.ndarray):
            digest.update(f"array {item.dtype.str} {item.shape}:".encode())
            digest.update(np.ascontiguousarray(item).tobytes())
        elif dataclasses.is_dataclass(item) and not isinstance(item, type):
            digest.update(f"{type(item).__qualname__}(".encode())
            for field in dataclasses.fields(item):
                if not field.repr:
                    continue  # derived from the simulation's state at the call, not an argument
                digest.update(f"{field.name}=".encode())
                feed(getattr(item, field.name))
            digest.update(b")")
        elif isinstance(item, Mapping):
            digest.update(f"{{{len(item)}:".encode())
            for key, entry in item.items():
                feed(key)
                feed(entry)
        elif isinstance(item, (list, tuple)):
            digest.update(f"[{len(item)}:".encode())
            for entry in item:
                feed(entry)
        else:
            digest.update(f"{type(item).__name__}:{item!r};".encode())

    feed(value)
    return digest.hexdigest()[:16]


def _shorten(text: str, width: int = 120) -> str:
    return "`" + (text if len(text) <= width else text[: width - 3] + "...") + "`"


class Journal:
    """Every call that changed a simulation of the ``engine`` engine, with its result, in order;
    with ``restart`` ``resume=True``, the latest checkpoint, whose script's calls the journal
    checks and replays until the run it was taken in (:attr:`checkpoint`, ``None`` after)."""

    def __init__(self, engine: str, restart: RestartSpec | None, log: EngineLog) -> None:
        self.engine = engine
        self.log = log
        #: ``[call, result]`` for every call that changed the simulation, in order.
        self.calls: list[list[Any]] = []
        self.checkpoint: Checkpoint | None = None
        #: The checkpoint's file, and the files beside the last checkpoint written that it needs.
        self.path: Path | None = None
        self._written: tuple[Path, list[Path]] | None = None
        if restart is not None and restart.resume:
            self.path = latest_checkpoint(restart)
            self.checkpoint = read_checkpoint(self.path)
            if self.checkpoint.engine != engine:
                raise ConfigError(
                    f"{self.path} was written by the {self.checkpoint.engine} engine; "
                    f"resume it with engine={self.checkpoint.engine!r}"
                )
            log.log(
                "resuming from %s (step %d): the calls before it are checked and replayed",
                self.path,
                self.checkpoint.step,
            )

    @property
    def replaying(self) -> bool:
        """Whether the script is being replayed up to the checkpoint it resumes from."""
        return self.checkpoint is not None

    def record(self, call: str, spec: Any = None) -> Any:
        """Record a call that changes the simulation: its text, and for a call with a spec a
        digest of every argument (``repr`` shortens arrays of over 1,000 values). While
        :attr:`replaying`, check it is the call the checkpoint's script made at this point and
        return that call's result."""
        if spec is not None:
            call = f"{call} #{content_digest(spec)}"
        index = len(self.calls)
        self.calls.append([call, None])
        if self.checkpoint is None:
            return None
        recorded = self.checkpoint.journal
        if index >= len(recorded) or recorded[index][0] != call:
            was = recorded[index][0] if index < len(recorded) else "nothing more"
            raise ConfigError(
                f"This script is not the one that wrote {self.path}: its call {index + 1} is "
                f"{_shorten(call)} where that script's was {_shorten(was)}. Resume with the same "
                "script, or start afresh without resume."
            )
        self.calls[index][1] = recorded[index][1]
        return recorded[index][1]

    def result(self, value: Any) -> None:
        """The result of the call recorded last."""
        self.calls[-1][1] = value

    def record_run(self, nsteps: int, dt: float) -> None:
        """Record a run of ``nsteps`` steps of ``dt`` (see :meth:`record`)."""
        self.record(f"run {nsteps} {dt!r}")

    def replayed_dt(self) -> float | None:
        """While :attr:`replaying`, the time step of the run the checkpoint's script made next,
        as :meth:`record_run` wrote it (a default time step needs the particles, which a
        replay does not create)."""
        if self.checkpoint is None or len(self.calls) >= len(self.checkpoint.journal):
            return None
        call = self.checkpoint.journal[len(self.calls)][0].split()
        return float(call[2]) if call[0] == "run" and len(call) == 3 else None

    def finished_before(self) -> bool:
        """Whether the call recorded last (a run) was over before the checkpoint was taken."""
        return self.checkpoint is not None and len(self.calls) < len(self.checkpoint.journal)

    def compare_facts(self, checkpoint: Checkpoint, facts: dict[str, Any]) -> None:
        """Log that the run will not continue bitwise when ``facts`` (the engine's, see
        ``_facts``) differ from the checkpoint's."""
        if checkpoint.facts != facts:
            self.log.log(
                "resuming with %s where the checkpoint had %s: the run continues, but not bitwise",
                facts,
                checkpoint.facts,
                level=logging.WARNING,
            )

    def resume(self) -> Checkpoint:
        """The checkpoint, at the run it was taken in: the replay is over."""
        checkpoint, self.checkpoint = self.checkpoint, None
        if checkpoint is None:
            raise RuntimeError("no checkpoint is being resumed")
        return checkpoint

    def write(self, path: Path, checkpoint: Checkpoint, files: list[Path]) -> None:
        """Write ``checkpoint`` (its journal: this one's calls) to ``path``; ``files``: those
        beside it that it needs. The files of the checkpoint it replaces (at the same path) that
        this one does not need are deleted."""
        checkpoint.journal = [list(call) for call in self.calls]
        write_checkpoint(path, checkpoint)
        if self._written is not None and self._written[0] == path:
            for stale in set(self._written[1]) - set(files):
                stale.unlink(missing_ok=True)
        self._written = (path, files)
        self.log.log("checkpoint at step %d: %s", checkpoint.step, path)


def cut_aside(path: Path) -> Path:
    """Where a resume keeps a single-file trajectory while it copies back the frames it keeps
    (``traj.h5`` -> ``traj.before-resume.h5``)."""
    return path.with_name(f"{path.stem}.before-resume{path.suffix}")


def cut_trajectory(
    path: Path, copy: FrameCopier, step: int, log: EngineLog, beside: Sequence[Path] = ()
) -> None:
    """Keep the frames of the single-file trajectory ``path`` up to ``step``, copied by
    ``copy`` from the file set aside (:func:`cut_aside`), with the files ``beside`` it (a
    contacts dump's walls) set aside too. A resume killed while copying leaves the original
    aside: the next one copies from it again. A damaged original is left aside, logged."""
    moved = [(path, cut_aside(path))] + [(other, cut_aside(other)) for other in beside]
    moved = [(now, aside) for now, aside in moved if now.exists() or aside.exists()]
    for now, aside in moved:
        if aside.exists():  # an earlier resume was killed while copying: the original is there
            now.unlink(missing_ok=True)
        else:
            os.replace(now, aside)
    original = cut_aside(path)
    try:
        kept = copy(original, path, step)
    except ReadError as exc:
        log.log(
            "resume: %s; the frames before it are kept in %s, the original is left as %s",
            exc,
            path,
            original,
            level=logging.WARNING,
        )
        return
    for _, aside in moved:
        aside.unlink()
    log.log("resume: %d frames up to step %d kept in %s", kept, step, path)
