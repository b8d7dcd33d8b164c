"""The LIGGGHTS worker: ``python -m pygran_liggghts.worker SOCKET [liggghts args...]``.

Run alone or under ``mpirun -np N``. Once LIGGGHTS is loaded, rank 0 connects to the
engine at the Unix socket ``SOCKET``, receives ``(request, params)`` pairs and broadcasts
them; every rank executes each request on the shared LIGGGHTS instance (a
:class:`Session`), and rank 0 sends back ``("ok", result)`` or ``("error", message)``. A
LIGGGHTS error ends the job, which the engine notices. When the engine goes away without
closing (its process killed), rank 0 removes the socket and its folder, which the engine
would have removed, and the job ends.

This module imports nothing of ``pygran_core``, so that a worker starts in the time of
numpy, mpi4py and the library.
"""

from __future__ import annotations

import os
import socket
import sys
from collections.abc import Sequence
from multiprocessing.connection import Connection
from typing import Any


class Session:
    """The requests PyGran makes of one LIGGGHTS instance (see :class:`~.binding.Liggghts`).

    ``root`` is the rank that receives gathered arrays (``None``: every rank); ``echo``
    prefixes LIGGGHTS' error lines also written to standard error (``None``: not written).
    """

    requests = frozenset(
        {"execute", "run", "timestep", "natoms", "gather", "assign", "scalar", "fix_vector", "close"}
    )

    def __init__(self, args: Sequence[str], comm: Any, root: int | None, echo: str | None = None) -> None:
        from pygran_liggghts.binding import Liggghts

        self.lmp = Liggghts(args, comm, echo)
        self.root = root

    def execute(self, lines: Sequence[str]) -> int:
        """Run ``lines``; returns the largest atom id afterwards (new atoms get the next ids)."""
        for line in lines:
            self.lmp.command(line)
        return self.lmp.max_id()

    def run(self, lines: Sequence[str], runs: int, inserting: Sequence[str]) -> tuple[int, list[Any]]:
        """Run ``lines``, the last ``runs`` of them ``run`` commands; ``inserting`` are the
        insertion fixes.

        Returns the largest atom id afterwards and, for each ``run``, the particles lost during
        it: their number (those present at its start and gone at its end, and those inserted
        during it and gone), and the positions and velocities at its start of those present then.
        """
        for line in lines[: len(lines) - runs]:
            self.lmp.command(line)
        losses = [self._run(line, inserting) for line in lines[len(lines) - runs :]]
        return self.lmp.max_id(), losses

    def _run(self, line: str, inserting: Sequence[str]) -> tuple[int, Any, Any]:
        """Run the ``run`` command ``line``: the particles lost (see :meth:`run`)."""
        import numpy as np

        comm = self.lmp.comm
        ids, x, v = (self.lmp.local(q) for q in ("id", "x", "v"))
        count, inserted = self.lmp.count(), self.lmp.inserted(inserting)
        self.lmp.command(line)
        now = self.lmp.local("id")
        made = self.lmp.inserted(inserting) - inserted
        lost = count + made - self.lmp.count()
        # LIGGGHTS numbers new particles on from the largest id present, so the ids of lost
        # particles come back: the ``made`` largest ids are the new particles' (none of them
        # lost: the engine ends a run at an insertion), unless that finds too many lost
        newest = np.sort(np.concatenate(comm.allgather(np.sort(now)[max(0, len(now) - made) :])))[-made:]
        for present in (now[~np.isin(now, newest)], now) if made else (now,):
            gone = ~np.isin(ids, present)  # gone from this rank: lost, or moved to another rank
            parts = comm.allgather((ids[gone], x[gone], v[gone]))
            candidates, start_x, start_v = (np.concatenate([part[i] for part in parts]) for i in range(3))
            elsewhere = comm.allreduce(np.isin(candidates, present).astype(np.int8), op=_sum())
            known = elsewhere == 0
            if known.sum() <= lost:
                break
        return max(lost, int(known.sum())), start_x[known], start_v[known]

    def timestep(self) -> int:
        return self.lmp.timestep()

    def natoms(self) -> int:
        return self.lmp.count()

    def gather(self, quantities: Sequence[str]) -> Any:
        return self.lmp.gather(quantities, root=self.root)

    def assign(self, quantity: str, ids: Any, value: Sequence[float]) -> None:
        self.lmp.assign(quantity, ids, value)

    def scalar(self, compute: str) -> float:
        return self.lmp.compute_scalar(compute)

    def fix_vector(self, fix: str, count: int) -> list[float]:
        return self.lmp.fix_vector(fix, count)

    def close(self) -> None:
        self.lmp.close()


def _sum() -> Any:
    from mpi4py import MPI

    return MPI.SUM


def main(argv: list[str]) -> None:
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    address, args = argv[0], argv[1:]
    session = Session(args, comm, root=0)  # before connecting: connected means ready
    connection = None
    gone = False  # whether the engine went away without closing
    if comm.rank == 0:
        client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            client.connect(address)
            connection = Connection(client.detach())
        except OSError:  # the engine went away before the worker started
            client.close()
            gone = True
        # connected or not, the socket's name is no longer needed: removed now, it is left
        # behind by no end of the worker's (one by a signal when the script dies included)
        remove_socket(address)
    while True:
        request = None
        if comm.rank == 0:
            try:
                request = ("close", ()) if connection is None else connection.recv()
            except (EOFError, OSError):  # the engine went away: shut down
                request, gone = ("close", ()), True
        name, params = comm.bcast(request, root=0)
        try:
            if name not in Session.requests:
                raise ValueError(f"unknown request {name!r}")
            reply = ("ok", getattr(session, name)(*params))
        except Exception as exc:  # noqa: BLE001 - reported to the engine, which raises EngineError
            reply = ("error", f"{type(exc).__name__}: {exc}")
        if connection is not None and not gone:
            try:
                connection.send(reply)
            except OSError:
                pass
        if name == "close":
            break


def remove_socket(address: str) -> None:
    """Remove the socket ``address`` and its folder (the engine's, which holds nothing else)."""
    for remove, path in ((os.unlink, address), (os.rmdir, os.path.dirname(address))):
        try:
            remove(path)
        except OSError:
            pass


if __name__ == "__main__":
    main(sys.argv[1:])
