"""An engine's messages: its own log file ``<output>/pygran.log``, the ``pygran`` logger for
whoever has configured logging to show it, and warnings issued at the user's line.

The engine owns its file handler rather than adding one to the ``pygran`` logger, so that
simulations never write into each other's logs and global logging state is untouched.
"""

from __future__ import annotations

import logging
import sys
import warnings
from pathlib import Path
from types import FrameType
from typing import Any

from pygran_core.simulation.mpi import launch_rank

LOG_NAME = "pygran.log"
_LOG_FORMAT = "%(asctime)s %(levelname)s %(message)s"


def user_stacklevel() -> int:
    """The ``stacklevel`` of ``warnings.warn`` that points at the first caller outside PyGran."""
    frame: FrameType | None = sys._getframe(1)
    level = 1
    while frame is not None and frame.f_globals.get("__name__", "").startswith("pygran"):
        frame, level = frame.f_back, level + 1
    return level


def progress_shown(progress: bool | None, default: bool | None) -> tuple[bool, bool]:
    """How a run shows its progress (``progress``, else the simulation's ``default``): whether
    as a bar, and whether as lines on stderr. By default a bar on a terminal, lines elsewhere (a
    file, a batch job's log); ``True`` asks for the bar, ``False`` for neither. The lines always
    go to ``pygran.log``."""
    terminal = sys.stderr.isatty()
    chosen = progress if progress is not None else default
    return (terminal if chosen is None else chosen), (chosen is None and not terminal)


class EngineLog:
    """The messages of the ``engine`` simulation writing into ``output``. When ``enabled`` is
    false (an MPI rank other than the first of the ranks sharing a simulation), it records and
    warns nothing: each message is the simulation's once."""

    def __init__(self, engine: str, output: Path, enabled: bool = True) -> None:
        self.engine = engine
        self.enabled = enabled
        #: Whether progress lines go to stderr too (see :func:`progress_shown`).
        self.progress_to_stderr = False
        self._logger = logging.getLogger(f"pygran.simulation.{engine}")
        self._handler = logging.FileHandler(output / LOG_NAME, encoding="utf-8")
        self._handler.setFormatter(logging.Formatter(_LOG_FORMAT))

    def log(self, message: str, *args: Any, level: int = logging.INFO) -> None:
        """Record ``message % args`` in ``pygran.log``, and on the ``pygran`` logger."""
        if not self.enabled:
            return
        record = self._logger.makeRecord(self._logger.name, level, __file__, 0, message, args, None)
        self._handler.handle(record)
        if self._logger.isEnabledFor(level):
            self._logger.handle(record)

    def to_file(self, level: int, message: str) -> None:
        """Record ``message`` in ``pygran.log`` only: what is also raised or warned, so that it
        does not reach the console twice."""
        if self.enabled:
            record = self._logger.makeRecord(self._logger.name, level, __file__, 0, "%s", (message,), None)
            self._handler.handle(record)

    def warn(self, message: str, category: type[Warning]) -> None:
        """Issue a warning at the user's line, recorded in ``pygran.log``."""
        if self.enabled:
            self.to_file(logging.WARNING, message)
            warnings.warn(message, category, stacklevel=user_stacklevel())

    def progress(self, text: str, stderr: bool = True) -> None:
        """A progress line into ``pygran.log`` and, if ``stderr`` and :attr:`progress_to_stderr`,
        on stderr, there from the first MPI rank only (under ``mpirun`` every rank runs the
        script)."""
        self.log("%s", text)
        if stderr and self.progress_to_stderr and launch_rank() == 0:
            print(f"{self.engine}: {text}", file=sys.stderr, flush=True)

    def close(self) -> None:
        self._handler.close()
