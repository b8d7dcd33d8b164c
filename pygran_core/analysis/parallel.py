"""Per-frame analysis in parallel on a Dask cluster: :meth:`System.map
<pygran_core.analysis.system.System.map>`.

The frames are cut into runs of consecutive frames, one Dask task each. A task carries the
recipe of the System (its file names, SubSystem classes, options and units), never frame data:
the worker opens the trajectories itself, reads only its frames, one after the other, calls the
function on each and returns the results, which come back in frame order. A worker process
reads at most :data:`FRAMES_PER_WORKER` frames at a time, however many threads it has.
"""

from __future__ import annotations

import sys
import threading
import types
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pygran_core import cluster
from pygran_core.analysis.subsystem import SubSystem
from pygran_core.errors import ConfigError, SelectionError, UnsupportedFeature
from pygran_core.io import Trajectory

#: Frames one worker process holds at most at any time (its tasks wait for each other beyond it).
FRAMES_PER_WORKER = 2
#: Tasks per worker thread: while the last tasks run, the other workers idle, up to a task's
#: time, so tasks are short; each opens the trajectories (about 25 ms), so a long trajectory
#: still makes few tasks of many frames.
TASKS_PER_THREAD = 16
_frames_held = threading.BoundedSemaphore(FRAMES_PER_WORKER)

Frames = int | slice | Sequence[int] | None


@dataclass(frozen=True)
class Recipe:
    """What a worker needs to open a System as the caller's: its class, the SubSystem classes,
    what each was given (file names, or a fixed SubSystem object), their options and the units."""

    system: Callable[..., Any]
    classes: Mapping[str, type[SubSystem]]
    given: Mapping[str, Any]
    options: Mapping[str, Any]
    units: str

    def open(self) -> Any:
        module = types.ModuleType("pygran_map_classes")  # resolve_class finds the caller's classes here
        module.__dict__.update(self.classes)
        return self.system(units=self.units, module=module, **self.options, **self.given)


def recipe(
    system: Callable[..., Any],
    classes: Mapping[str, type[SubSystem]],
    given: Mapping[str, Any],
    options: Mapping[str, Any],
    units: str,
) -> Recipe:
    """The :class:`Recipe` of a ``system`` (a System class) of SubSystem ``classes``, whose
    constructor was given the SubSystems ``given`` and the ``options``, now in ``units``; open
    trajectories cannot travel."""
    for name, value in given.items():
        if isinstance(value, Trajectory):
            raise UnsupportedFeature(
                f"System.map on a cluster: {name}= was given an open trajectory, which a worker cannot "
                f"reopen; give its file name instead (System({name}='traj.h5'))"
            )
    return Recipe(system, dict(classes), dict(given), dict(options), units)


def frame_indices(frames: Frames, n: int) -> list[int]:
    """``frames`` (None: all; an index; a slice; a sequence; negative counts from the end) as
    indices into ``n`` frames."""
    if frames is None:
        return list(range(n))
    if isinstance(frames, slice):
        return list(range(n))[frames]
    if isinstance(frames, (int, np.integer)) and not isinstance(frames, bool):
        frames = [int(frames)]
    if isinstance(frames, (str, bytes)) or not isinstance(frames, (Sequence, np.ndarray)):
        raise ConfigError(f"frames={frames!r}: give None (all), a frame index, a slice or a list of indices")
    chosen = []
    for f in frames:
        if isinstance(f, bool) or not isinstance(f, (int, np.integer)):
            raise ConfigError(f"frames: {f!r} is not a frame index")
        if not -n <= f < n:
            raise SelectionError(f"Frame {f} is out of range: the system has {n} frames (0..{n - 1})")
        chosen.append(int(f) % n)
    return chosen


def run_frames(source: Recipe, frames: list[int], func: Callable[[Any], Any]) -> list[Any]:
    """``func`` of the System ``source`` opens, at each of ``frames`` in turn (a worker's task).
    A task reads one frame at a time (moving on drops the last one), and holds one of the
    process's :data:`FRAMES_PER_WORKER` places while it runs."""
    with _frames_held, source.open() as system:
        return [func(system) for _ in _visit(system, frames)]


def map_frames(
    system: Any,
    source: Recipe | None,
    func: Callable[[Any], Any],
    frames: Frames,
    client: Any,
    workers: int | None,
    progress: bool | None,
) -> list[Any]:
    """:meth:`System.map <pygran_core.analysis.system.System.map>`; ``source`` is None on the serial path."""
    if not callable(func):
        raise ConfigError(f"System.map needs a function of the System, not {func!r}")
    cluster.check(client, workers, "System.map")
    chosen = frame_indices(frames, len(system))
    with _bar(len(chosen), progress) as bar:
        if source is None:
            here, results = system.frame, []
            try:
                for _ in _visit(system, chosen):
                    results.append(func(system))
                    bar.update(1)
            finally:
                system.goto(here)
            return results
        with cluster.connect(client, workers, "System.map") as dask_client:
            dd = cluster.distributed("System.map")
            parts = _split(chosen, TASKS_PER_THREAD * cluster.total_threads(dask_client))
            futures = [dask_client.submit(run_frames, source, part, func, pure=False) for part in parts]
            sizes = {future.key: len(part) for future, part in zip(futures, parts, strict=True)}
            try:
                for future in dd.as_completed(futures):
                    bar.update(sizes[future.key])
                done = dask_client.gather(futures)
            finally:
                dask_client.cancel(futures)
    return [result for part in done for result in part]


def _bar(total: int, progress: bool | None) -> Any:
    """The progress bar of a map: frames done, on a terminal unless ``progress`` says."""
    from tqdm import tqdm

    show = progress if progress is not None else sys.stderr.isatty()
    return tqdm(total=total, unit="frame", desc="System.map", disable=not show)


def _visit(system: Any, frames: list[int]) -> Iterator[int]:
    for frame in frames:
        system.goto(frame)
        yield frame


def _split(frames: list[int], pieces: int) -> list[list[int]]:
    """``frames`` in at most ``pieces`` runs of consecutive entries, of sizes differing by one at most."""
    pieces = max(1, min(pieces, len(frames)))
    bounds = np.linspace(0, len(frames), pieces + 1).round().astype(int)
    return [frames[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]
