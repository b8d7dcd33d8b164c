"""Time-dependent analysis over the frames of a :class:`~pygran_core.analysis.System`.

Particles are matched across frames by their ``id`` (frames may gain and lose particles);
each method visits the frames in order and leaves the System on the frame it was on.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pygran_core.analysis import plot
from pygran_core.analysis.particles import Particles
from pygran_core.analysis.system import System
from pygran_core.errors import ConfigError


@dataclass(frozen=True)
class TimeSeries:
    """A quantity over the frames of a trajectory: ``time`` (one per frame) and ``value`` (one
    entry per frame: an array with a row per frame, or a list when the shapes differ).
    Unpacks as ``time, value = temporal.timeseries(...)``."""

    time: np.ndarray
    value: np.ndarray | list[Any]
    name: str = "value"

    def __iter__(self) -> Iterator[Any]:
        yield self.time
        yield self.value

    def table(self) -> np.ndarray:
        """One row per frame: the time, then the value (a scalar, or a vector's entries)."""
        values = np.asarray(self.value, dtype=float)
        if values.ndim > 2 or len(values) != len(self.time):
            raise ConfigError(
                f"TimeSeries.table: {self.name} is not one number or one vector per frame "
                f"(shape {values.shape}); index it first"
            )
        return np.column_stack([self.time, values.reshape(len(self.time), -1)])

    def plot(self, ax: Any = None, label: str | None = None, unit: str = "", units: str = "si") -> Any:
        """Plot the value against time (see :func:`pygran_core.analysis.plot.time_series`)."""
        return plot.time_series(self, label=label or self.name, unit=unit, units=units, ax=ax)


class Temporal:
    """Time series of a System's ``Particles`` (or of the SubSystem named ``subsystem``)."""

    def __init__(self, system: System, subsystem: str = "Particles") -> None:
        if subsystem not in system.names:
            raise ConfigError(f"Temporal: the System has no {subsystem!r}; it has {system.names}")
        self.system, self.subsystem = system, subsystem

    def _frames(self) -> Iterator[Any]:
        """Each frame's SubSystem, restoring the System's current frame afterwards."""
        start = self.system.frame
        try:
            for index in range(len(self.system)):
                self.system.goto(index)
                yield getattr(self.system, self.subsystem)
        finally:
            self.system.goto(start)

    def series(self, attr: str | Callable[..., Any], *args: Any, **kwargs: Any) -> np.ndarray | list[Any]:
        """``attr`` in every frame: an attribute name (``'x'``, ``'timestep'``), a method name
        (``'computeROG'``) or a function of the SubSystem, called with ``args`` and ``kwargs``
        (``series(mixing.lacey, resol=3e-3, species=1)``).

        Returns an array with one row per frame when the values have the same shape in every
        frame, else a list. :meth:`timeseries` pairs them with the frames' times.
        """
        current = getattr(self.system, self.subsystem)
        if (args or kwargs) and not callable(attr) and not callable(getattr(current, attr)):
            raise ConfigError(f"Temporal.series: {attr!r} is an attribute, it takes no arguments")
        values = []
        for obj in self._frames():
            value = attr(obj, *args, **kwargs) if callable(attr) else getattr(obj, attr)
            values.append(value(*args, **kwargs) if callable(value) else value)
        if len({np.shape(v) for v in values}) <= 1:
            return np.array(values)
        return values

    def timeseries(
        self, attr: str | Callable[..., Any], *args: Any, dt: float | None = None, **kwargs: Any
    ) -> TimeSeries:
        """:meth:`series` with each frame's time: a :class:`TimeSeries` ``(time, value)``, ready
        to tabulate (:meth:`TimeSeries.table`) or plot (:meth:`TimeSeries.plot`). Times are the
        frames' own, or ``timestep * dt`` when ``dt`` (the simulation's time step) is given."""
        name = attr if isinstance(attr, str) else getattr(attr, "__name__", "value")
        return TimeSeries(self._times(dt), self.series(attr, *args, **kwargs), name)

    def _times(self, dt: float | None) -> np.ndarray:
        """Time of each frame: ``timestep * dt`` when ``dt`` is given, else the frames' ``time``."""
        frames = [(obj.meta.get("timestep"), obj.meta.get("time")) for obj in self._frames()]
        if dt is not None:
            if any(step is None for step, _ in frames):
                raise ConfigError("Temporal: dt was given but some frames have no timestep")
            return np.array([step for step, _ in frames], dtype=float) * dt
        if any(time is None for _, time in frames):
            raise ConfigError(
                "Temporal: the frames carry no time; pass dt= (the simulation time step) to use timestep * dt"
            )
        return np.array([time for _, time in frames], dtype=float)

    def flowRate(
        self,
        point: Sequence[float],
        normal: Sequence[float],
        dt: float | None = None,
        density: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rate at which particles cross the plane through ``point`` with normal ``normal``,
        counted in the direction of ``normal``, between consecutive frames.

        A particle (matched by ``id``) crosses when its centre goes from behind the plane to in
        front of it (crossings back count negative). The rate is mass per time when the
        particles have a mass (``density=`` or a ``mass``/``density`` column), else particles
        per time. Returns (mid-interval times, rates), one per pair of frames.
        """
        unit = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
        origin = np.asarray(point, dtype=float)
        times = self._times(dt)
        crossed = []
        previous: tuple[np.ndarray, np.ndarray] | None = None
        for obj in self._frames():
            particles = self._particles(obj, "flowRate")
            ids = np.asarray(particles.id) if len(particles) else np.zeros(0, dtype=np.int64)
            side = (particles.positions - origin) @ unit > 0 if len(particles) else np.zeros(0, dtype=bool)
            try:
                weight = particles.computeMass(density) if len(particles) else np.zeros(0)
            except ValueError:
                weight = np.ones(len(particles))
            if previous is not None:
                old_ids, old_side = previous
                _, new_at, old_at = np.intersect1d(ids, old_ids, assume_unique=True, return_indices=True)
                direction = side[new_at].astype(int) - old_side[old_at].astype(int)
                crossed.append(float(direction @ weight[new_at]))
            previous = ids, side
        return 0.5 * (times[1:] + times[:-1]), np.array(crossed) / np.diff(times)

    def meanSquareDisplacement(
        self, dt: float | None = None, reference: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Mean square displacement from frame ``reference`` (default: the first frame with
        particles) of the particles present in both frames, matched by ``id``.

        Uses unwrapped coordinates ``xu, yu, zu`` when present. Returns (time since the
        reference, MSD); frames before the reference or sharing no particle give NaN.
        """
        snapshots = []
        for obj in self._frames():
            particles = self._particles(obj, "meanSquareDisplacement")
            keys = ("xu", "yu", "zu") if all(k in particles for k in ("xu", "yu", "zu")) else ("x", "y", "z")
            ids = np.asarray(particles.id) if len(particles) else np.zeros(0, dtype=np.int64)
            coords = (
                np.column_stack([particles[k] for k in keys]).reshape(-1, 3)
                if len(particles)
                else np.zeros((0, 3))
            )
            snapshots.append((ids, coords))
        if reference is None:
            reference = next((k for k, (ids, _) in enumerate(snapshots) if ids.size), 0)
        ref_ids, ref_coords = snapshots[reference]
        msd = np.full(len(snapshots), np.nan)
        for k, (ids, coords) in enumerate(snapshots[reference:], start=reference):
            _, at, ref_at = np.intersect1d(ids, ref_ids, assume_unique=True, return_indices=True)
            if at.size:
                msd[k] = ((coords[at] - ref_coords[ref_at]) ** 2).sum(axis=1).mean()
        times = self._times(dt)
        return times - times[reference], msd

    def granularTemperature(self) -> np.ndarray:
        """Granular temperature of each frame, ``<|v - <v>|^2> / 3`` (velocity fluctuations
        about the frame's mean velocity); NaN for frames without particles."""
        temperature = []
        for obj in self._frames():
            particles = self._particles(obj, "granularTemperature")
            if len(particles) == 0:
                temperature.append(np.nan)
                continue
            v = np.column_stack((particles.vx, particles.vy, particles.vz))
            temperature.append(((v - v.mean(axis=0)) ** 2).sum(axis=1).mean() / 3)
        return np.array(temperature)

    @staticmethod
    def _particles(obj: Any, what: str) -> Particles:
        if not isinstance(obj, Particles):
            raise TypeError(f"Temporal.{what} needs Particles, not {type(obj).__name__}")
        return obj
