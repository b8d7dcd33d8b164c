"""Where LIGGGHTS runs: in this process (under ``mpirun``) or in a worker job it can crash.

:class:`~.worker.Session` is what the engine asks of LIGGGHTS; every rank of its
communicator runs the same requests. :class:`LocalSession` is a session in this process (the
manual's mode: the whole script runs under ``mpirun``, one LIGGGHTS instance per group of
ranks). :class:`WorkerSession` runs it in ``python -m pygran_liggghts.worker`` (under
``mpirun -np N`` for N > 1 ranks) and relays requests over a Unix socket, so that a LIGGGHTS
error, which ends its process, becomes an :class:`EngineError` carrying LIGGGHTS' message.
The worker starts in the background: the engine queues commands until it is :meth:`ready`,
and ends with this process, however it ends (see
:func:`~pygran_core.simulation.engine.die_with_parent`).
"""

from __future__ import annotations

import os
import re
import select
import shutil
import signal
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
from pygran_core.simulation.engine import die_with_parent
from pygran_liggghts.worker import Session

#: The end of a LIGGGHTS error message: its source line, ``(./src/input.cpp:327)``.
SOURCE_LINE = re.compile(r"\(\S+:\d+\)$")
#: Lines an error message may span.
MESSAGE_LINES = 10
#: Seconds to wait for a worker to connect, and to exit after ``close``.
START_TIMEOUT = 120.0
EXIT_TIMEOUT = 30.0
#: Open MPI's cm PML probes the libraries of fast interconnects (PSM, PSM2, libfabric) at every
#: start, 0.2 s, for networks a job on one node does not use; the worker leaves it out unless
#: the environment chooses a PML or an MTL (``OMPI_MCA_pml``, ``OMPI_MCA_mtl``).
WORKER_MPI = {"OMPI_MCA_pml": "^cm"}


class LocalSession(Session):
    """LIGGGHTS in this process on ``comm``; gathered arrays reach every rank. A LIGGGHTS
    error ends the MPI job: its message goes to standard error first, prefixed with ``name``
    (the run's output directory), once (see :mod:`~.screen`)."""

    def __init__(self, args: Sequence[str], comm: Any, name: str) -> None:
        super().__init__(args, comm, root=None, echo=f"LIGGGHTS stopped in {name}")

    def ready(self) -> bool:
        return True

    def post(self, name: str, *params: Any) -> None:
        getattr(self, name)(*params)

    def request(self, name: str, *params: Any) -> Any:
        return getattr(self, name)(*params)


def error_message(log: Path, stderr: Path) -> str | None:
    """LIGGGHTS' error: the last ``ERROR`` line, with the lines that continue it up to its
    source line ``(file:line)``, in the screen file ``log``, else in a rank's screen file,
    else in the job's output ``stderr``."""
    ranks = sorted(log.parent.glob(f"{log.stem}.rank*{log.suffix}"))
    for path in (log, *ranks, stderr):
        if not path.is_file():
            continue
        lines = [line.strip() for line in path.read_text(errors="replace").splitlines()]
        starts = [i for i, line in enumerate(lines) if line.startswith("ERROR")]
        if starts:
            message = lines[starts[-1] : starts[-1] + MESSAGE_LINES]
            ends = [i for i, line in enumerate(message) if SOURCE_LINE.search(line)]
            return " ".join(message[: ends[0] + 1] if ends else message[:1])
    return None


def signal_message(code: int, stderr: Path) -> str | None:
    """How a worker ended by a signal: its name and, from the backtrace Open MPI prints, the
    innermost LIGGGHTS function; ``None`` if it did not end by a signal."""
    text = stderr.read_text(errors="replace") if stderr.is_file() else ""
    number = -code if code < 0 else None
    match = re.search(r"exited on signal (\d+)", text) or re.search(r"Signal: .*\((\d+)\)", text)
    if number is None and match is not None:
        number = int(match.group(1))
    if number is None:
        return None
    try:
        name = f"{signal.Signals(number).name} ({signal.strsignal(number)})"
    except ValueError:
        name = f"signal {number}"
    frame = re.search(r"libliggghts[^(]*\(([^+)]+)", text)
    where = f" in {demangle(frame.group(1))}" if frame else ""
    return f"LIGGGHTS ended by {name}{where}"


