"""MPI launch: whether this process is one of several an MPI launcher (``mpirun``, ``srun``)
started, their communicator, the run of ``nSim`` each makes and the values they share.

mpi4py is optional: without it, or without a launcher, a script runs as one process.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from pygran_core.errors import ConfigError

#: Environment variables an MPI launcher (mpirun, srun) sets in every process it starts.
MPI_LAUNCH_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK")

#: Environment variables holding this process's rank, per launcher (Open MPI, MPICH and Slurm's PMI, PMIx).
MPI_RANK_VARIABLES = ("OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK")
#: Environment variables holding how many processes the launcher started (Open MPI, PMI).
MPI_SIZE_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE")

T = TypeVar("T")


def launch_size() -> int:
    """How many processes this one's MPI launcher started, 1 without a launcher (from its
    environment, as :func:`launch_rank`)."""
    for name in MPI_SIZE_VARIABLES:
        if name in os.environ:
            return int(os.environ[name])
    return 1


def launch_rank() -> int:
    """This process's rank as its MPI launcher numbered it, 0 without a launcher; read from the
    launcher's environment, so it needs no mpi4py and no communicator."""
    for name in MPI_RANK_VARIABLES:
        if name in os.environ:
            return int(os.environ[name])
    return 0


def launch_communicator() -> Any:
    """``MPI.COMM_WORLD`` when this process is one of several an MPI launcher started and
    mpi4py is installed, else ``None``."""
    if not any(name in os.environ for name in MPI_LAUNCH_VARIABLES):
        return None
    try:
        from mpi4py import MPI
    except ImportError:
        return None
    return MPI.COMM_WORLD if MPI.COMM_WORLD.size > 1 else None


def rank_run(runs: Sequence[T], engine: str) -> T:
    """This process's run of ``runs`` (the ``nSim`` runs of a spec), for an engine that makes
    each run on one MPI rank: under ``mpirun -np nSim``, rank k makes run k."""
    world = launch_communicator()
    if world is None or world.size != len(runs):
        started = "" if world is None else f", not {world.size}"
        raise ConfigError(
            f"nSim={len(runs)} makes one run per MPI rank on the {engine} engine: start the "
            f"script with mpirun -np {len(runs)}{started}"
        )
    return runs[world.rank]


def rank0_value(make: Callable[[], T]) -> T:
    """``make()`` on rank 0, and the same value on every rank launched with it (so that each
    rank does not read its own clock); ``make()`` alone when not launched by MPI."""
    comm = launch_communicator()
    if comm is None:
        return make()
    value: T = comm.bcast(make() if comm.rank == 0 else None, root=0)
    return value
