"""The LIGGGHTS engine's line to its session: the commands it queues, records and sends, and
the requests LIGGGHTS answers.

Commands wait in a queue only while the worker starts (the script goes on meanwhile) and,
for particles created one by one, until the next request (their ``set atom`` lines merged
into ranges) or until :data:`STREAM_LINES` are queued, which are then sent without waiting
for the answer. Every command sent is appended to ``<output>/in.pygran``, which reruns
unchanged with the ``liggghts`` binary; angular velocities, which no LIGGGHTS 3.8 command
sets, are written into its arrays and only noted there in a comment. LIGGGHTS' screen output
goes to ``<output>/liggghts.log``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import EngineError
from pygran_liggghts.commands import fmt
from pygran_liggghts.session import LocalSession, WorkerSession

INPUT_NAME = "in.pygran"
LOG_NAME = "liggghts.log"
WORKER_LOG_NAME = "worker.log"
#: Queued lines of particles created one by one that are sent on without waiting.
STREAM_LINES = 1000


class Channel:
    """The session running one simulation's LIGGGHTS: under ``mpirun`` in this process's ranks
    (``comm``), else in a worker job of ``nprocs`` ranks. It keeps the lines LIGGGHTS has not
    run yet, the largest atom id it has given and whether the next run may skip its set-up; a
    failure of the session is kept, and ends the simulation. ``root``: whether this rank
    records the commands in ``in.pygran``; ``log``: the engine's log."""

    def __init__(self, output: Path, comm: Any, nprocs: int, root: bool, log: Callable[..., None]) -> None:
        self._log = log
        self.failure: EngineError | None = None
        self._pending: list[str] = []  # lines LIGGGHTS has not run yet
        #: ``[first, last, "keyword value ..."]``: the ``set atom first*last`` still open to
        #: particles created next with the same properties.
        self._open_set: list[Any] | None = None
        #: The largest atom id, as LIGGGHTS last answered and counted on since.
        self.max_id = 0
        #: No command since the last run: the next may skip its set-up.
        self.prepared = False
        self._record = (output / INPUT_NAME).open("w") if root else None
        # -nocite: LIGGGHTS would write log.cite into the script's working folder
        args = ["-screen", str(output / LOG_NAME), "-log", "none", "-nocite"]
        try:
            if comm is not None:
                self.session: Any = LocalSession(args, comm, str(output))
            else:
                self.session = WorkerSession(args, nprocs, output / LOG_NAME, output / WORKER_LOG_NAME)
        except BaseException:
            self._close_record()
            raise

    def ask(self, name: str, *params: Any, wait: bool = True) -> Any:
        """One request to the session (``wait=False``: its answer is checked by the next
        one); a failure is kept and ends this simulation."""
        if self.failure is not None:
            raise EngineError(f"This LIGGGHTS simulation stopped after an error: {self.failure}")
        try:
            if wait:
                return self.session.request(name, *params)
            self.session.post(name, *params)
        except EngineError as exc:
            self.failure = exc
            self._log("%s", exc)
            raise

    def request(self, name: str, *params: Any) -> Any:
        """Request ``name`` after the queued lines have run."""
        self.flush()
        return self.ask(name, *params)

    def gather(self, *names: str) -> dict[str, np.ndarray]:
        """The per-atom arrays ``names`` of every rank, ordered by id."""
        return self.request("gather", list(names))

    def queue(self, lines: Sequence[str], keep_set_open: bool = False) -> None:
        """Append ``lines`` to the lines LIGGGHTS has not run yet; ``keep_set_open``: after
        the open ``set atom`` (lines creating atoms whose properties may continue it)."""
        if not keep_set_open:
            self._close_set()
        self._pending += lines
        self.prepared = False

    def execute(self, lines: Sequence[str]) -> None:
        """Queue ``lines`` and run them now, unless the worker is still starting: then they run
        with the first request after it has started (errors in them are raised there)."""
        self.queue(lines)
        if self.failure is not None or self.session.ready():
            self.flush()

    def flush(self) -> None:
        """Run the queued lines in LIGGGHTS (waiting for the worker to start)."""
        lines = self._take()
        if lines:
            self.max_id = self.ask("execute", lines)

    def stream(self) -> None:
        """Send the queued lines without waiting once :data:`STREAM_LINES` are queued and the
        session has started: LIGGGHTS runs them while the script goes on."""
        if len(self._pending) >= STREAM_LINES and self.session.ready():
            self.ask("execute", self._take(), wait=False)

    def run(self, runs: list[str], fixes: list[str]) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Queue the ``run`` commands ``runs`` and run the queue; the particles lost in each
        run (see :meth:`~.worker.Session.run`), the insertion fixes ``fixes`` counted."""
        self.queue(runs)
        self.max_id, losses = self.ask("run", self._take(), len(runs), fixes)
        self.prepared = True
        return losses

    def set_atoms(self, first: int, last: int, values: str) -> None:
        """Queue ``set atom first*last values``, merged with the open one if it continues it."""
        current = self._open_set
        if current is not None and current[2] == values and current[1] + 1 == first:
            current[1] = last
            return
        self._close_set()
        self._open_set = [first, last, values]

    def set_omega(self, ids: np.ndarray, omega: Sequence[float], which: str) -> None:
        """Give the atoms ``ids`` the angular velocity ``omega``. LIGGGHTS 3.8 has no input
        command for it, so it is written into its arrays; ``in.pygran`` notes it in a comment."""
        self.flush()
        if self._record is not None:
            values = " ".join(fmt(w) for w in omega)
            self._record.write(f"# PyGran: omega {values} given to {which} through the library interface\n")
        self.request("assign", "omega", ids, tuple(omega))
        self.prepared = False  # the next run's set-up sends the new values to ghost atoms

    def close(self) -> None:
        """Run what is queued and end the session (unless it failed); close ``in.pygran``."""
        try:
            if self.failure is None:
                self.flush()
                self.session.close()
        finally:
            self._close_record()

    def _take(self) -> list[str]:
        """The queued lines, now recorded in ``in.pygran``."""
        self._close_set()
        lines, self._pending = self._pending, []
        if self._record is not None and lines:
            self._record.write("".join(line + "\n" for line in lines))
            self._record.flush()
        return lines

    def _close_set(self) -> None:
        if self._open_set is not None:
            first, last, values = self._open_set
            self._open_set = None
            atoms = f"{first}*{last}" if last > first else str(first)
            self._pending.append(f"set atom {atoms} {values}")

    def _close_record(self) -> None:
        if self._record is not None:
            self._record.close()
