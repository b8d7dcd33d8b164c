"""Where LIGGGHTS runs: in this process (under ``mpirun``) or in a worker job it can crash.

:class:`~.worker.Session` is what the engine asks of LIGGGHTS; every rank of its
communicator runs the same requests. :class:`LocalSession` is a session in this process (the
manual's mode: the whole script runs under ``mpirun``, one LIGGGHTS instance per group of
ranks). :class:`WorkerSession` runs it in ``python -m pygran_liggghts.worker`` (under
``mpirun -np N`` for N > 1 ranks) and relays requests over a Unix socket, so that a LIGGGHTS
error, which ends its process, becomes an :class:`EngineError` carrying LIGGGHTS' message.
The worker starts in the background: the engine queues commands until it is :meth:`ready`.
"""

from __future__ import annotations

import os
import select
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from pygran_core.errors import EngineError
from pygran_liggghts.worker import Session

#: Seconds to wait for a worker to connect, and to exit after ``close``.
START_TIMEOUT = 120.0
EXIT_TIMEOUT = 30.0


class LocalSession(Session):
    """LIGGGHTS in this process on ``comm``; gathered arrays reach every rank."""

    def __init__(self, args: Sequence[str], comm: Any) -> None:
        super().__init__(args, comm, root=None)

    def ready(self) -> bool:
        return True

    def post(self, name: str, *params: Any) -> None:
        getattr(self, name)(*params)

    def request(self, name: str, *params: Any) -> Any:
        return getattr(self, name)(*params)


def error_message(*logs: Path) -> str | None:
    """The last ``ERROR`` line LIGGGHTS wrote to any of ``logs``."""
    found = None
    for log in logs:
        if log.is_file():
            for line in log.read_text(errors="replace").splitlines():
                if line.startswith("ERROR"):
                    found = line.strip()
    return found


def _tail(path: Path, lines: int = 5) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:]) if path.is_file() else ""


class WorkerSession:
    """LIGGGHTS on ``nprocs`` MPI ranks in a worker job; ``log`` is its screen output and
    ``stderr`` receives the job's own output (``mpirun`` and Python messages).

    The job starts in the background; the first request waits for it to connect.
    """

    def __init__(self, args: Sequence[str], nprocs: int, log: Path, stderr: Path) -> None:
        self.log, self.stderr = log, stderr
        self.connection: Connection | None = None
        self._posted = 0  # requests sent whose answers are not read yet
        self._dir = tempfile.mkdtemp(prefix="pygran-liggghts-")
        address = os.path.join(self._dir, "socket")
        self._server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._server.bind(address)
        self._server.listen(1)
        command = [sys.executable, "-m", "pygran_liggghts.worker", address, *args]
        if nprocs > 1:
            command = [*mpirun_prefix(nprocs), *command]
        self._deadline = time.monotonic() + START_TIMEOUT
        try:
            with stderr.open("w") as out:
                self.process = subprocess.Popen(
                    command, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
                )
        except BaseException:
            self._cleanup()
            raise

    def ready(self) -> bool:
        """Whether the worker has connected (never waits)."""
        if self.connection is None and self._server.fileno() >= 0:
            if select.select([self._server], [], [], 0)[0]:
                self._accept()
        return self.connection is not None

    def _accept(self) -> None:
        """Wait for the worker to connect; fail if it exits or does not connect in time."""
        while not select.select([self._server], [], [], 0.05)[0]:
            if self.process.poll() is not None:
                raise self._failure("could not start")
            if time.monotonic() > self._deadline:
                raise EngineError(
                    f"The LIGGGHTS worker did not connect within {START_TIMEOUT:g} s; see {self.stderr}"
                )
        client, _ = self._server.accept()
        client.setblocking(True)
        self.connection = Connection(client.detach())
        self._server.close()

    def post(self, name: str, *params: Any) -> None:
        """Send request ``name`` without waiting: the worker runs it while this process goes
        on; the next :meth:`request` checks its answer."""
        self._send((name, params))
        self._posted += 1

    def request(self, name: str, *params: Any) -> Any:
        """Run request ``name`` on every rank of the worker and return rank 0's answer."""
        self._send((name, params))
        try:
            replies = [self.connection.recv() for _ in range(self._posted + 1)]
        except (EOFError, OSError):
            raise self._failure("stopped") from None
        finally:
            self._posted = 0
        for status, value in replies:
            if status == "error":
                raise EngineError(value)
        return replies[-1][1]

    def _send(self, message: tuple[str, tuple[Any, ...]]) -> None:
        if self.connection is None:
            self._accept()
        try:
            self.connection.send(message)
        except OSError:
            raise self._failure("stopped") from None

    def _failure(self, what: str) -> EngineError:
        """The worker died: an :class:`EngineError` with LIGGGHTS' own message."""
        try:
            code = self.process.wait(EXIT_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait()
        self._cleanup()
        message = error_message(self.log, self.stderr)
        if message is None:
            how = f"signal {-code}" if code < 0 else f"exit code {code}"
            message = (
                f"no LIGGGHTS error message ({how}); last output:\n{_tail(self.log)}\n{_tail(self.stderr)}"
            )
        return EngineError(f"LIGGGHTS {what}: {message} (log: {self.log})")

    def close(self) -> None:
        """Delete the instance and wait for the worker to exit."""
        if self.process.poll() is None:
            try:
                self.request("close")
            finally:
                try:
                    self.process.wait(EXIT_TIMEOUT)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
        self._cleanup()

    def _cleanup(self) -> None:
        self._server.close()
        shutil.rmtree(self._dir, ignore_errors=True)


def mpirun_prefix(nprocs: int) -> list[str]:
    """``mpirun -np nprocs`` with the flags this machine needs (root, more ranks than cores)."""
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise EngineError("nprocs > 1 needs mpirun: apt-get install -y openmpi-bin")
    command = [mpirun, "-np", str(nprocs)]
    if os.geteuid() == 0:
        command.append("--allow-run-as-root")
    if nprocs > (os.cpu_count() or 1):
        command.append("--oversubscribe")
    return command


def under_mpirun() -> bool:
    """Whether this process was started by an MPI launcher."""
    return any(key in os.environ for key in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"))
