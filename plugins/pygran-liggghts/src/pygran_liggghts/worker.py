"""The LIGGGHTS worker: ``python -m pygran_liggghts.worker SOCKET [liggghts args...]``.

Run alone or under ``mpirun -np N``. Rank 0 connects to the engine at the Unix socket
``SOCKET``, receives ``(request, params)`` pairs and broadcasts them; every rank executes
each request on the shared LIGGGHTS instance, and rank 0 sends back ``("ok", result)`` or
``("error", message)``. A LIGGGHTS error ends the job, which the engine notices.
"""

from __future__ import annotations

import socket
import sys
from multiprocessing.connection import Connection


def main(argv: list[str]) -> None:
    from mpi4py import MPI

    from pygran_liggghts.session import Session

    comm = MPI.COMM_WORLD
    address, args = argv[0], argv[1:]
    connection = None
    if comm.rank == 0:
        client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        client.connect(address)
        connection = Connection(client.detach())
    session = Session(args, comm, root=0)
    while True:
        request = None
        if connection is not None:
            try:
                request = connection.recv()
            except EOFError:  # the engine went away: shut down
                request = ("close", ())
        name, params = comm.bcast(request, root=0)
        try:
            if name not in Session.requests:
                raise ValueError(f"unknown request {name!r}")
            reply = ("ok", getattr(session, name)(*params))
        except Exception as exc:  # reported to the engine, which raises EngineError
            reply = ("error", f"{type(exc).__name__}: {exc}")
        if connection is not None and not connection.closed:
            try:
                connection.send(reply)
            except OSError:
                pass
        if name == "close":
            break


if __name__ == "__main__":
    main(sys.argv[1:])
