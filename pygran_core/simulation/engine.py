"""The :class:`Engine` base class: what every DEM engine shares.

An engine owns a solver. The base class owns the behaviour that must not differ between
engines: the output directory (created, never ``chdir``-ed into), the log of every call in
``<output>/pygran.log``, capability checks that name the engines able to do what was asked,
handle bookkeeping for ``remove``, the progress bar and step/time accounting of ``run``,
and closing (also as a context manager). An engine implements the ``_underscored`` hooks.
"""

from __future__ import annotations

import abc
import itertools
import logging
import os
import sys
from dataclasses import dataclass
from numbers import Integral, Real
from pathlib import Path
from typing import Any, ClassVar

from pygran_core.errors import ConfigError, EngineError, UnsupportedFeature

LOG_NAME = "pygran.log"
_LOG_FORMAT = "%(asctime)s %(levelname)s %(message)s"


@dataclass(frozen=True)
class Handle:
    """What an engine call such as ``insert`` or ``setupWall`` returns; pass it to ``remove``."""

    kind: str
    id: int
    label: str
    engine_id: int


def positive_int(value: Any, name: str) -> int:
    """``value`` as an int > 0, or a :class:`ConfigError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value <= 0:
        raise ConfigError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def positive_float(value: Any, name: str) -> float:
    """``value`` (int or float) as a float > 0, or a :class:`ConfigError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Real) or not value > 0:
        raise ConfigError(f"{name} must be a positive number, got {value!r}")
    return float(value)


class Engine(abc.ABC):
    """Base class of DEM engines.

    Subclasses set :attr:`name` and :attr:`capabilities` and implement :meth:`_advance`;
    they override :meth:`_remove` and :meth:`_close` when they hold solver resources.
    """

    name: ClassVar[str] = "engine"
    capabilities: ClassVar[frozenset[str]] = frozenset()
    #: Upper bound on the number of progress updates (and Python round trips) per ``run``.
    max_run_chunks: ClassVar[int] = 100

    _ids = itertools.count(1)

    def __init__(
        self, output: str | os.PathLike[str], *, dt: float | None = None, progress: bool | None = None
    ) -> None:
        self.output = Path(output).resolve()
        self.output.mkdir(parents=True, exist_ok=True)
        self.dt = None if dt is None else positive_float(dt, "dt")
        self.progress = progress
        self.step = 0
        self.time = 0.0
        self.closed = False
        self._engine_id = next(Engine._ids)
        self._handles: dict[int, Handle] = {}
        self._handle_ids = itertools.count(1)
        self._logger = logging.getLogger(f"pygran.simulation.{self.name}")
        self._log_handler = logging.FileHandler(self.output / LOG_NAME, encoding="utf-8")
        self._log_handler.setFormatter(logging.Formatter(_LOG_FORMAT))
        self.log("%s engine opened, output in %s", self.name, self.output)

    # -- common behaviour ------------------------------------------------------------

    def log(self, message: str, *args: Any, level: int = logging.INFO) -> None:
        """Record ``message`` in ``<output>/pygran.log``, and on the ``pygran`` logger
        for whoever has configured logging to show it."""
        record = self._logger.makeRecord(self._logger.name, level, __file__, 0, message, args, None)
        self._log_handler.handle(record)
        if self._logger.isEnabledFor(level):
            self._logger.handle(record)

    def require(self, capability: str, what: str | None = None) -> None:
        """Raise :class:`UnsupportedFeature` unless this engine has ``capability``."""
        if capability in self.capabilities:
            return
        from pygran_core.registry import engines_with

        able = [name for name in engines_with(capability) if name != self.name]
        alternative = f"Engines that can: {', '.join(able)}." if able else "No installed engine can."
        raise UnsupportedFeature(
            f"The {self.name} engine does not support {what or capability} "
            f"(capability {capability!r}). {alternative}"
        )

    def _check_open(self) -> None:
        if self.closed:
            raise EngineError(f"This {self.name} simulation is closed; create a new one")

    def _new_handle(self, kind: str, label: str) -> Handle:
        """Record a removable object created in the solver and return its handle."""
        handle = Handle(kind, next(self._handle_ids), label, self._engine_id)
        self._handles[handle.id] = handle
        return handle

    @property
    def handles(self) -> tuple[Handle, ...]:
        """Handles of the objects not yet removed, oldest first."""
        return tuple(self._handles.values())

    def remove(self, handle: Handle) -> None:
        """Remove what ``handle`` refers to (an insertion, wall, mesh motion, force, monitor)."""
        self._check_open()
        if not isinstance(handle, Handle) or handle.engine_id != self._engine_id:
            raise ConfigError(f"{handle!r} is not a handle returned by this simulation")
        if handle.id not in self._handles:
            raise ConfigError(f"{handle.kind} {handle.label!r} was already removed")
        self._remove(handle)
        del self._handles[handle.id]
        self.log("remove %s %s", handle.kind, handle.label)

    def run(self, nsteps: int, dt: float | None = None, *, progress: bool | None = None) -> None:
        """Advance ``nsteps`` time steps (of ``dt``, or the simulation's time step).

        A progress bar is shown on a terminal unless ``progress=False`` (here or at
        construction); Python regains control only between the bar's updates.
        """
        self._check_open()
        nsteps = positive_int(nsteps, "nsteps")
        if dt is not None:
            self.dt = positive_float(dt, "dt")
        if self.dt is None:
            raise ConfigError("No time step: pass dt to run(nsteps, dt) or to the simulation")
        self.log("run %d steps of dt=%g from step %d", nsteps, self.dt, self.step)
        show = progress if progress is not None else self.progress
        if show is None:
            show = sys.stderr.isatty()
        from tqdm import tqdm

        with tqdm(total=nsteps, unit="step", disable=not show, desc=f"{self.name} run") as bar:
            for chunk in self._chunks(nsteps):
                self._advance(chunk)
                self.step += chunk
                self.time += chunk * self.dt
                bar.update(chunk)

    def _chunks(self, nsteps: int) -> list[int]:
        """Split a run into at most :attr:`max_run_chunks` nearly equal pieces."""
        pieces = min(nsteps, self.max_run_chunks)
        base, extra = divmod(nsteps, pieces)
        return [base + 1] * extra + [base] * (pieces - extra)

    def close(self) -> None:
        """Release the solver and the log file; closing twice is harmless."""
        if self.closed:
            return
        try:
            self._close()
        finally:
            self.closed = True
            self.log("%s engine closed at step %d", self.name, self.step)
            self._log_handler.close()

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- engine hooks ----------------------------------------------------------------

    @abc.abstractmethod
    def _advance(self, nsteps: int) -> None:
        """Integrate ``nsteps`` steps of :attr:`dt` in the solver."""

    def _remove(self, handle: Handle) -> None:
        """Delete the solver object behind ``handle``; engines that create objects override."""
        raise UnsupportedFeature(f"The {self.name} engine cannot remove a {handle.kind}")

    def _close(self) -> None:
        """Release solver resources; engines holding any override."""