def demangle(symbol: str) -> str:
    """A C++ symbol readable (``c++filt``, when installed)."""
    tool = shutil.which("c++filt")
    if tool is None:
        return symbol
    try:
        return subprocess.run([tool, symbol], capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return symbol


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
                    command,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                    env=worker_env(),
                    # mpirun takes its ranks down on SIGTERM; a lone worker is killed
                    preexec_fn=die_with_parent(signal.SIGTERM if nprocs > 1 else signal.SIGKILL),
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

    def _accept(self) -> Connection:
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
        return self.connection

    def post(self, name: str, *params: Any) -> None:
        """Send request ``name`` without waiting: the worker runs it while this process goes
        on; the next :meth:`request` checks its answer."""
        self._send((name, params))
        self._posted += 1

    def request(self, name: str, *params: Any) -> Any:
        """Run request ``name`` on every rank of the worker and return rank 0's answer."""
        connection = self._send((name, params))
        try:
            replies = [connection.recv() for _ in range(self._posted + 1)]
        except (EOFError, OSError):
            raise self._failure("stopped") from None
        finally:
            self._posted = 0
        for status, value in replies:
            if status == "error":
                raise EngineError(value)
        return replies[-1][1]

    def _send(self, message: tuple[str, tuple[Any, ...]]) -> Connection:
        """Send ``message`` (waiting for the worker to connect); returns the connection."""
        connection = self.connection if self.connection is not None else self._accept()
        try:
            connection.send(message)
        except OSError:
            raise self._failure("stopped") from None
        return connection

    def _failure(self, what: str) -> EngineError:
        """The worker died: an :class:`EngineError` with LIGGGHTS' own message (and source
        line), or the signal that ended it and where."""
        try:
            code = wait_exit(self.process, EXIT_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait()
        self._cleanup()
        message = error_message(self.log, self.stderr) or signal_message(code, self.stderr)
        if message is None:
            message = (
                f"no LIGGGHTS error message (exit code {code}); last output:\n{_tail(self.log)}\n"
                f"{_tail(self.stderr)}"
            )
        return EngineError(f"LIGGGHTS {what}: {message} (log: {self.log}, job output: {self.stderr})")

    def close(self) -> None:
        """Delete the instance and wait for the worker to exit."""
        if self.process.poll() is None:
            try:
                self.request("close")
            finally:
                try:
                    wait_exit(self.process, EXIT_TIMEOUT)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
        self._cleanup()

    def _cleanup(self) -> None:
        self._server.close()
        shutil.rmtree(self._dir, ignore_errors=True)


def worker_env() -> dict[str, str]:
    """This process's environment with :data:`WORKER_MPI` where it chooses no PML or MTL."""
    env = dict(os.environ)
    if not {"OMPI_MCA_pml", "OMPI_MCA_mtl"} & env.keys():
        env.update(WORKER_MPI)
    return env


def wait_exit(process: subprocess.Popen[bytes], timeout: float) -> int:
    """``process.wait(timeout)`` on a pidfd where Linux has them: ``Popen.wait`` with a timeout
    polls, sleeping up to 50 ms between checks, which delayed the end of every simulation."""
    try:
        pidfd = os.pidfd_open(process.pid)
    except (AttributeError, OSError):  # not Linux, or the process is reaped already
        return process.wait(timeout)
    try:
        if not select.select([pidfd], [], [], timeout)[0]:
            raise subprocess.TimeoutExpired(process.args, timeout)
    finally:
        os.close(pidfd)
    return process.wait()


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
