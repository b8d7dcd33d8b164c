"""What a simulation writes as it runs: trajectory frames (particles, meshes, contacts) through
the registered writers, and monitor samples, at their frequencies in absolute steps.

The engine makes the frames; :class:`Output` decides when, writes them and keeps the writers.
A trajectory the engine's solver writes itself (LIGGGHTS' ``.dump`` and ``.vtk``) is declared
by the engine as a :class:`NativeTrajectory`: PyGran then writes none of its frames, and a
resume cuts it back with the engine's own frame copier.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import EngineError, ReadError
from pygran_core.formats import contacts as contact_schema
from pygran_core.io import Frame, TrajectoryWriter, open_trajectory, open_writer
from pygran_core.simulation.calls import MonitorSpec
from pygran_core.simulation.log import EngineLog
from pygran_core.simulation.resume import FrameCopier, cut_aside, cut_trajectory
from pygran_core.simulation.specs import SimulationSpec

#: Trajectory columns (``traj`` ``args``) of the per-particle vectors an engine extracts.
TRAJ_VECTORS = {
    "x": ("x", "y", "z"),
    "v": ("vx", "vy", "vz"),
    "f": ("fx", "fy", "fz"),
    "omega": ("omegax", "omegay", "omegaz"),
    "torque": ("tqx", "tqy", "tqz"),
}
TRAJ_SCALARS = ("id", "type", "radius", "mass")
#: ``density``: the true density of each particle's species, as LIGGGHTS' dump gives it.
TRAJ_COLUMNS = frozenset({*TRAJ_SCALARS, "density"}).union(*TRAJ_VECTORS.values())


@dataclass(frozen=True)
class NativeTrajectory:
    """A trajectory the engine's solver writes itself: ``cut`` copies the frames to keep on
    resume; ``due(step, time)`` is told of each frame the solver writes at that step."""

    cut: FrameCopier
    due: Callable[[int, float], None] = lambda step, time: None


@dataclass
class Monitor:
    """Scalars sampled during ``run``: ``values[name]`` is an array, one entry per sample."""

    handle: Any
    spec: MonitorSpec
    path: Path
    samples: list[tuple[float, ...]] = field(default_factory=list)

    @property
    def values(self) -> dict[str, np.ndarray]:
        table = np.array(self.samples, float).reshape(-1, 2 + len(self.spec.quantities))
        names = ("step", "time", *self.spec.quantities)
        return {name: table[:, i] for i, name in enumerate(names)}

    def rewrite(self) -> None:
        """Write the file anew: its header and every sample so far."""
        lines = [" ".join(repr(v) for v in row) + "\n" for row in self.samples]
        self.path.write_text("# step time " + " ".join(self.spec.quantities) + "\n" + "".join(lines))


def bounds(spec: SimulationSpec) -> tuple[np.ndarray, tuple[str, ...]]:
    """The box bounds and the boundary flags as a trajectory frame gives them."""
    box = np.array(spec.domain.box, float)
    return box, tuple(flag * 2 if len(flag) == 1 else flag for flag in spec.domain.boundary)


def particle_frame(
    spec: SimulationSpec, extract: Callable[[str], np.ndarray], step: int, time: float
) -> Frame:
    """The particles ``extract`` gives (those of species ``traj`` ``sel`` unless ``"all"``), as a
    trajectory frame with the ``traj`` columns in their order."""
    traj = spec.traj
    arrays: dict[str, np.ndarray] = {}
    for quantity, names in TRAJ_VECTORS.items():
        if set(traj.args) & set(names):
            values = extract(quantity)
            arrays.update({n: values[:, i] for i, n in enumerate(names)})
    for name in TRAJ_SCALARS:
        if name in traj.args:
            arrays[name] = extract(name)
    if "density" in traj.args:
        densities = np.array([0.0, *(species.density for species in spec.species)])
        arrays["density"] = densities[extract("type")]
    chosen = slice(None) if traj.sel == "all" else extract("type") == traj.sel
    box, boundary = bounds(spec)
    return Frame(
        {name: arrays[name][chosen] for name in traj.args},
        timestep=step,
        time=time,
        box=box,
        boundary=boundary,
    )


def contacts_frame(
    spec: SimulationSpec, records: Mapping[str, Any], where: str, step: int, time: float
) -> Frame:
    """The contact ``records`` (the columns of :data:`pygran_core.formats.contacts.COLUMNS`,
    checked: an :class:`EngineError` naming ``where`` they came from) as a contacts frame."""
    try:
        arrays = contact_schema.checked(records, where)
    except ValueError as exc:
        raise EngineError(str(exc)) from None
    box, boundary = bounds(spec)
    return Frame(
        arrays, timestep=step, time=time, box=box, boundary=boundary, attrs={"kind": contact_schema.KIND}
    )


def mesh_frame(triangles: list[np.ndarray], step: int, time: float) -> Frame:
    """Meshes, each its triangles' corners ``(T, 3, 3)``, as one frame of triangle cells with
    each cell's mesh (``meshid``: its index in ``triangles``)."""
    corners = np.concatenate(triangles) if triangles else np.zeros((0, 3, 3))
    meshid = (
        np.concatenate([np.full(len(t), i) for i, t in enumerate(triangles)]) if triangles else np.zeros(0)
    )
    cells = np.arange(3 * len(corners)).reshape(-1, 3)
    arrays = {
        "points": corners.reshape(-1, 3),
        "cells": cells,
        "cell_types": np.full(len(cells), 5),
        "meshid": meshid,
    }
    return Frame(
        arrays, timestep=step, time=time, attrs={"kind": "mesh", "point_data": [], "cell_data": ["meshid"]}
    )


