"""Where LIGGGHTS runs: in this process (under ``mpirun``) or in a worker job it can crash.

:class:`Session` is what the engine asks of LIGGGHTS; every rank of its communicator runs
the same requests. :class:`LocalSession` is a session in this process (the manual's mode:
the whole script runs under ``mpirun``, one LIGGGHTS instance per group of ranks).
:class:`WorkerSession` runs it in ``python -m pygran_liggghts.worker`` (under
``mpirun -np N`` for N > 1 ranks) and relays requests over a Unix socket, so that a LIGGGHTS
error, which ends its process, becomes an :class:`EngineError` carrying LIGGGHTS' message.
"""

from __future__ import annotations

import os
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

import numpy as np

from pygran_core.errors import EngineError

#: Seconds to wait for a worker to connect, and to exit after ``close``.
START_TIMEOUT = 120.0
EXIT_TIMEOUT = 30.0


class Session:
    """The requests PyGran makes of one LIGGGHTS instance (see :class:`~.binding.Liggghts`).

    ``root`` is the rank that receives gathered arrays (``None``: every rank).
    """

    requests = frozenset({"execute", "timestep", "natoms", "gather", "scalar", "close"})

    def __init__(self, args: Sequence[str], comm: Any, root: int | None) -> None:
        from pygran_liggghts.binding import Liggghts

        self.lmp = Liggghts(args, comm)
        self.root = root

    def execute(self, lines: Sequence[str]) -> int:
        """Run ``lines``; returns the largest atom id afterwards (new atoms get the next ids)."""
        for line in lines:
            self.lmp.command(line)
        return self.lmp.max_id()

    def timestep(self) -> int:
        return self.lmp.timestep()

    def natoms(self) -> int:
        return self.lmp.natoms()

    def gather(self, quantities: Sequence[str]) -> dict[str, np.ndarray] | None:
        return self.lmp.gather(quantities, root=self.root)

    def scalar(self, compute: str) -> float:
        return self.lmp.compute_scalar(compute)

    def close(self) -> None:
        self.lmp.close()


class LocalSession(Session):
    """LIGGGHTS in this process on ``comm``; gathered arrays reach every rank."""

    def __init__(self, args: Sequence[str], comm: Any) -> None:
        super().__init__(args, comm, root=None)

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
    ``stderr`` receives the job's own output (``mpirun`` and Python messages)."""

    def __init__(self, args: Sequence[str], nprocs: int, log: Path, stderr: Path) -> None:
        self.log, self.stderr = log, stderr
        self._dir = tempfile.mkdtemp(prefix="pygran-liggghts-")
        address = os.path.join(self._dir, "socket")
        server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        server.bind(address)
        server.listen(1)
        server.settimeout(0.2)
        command = [sys.executable, "-m", "pygran_liggghts.worker", address, *args]
        if nprocs > 1:
            command = [*mpirun_prefix(nprocs), *command]
        with stderr.open("w") as out:
            self.process = subprocess.Popen(
                command, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
            )
        try:
            self.connection = self._accept(server)
        except BaseException:
            self._cleanup()
            raise
        finally:
            server.close()

    def _accept(self, server: socket.socket) -> Connection:
        deadline = time.monotonic() + START_TIMEOUT
        while time.monotonic() < deadline:
            try:
                client, _ = server.accept()
            except TimeoutError:
                if self.process.poll() is not None:
                    raise self._failure("could not start") from None
                continue
            client.setblocking(True)
            return Connection(client.detach())
        raise EngineError(
            f"The LIGGGHTS worker did not connect within {START_TIMEOUT:g} s; see {self.stderr}"
        )

    def request(self, name: str, *params: Any) -> Any:
        """Run request ``name`` on every rank of the worker and return rank 0's answer."""
        try:
            self.connection.send((name, params))
            status, value = self.connection.recv()
        except (EOFError, OSError):
            raise self._failure("stopped") from None
        if status == "error":
            raise EngineError(value)
        return value

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
