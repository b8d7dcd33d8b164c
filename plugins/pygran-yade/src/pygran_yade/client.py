"""The adapter's side of the YADE worker: start it, send requests, turn failures into errors.

YADE runs in its own process (:mod:`pygran_yade.worker`, under the interpreter named by
the launcher), so a YADE crash ends that process and raises :class:`EngineError` here,
never taking the user's session with it. The worker is killed by :meth:`Worker.close`, at
interpreter exit if the user forgot, and by Linux when this process ends however it ends
(see :func:`~pygran_core.simulation.engine.die_with_parent`).
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import weakref
from pathlib import Path
from typing import Any

from pygran_core.errors import EngineError
from pygran_core.simulation.engine import die_with_parent
from pygran_yade import worker as worker_module
from pygran_yade.launcher import find_launcher, interpreter
from pygran_yade.worker import read_message, write_message

#: How many lines of the worker's log an error message quotes.
LOG_TAIL = 15
#: Seconds to wait for one answer (a run is split into pieces, each one answer); a worker
#: silent for longer is taken to be hung (YADE's periodic collider can hang) and stopped.
TIMEOUT_ENV = "PYGRAN_YADE_TIMEOUT"
DEFAULT_TIMEOUT = 600.0


def _kill(process: subprocess.Popen, streams: tuple[Any, ...]) -> None:
    for stream in streams:
        stream.close()
    if process.poll() is None:
        process.kill()
    process.wait()


class Worker:
    """A running YADE worker; :meth:`call` sends one request and returns its answer.

    ``log`` receives YADE's own output; ``threads`` sets its OpenMP threads.
    """

    def __init__(self, log: Path, threads: int = 1) -> None:
        found = interpreter(find_launcher())
        self.log_path = log
        requests_read, self._requests = os.pipe()
        self._answers, answers_write = os.pipe()
        env = {**os.environ, "PYTHONPATH": found.pythonpath, "OMP_NUM_THREADS": str(threads)}
        env.pop("PYTHONHOME", None)
        with open(log, "ab") as sink:
            self.process = subprocess.Popen(
                [found.python, "-u", worker_module.__file__, str(requests_read), str(answers_write)],
                stdin=subprocess.DEVNULL,
                stdout=sink,
                stderr=subprocess.STDOUT,
                pass_fds=(requests_read, answers_write),
                env=env,
                cwd=log.parent,
                preexec_fn=die_with_parent(),
            )
        os.close(requests_read)
        os.close(answers_write)
        self._out = os.fdopen(self._requests, "wb")
        self._in = os.fdopen(self._answers, "rb")
        self._finalizer = weakref.finalize(self, _kill, self.process, (self._out, self._in))
        self.version = self._receive("starting YADE")

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def call(self, method: str, /, **kwargs: Any) -> Any:
        """Run the worker's ``Simulation.<method>(**kwargs)``; YADE errors raise :class:`EngineError`.

        ``method`` is positional-only, so that any keyword (``name=`` too) reaches the worker."""
        if not self.alive:
            raise EngineError(f"The YADE worker is gone ({self._exit_reason()}); create a new simulation")
        try:
            write_message(self._out, (method, kwargs))
        except BrokenPipeError:
            pass  # the worker died: _receive says how
        return self._receive(method)

    def _receive(self, what: str) -> Any:
        timeout = float(os.environ.get(TIMEOUT_ENV, DEFAULT_TIMEOUT))
        ready, _, _ = select.select([self._in], [], [], timeout)
        if not ready:
            self._finalizer()
            raise EngineError(
                f"YADE did not answer within {timeout:g} s during {what}, so the worker was stopped "
                f"(set {TIMEOUT_ENV} to wait longer).{self._log_tail()}"
            )
        answer = read_message(self._in)
        if answer is None:
            self.process.wait()
            raise EngineError(f"YADE died during {what} ({self._exit_reason()}).{self._log_tail()}")
        status, value = answer
        if status == "error":
            raise EngineError(f"YADE error during {what}: {value}")
        return value

    def _exit_reason(self) -> str:
        code = self.process.poll()
        if code is None:
            return "still running"
        if code < 0:
            return f"killed by {signal.Signals(-code).name}"
        return f"exit code {code}"

    def _log_tail(self) -> str:
        try:
            lines = self.log_path.read_text(errors="replace").splitlines()[-LOG_TAIL:]
        except OSError:
            return ""
        return f" Last lines of {self.log_path}:\n" + "\n".join(lines) if lines else ""

    def close(self) -> None:
        """Ask the worker to exit, and kill it if it does not."""
        if self.alive:
            try:
                write_message(self._out, ("close", {}))
                self.process.wait(timeout=10)
            except (BrokenPipeError, subprocess.TimeoutExpired):
                pass
        self._finalizer()