class Output:
    """The trajectory files and monitors of a simulation of ``spec``. ``writes_files`` is false
    on the MPI ranks that share a simulation but do not write its files (all but its first);
    they still make the frames (gathering is collective) and keep the monitor samples.
    ``native``: the trajectories the engine's solver writes itself, by key."""

    def __init__(
        self, spec: SimulationSpec, log: EngineLog, writes_files: bool, native: Mapping[str, NativeTrajectory]
    ) -> None:
        self.spec = spec
        self.log = log
        self.writes_files = writes_files
        self.native = native
        self.monitors: dict[int, Monitor] = {}  # by handle id
        self.writers: dict[str, TrajectoryWriter] = {}  # by trajectory key

    def trajectories(self) -> Iterator[tuple[str, Path]]:
        """``(key, path)`` of each trajectory written: ``particles``, ``meshes`` (when there are
        meshes), ``contacts``."""
        traj = self.spec.traj
        for key, path in (("particles", traj.pfile), ("meshes", traj.mfile), ("contacts", traj.cfile)):
            if path is not None and (key != "meshes" or self.spec.meshes):
                yield key, path

    def frequencies(self) -> list[int]:
        """The intervals of the trajectory frames and monitor samples, in steps."""
        traj = self.spec.traj
        written = traj.pfile is not None or traj.mfile is not None or traj.cfile is not None
        return [m.spec.freq for m in self.monitors.values()] + ([traj.freq] if written else [])

    def add_monitor(self, handle: Any, spec: MonitorSpec, folder: Path) -> Monitor:
        monitor = Monitor(handle, spec, folder / spec.file)
        if self.writes_files:
            monitor.path.parent.mkdir(parents=True, exist_ok=True)  # file="monitors/ke.txt"
            monitor.rewrite()
        self.monitors[handle.id] = monitor
        return monitor

    def take(
        self,
        step: int,
        time: float,
        frames: Callable[[str], list[Frame]],
        scalar: Callable[[str], float],
        species_scalar: Callable[[str, tuple[int, ...]], float],
    ) -> None:
        """Write the trajectory frames (``frames(key)`` makes them) and take the monitor samples
        (``scalar(quantity)``, or ``species_scalar(quantity, species)`` of some species) due at
        ``step``."""
        if step % self.spec.traj.freq == 0:
            written = False
            for key, path in self.trajectories():
                self._write(key, path, step, time, frames)
                written = True
            if written:  # a dump stores the step only, as LIGGGHTS writes it: the log keeps each frame's time
                self.log.to_file(logging.INFO, f"trajectory frame at step {step}, time {time!r} s")
        for monitor in self.monitors.values():
            if step % monitor.spec.freq == 0:
                kinds, quantities = monitor.spec.species, monitor.spec.quantities
                values = (scalar(q) if kinds is None else species_scalar(q, kinds) for q in quantities)
                row = (float(step), time, *values)
                monitor.samples.append(row)
                if self.writes_files:
                    with monitor.path.open("a") as handle:
                        handle.write(" ".join(repr(v) for v in row) + "\n")

    def _write(
        self, key: str, path: Path, step: int, time: float, frames: Callable[[str], list[Frame]]
    ) -> None:
        native = self.native.get(key)
        if native is not None:
            native.due(step, time)
            return
        made = frames(key)  # on every rank: gathering is collective
        if not self.writes_files:
            return
        if key == "contacts" and self._contacts_with("particles"):
            key = "particles"  # the particle file's /contacts group
        if key not in self.writers:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.writers[key] = self._open(key, path)
        for frame in made:
            self.writers[key].write_frame(frame)

    def _contacts_with(self, key: str) -> bool:
        """Whether the trajectory ``key`` holds the contact records too (one H5MD file)."""
        return key == "particles" and self.spec.traj.cfile == self.spec.traj.pfile

    def _open(self, key: str, path: Path) -> TrajectoryWriter:
        return open_writer(path, contacts=True) if self._contacts_with(key) else open_writer(path)

    # -- checkpoints and resume ------------------------------------------------------------

    def samples(self) -> dict[int, np.ndarray]:
        """Every monitor's samples, by handle id, as a checkpoint keeps them."""
        return {
            h: np.array(m.samples, float).reshape(-1, 2 + len(m.spec.quantities))
            for h, m in self.monitors.items()
        }

    def check_samples(self, samples: Mapping[int, np.ndarray], where: Path) -> None:
        """Refuse a checkpoint's monitor ``samples`` (read from ``where``) that are not of this
        script's monitors, or not rows of their quantities."""
        unknown = sorted(set(samples) - set(self.monitors))
        if unknown:
            raise ReadError(f"{where}: monitors {unknown} are not among the script's monitors")
        for handle_id, values in samples.items():
            quantities = self.monitors[handle_id].spec.quantities
            if values.ndim != 2 or values.shape[1] != 2 + len(quantities):
                raise ReadError(
                    f"{where}: monitor {handle_id} has samples of shape {values.shape}, "
                    f"not rows of {2 + len(quantities)} (step, time, {', '.join(quantities)})"
                )

    def restore(self, samples: Mapping[int, np.ndarray], step: int) -> None:
        """Continue at ``step`` of a checkpoint: its monitor ``samples`` (see
        :meth:`check_samples`), and the trajectory files cut back to it: one holding several
        frames by :func:`.resume.cut_trajectory` with its writer's frame copier, one written a
        frame each by its writer's ``resume`` (later frames are overwritten as they come)."""
        for handle_id, values in samples.items():
            monitor = self.monitors[handle_id]
            monitor.samples = [tuple(float(v) for v in row) for row in values]
            if self.writes_files:
                monitor.rewrite()
        if not self.writes_files:
            return
        traj = self.spec.traj
        for key, path in self.trajectories():
            if key == "contacts" and path == traj.pfile:
                continue  # in the particle file: cut with it
            if path.is_file() or cut_aside(path).is_file():
                native = self.native.get(key)
                copier = native.cut if native is not None else self._copier(key)
                walls = [contact_schema.wall_file(path)] if key == "contacts" else []
                cut_trajectory(path, copier, step, self.log, walls)
            else:  # a file per frame: its writer keeps an index up to the step (a VTK series')
                path.parent.mkdir(parents=True, exist_ok=True)
                self.writers[key] = self._open(key, path)
                self.writers[key].resume(step)

    def _copier(self, key: str) -> FrameCopier:
        """PyGran's frame copier for the trajectory ``key``: its writer, kept open to append to."""

        def copy(original: Path, path: Path, step: int) -> int:
            writer = self.writers[key] = self._open(key, path)
            kept = 0
            with open_trajectory(original) as old, contextlib.ExitStack() as stack:
                contacts = old.contacts() if self._contacts_with(key) else None
                if contacts is not None:
                    stack.callback(contacts.close)
                for index in range(len(old)):
                    frames = [old[index]]
                    if contacts is not None and index < len(contacts):
                        frames.append(contacts[index])
                    if any(f.timestep is not None and f.timestep > step for f in frames):
                        break
                    for frame in frames:
                        writer.write_frame(frame)
                    kept += 1
            return kept

        return copy

    def close(self) -> None:
        for writer in self.writers.values():
            writer.close()
