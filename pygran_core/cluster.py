"""The Dask cluster that PyGran's parallel routes run on: :meth:`System.map
<pygran_core.analysis.system.System.map>` (per-frame analysis) and :class:`Study
<pygran_core.simulation.study.Study>` (parameter studies).

Both take ``client``: a ``dask.distributed.Client`` (used as it is and left open), the
address of a running scheduler (``"tcp://head-node:8786"``; PyGran connects and disconnects),
None: a ``LocalCluster`` of ``workers`` processes with one thread each (default: one per
core), started for the call and shut down after it, or ``"serial"``: no cluster, one call after
the other in this process. Dask is optional: ``pip install pygran-core[dask]``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from pygran_core.errors import ConfigError, UnsupportedFeature

INSTALL = "pip install pygran-core[dask]"
#: The ``client`` that runs one call after the other in this process, with no cluster.
SERIAL = "serial"


def distributed(feature: str) -> Any:
    """The ``dask.distributed`` module, or :class:`UnsupportedFeature` saying how to install it."""
    try:
        import distributed as module
    except ImportError as exc:
        raise UnsupportedFeature(f"{feature} needs Dask's distributed scheduler: {INSTALL}") from exc
    return module


def default_workers() -> int:
    """Worker processes of a local cluster when none are asked for: the cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def is_serial(client: Any) -> bool:
    """Whether ``client`` asks for no cluster: ``"serial"``, one call after the other here."""
    return isinstance(client, str) and client == SERIAL


def check(client: Any, workers: int | None, feature: str) -> None:
    """Refuse, before anything runs, a ``workers`` count that is not one or that cannot apply:
    it sizes the local cluster of ``client=None`` only."""
    if workers is None:
        return
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"{feature}: workers={workers!r}: give a number of worker processes (1 or more)")
    if client is not None:
        where = "runs here, one call after the other" if is_serial(client) else "has workers of its own"
        raise ConfigError(
            f"{feature}: workers={workers} sizes the local cluster of client=None, but "
            f"client={client!r} {where}"
        )


@contextmanager
def connect(client: Any, workers: int | None, feature: str) -> Iterator[Any]:
    """The Dask client ``client`` names (see the module docstring); closes what it opened."""
    check(client, workers, feature)
    dd = distributed(feature)
    if isinstance(client, dd.Client):
        yield client
    elif isinstance(client, str) and not is_serial(client):
        try:
            remote = dd.Client(client)  # waits as long as Dask's distributed.comm.timeouts.connect
        except OSError as exc:
            raise ConfigError(
                f"{feature}: no Dask scheduler answers at {client!r} ({exc}); start one with `dask "
                "scheduler` and workers with `dask worker ADDRESS`, or use client=None for a local cluster"
            ) from exc
        with remote:
            yield remote
    elif client is None:
        count = default_workers() if workers is None else workers
        # processes of one thread each: the analysis kernels and solvers release the GIL only in
        # parts, and a crashing solver takes only its own worker down
        with (
            dd.LocalCluster(
                n_workers=count, threads_per_worker=1, processes=True, dashboard_address=":0"
            ) as cluster,
            dd.Client(cluster) as local,
        ):
            yield local
    else:
        raise ConfigError(
            f"{feature}: client={client!r}: give a dask.distributed.Client, a scheduler address such as "
            "'tcp://head-node:8786', None for a local cluster, or 'serial' to run here"
        )


def total_threads(client: Any) -> int:
    """Threads over all of the cluster's workers (at least 1)."""
    return max(1, sum(client.nthreads().values()))
