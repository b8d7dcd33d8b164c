"""System: builds SubSystems (Particles, Mesh, user subclasses) from trajectories and moves
them through the frames together.

``System(Particles='traj*.dump', Mesh='mesh*.vtk', units='si')``: every keyword that starts
with an upper-case letter names a SubSystem class and gives its data; lower-case keywords
(other than ``units`` and ``module``) are passed to that class's constructor on every frame,
as in the manual's ``System(CoarseParticles='traj.dump', scale=3, percent=10.0,
module='coarseGrained')``. A class name is looked up first in ``module`` and then in
:mod:`pygran_core.analysis`.

``Contacts`` (:class:`~pygran_core.analysis.contacts.Contacts`) are the contact records of
each frame: ``Contacts='contacts*.dump'`` reads them from their own files, and a trajectory
whose file holds them too (an H5MD file's ``/contacts`` group) gives them without asking.

``module`` is a module object, an importable module name (``'coarseGrained'``; the running
script counts when its file is ``coarseGrained.py``, and ``coarseGrained.py`` in the current
directory is found too), or the path of a ``.py`` file. Loading a file never changes
``sys.path`` or ``sys.modules``.

The original PyGran's System calls work unchanged: ``for frame in system`` (rewinds, then
moves to each following frame and yields its number: 1, 2, ..., N - 1; frame 0 is the one
read on construction), ``system.skip()``, ``system.goto(-1)``, ``system.frame``,
``len(system)`` (the number of frames) and ``system.units("micro")``. ``system.time`` is the
current frame's simulated time.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from pygran_core import cluster
from pygran_core import units as _units
from pygran_core.analysis import parallel
from pygran_core.analysis.contacts import Contacts
from pygran_core.analysis.mesh import Mesh
from pygran_core.analysis.particles import Particles
from pygran_core.analysis.subsystem import SubSystem
from pygran_core.errors import ConfigError, ReadError, SelectionError, did_you_mean
from pygran_core.io import Trajectory, open_trajectory

PathLike = str | os.PathLike[str]
#: The SubSystem classes of :mod:`pygran_core.analysis`, by name.
BUILTIN_CLASSES: dict[str, Any] = {cls.__name__: cls for cls in (SubSystem, Particles, Mesh, Contacts)}


def load_module(module: ModuleType | PathLike) -> ModuleType:
    """The module ``module`` names: see the module docstring for the accepted forms."""
    if isinstance(module, ModuleType):
        return module
    text = os.fspath(module)
    if text.endswith(".py") or os.sep in text or "/" in text:
        return _module_from_file(Path(text))
    main = sys.modules.get("__main__")
    main_file = getattr(main, "__file__", None)
    if main is not None and main_file and Path(main_file).stem == text:
        return main
    try:
        return importlib.import_module(text)
    except ModuleNotFoundError as exc:
        if exc.name != text:
            raise
        local = Path.cwd() / f"{text}.py"
        if local.is_file():
            return _module_from_file(local)
        raise ConfigError(
            f"module={text!r}: no such module (looked on sys.path and for {local}); give an importable "
            "module name, the path of a .py file, or the module object"
        ) from None


def _module_from_file(path: Path) -> ModuleType:
    if not path.is_file():
        raise ConfigError(f"module={os.fspath(path)!r}: file not found ({path.resolve()})")
    spec = importlib.util.spec_from_file_location(path.stem, path)
    if spec is None or spec.loader is None:
        raise ConfigError(f"module={os.fspath(path)!r} cannot be imported as Python source")
    module = importlib.util.module_from_spec(spec)
    previous = sys.modules.get(spec.name)
    sys.modules[spec.name] = module  # only while it runs: decorators such as dataclass look it up
    try:
        spec.loader.exec_module(module)
    finally:
        if previous is None:
            del sys.modules[spec.name]
        else:
            sys.modules[spec.name] = previous
    return module


def resolve_class(name: str, module: ModuleType | None = None) -> type[SubSystem]:
    """The SubSystem subclass called ``name`` in ``module``, else in :mod:`pygran_core.analysis`."""
    places = [vars(module), BUILTIN_CLASSES] if module is not None else [BUILTIN_CLASSES]
    for place in places:
        candidate = place.get(name)
        if isinstance(candidate, type) and issubclass(candidate, SubSystem):
            return candidate
    known = sorted(
        {k for place in places for k, v in place.items() if isinstance(v, type) and issubclass(v, SubSystem)}
    )
    hint = "" if module is not None else " A class of your own needs module=... (see System's documentation)."
    raise ConfigError(
        f"System: unknown SubSystem class {name!r}.{did_you_mean(name, known)} "
        f"Known: {', '.join(known)}.{hint}"
    )


def _freeze(values: Any) -> None:
    """Make ``values`` and every array it views read-only."""
    while isinstance(values, np.ndarray):
        values.setflags(write=False)
        values = values.base


class _Source:
    """One SubSystem of a System: a trajectory read frame by frame, or a fixed object."""

    def __init__(self, cls: type[SubSystem], value: Any, options: dict[str, Any]) -> None:
        self.cls, self.options = cls, options
        self.trajectory: Trajectory | None = None
        self.fixed: SubSystem | None = None
        # contact records: the readers' contacts=True (an H5MD file's contacts, not its particles)
        reading: dict[str, Any] = {"contacts": True} if issubclass(cls, Contacts) else {}
        if isinstance(value, SubSystem):
            if not isinstance(value, cls):
                raise ConfigError(f"System: {cls.__name__}= was given a {type(value).__name__}")
            self.fixed = value
        elif isinstance(value, Trajectory):
            self.trajectory = value
        elif isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], dict):
            self.trajectory = open_trajectory(value[0], **{**reading, **value[1]})
        elif isinstance(value, (str, os.PathLike)) or (
            isinstance(value, Sequence) and value and all(isinstance(v, (str, os.PathLike)) for v in value)
        ):
            self.trajectory = open_trajectory(value, **reading)
        else:
            raise ConfigError(
                f"System: {cls.__name__}= takes a file name or glob, a list of files, (file, options), an "
                f"open trajectory or a {cls.__name__} object, not {value!r}"
            )
        #: whether the trajectory was opened here (its frames are read for this System only)
        self.opened = self.trajectory is not None and self.trajectory is not value
        if self.trajectory is not None and self.trajectory.n_frames == 0:
            if self.opened:
                self.trajectory.close()
            raise ReadError(
                f"System: {cls.__name__}={value!r} holds no frames, so there is nothing to analyse (a run "
                "stopped before it wrote its first frame leaves such a file)"
            )

    @property
    def n_frames(self) -> int:
        return 1 if self.trajectory is None else self.trajectory.n_frames

    def build(self, index: int, units: str) -> SubSystem:
        if self.trajectory is None:
            assert self.fixed is not None
            return self.fixed if self.fixed.units == units else self.fixed.copy().convert(units)
        frame = self.trajectory.read_frame(min(index, self.trajectory.n_frames - 1))
        if self.opened:  # the reader made the frame's arrays for this object alone: kept, not copied
            for values in frame.arrays.values():
                _freeze(values)
        obj = self.cls(**self.cls._frame_kwargs(frame), **self.options)
        return obj if obj.units == units else obj.convert(units)


class System:
    """A DEM system: one or more SubSystems read from trajectories, moved frame by frame.

    ``len(system)`` is the number of frames and :attr:`frame` the current one (0 after
    construction). ``for frame in system`` is the original's loop: it rewinds to frame 0 (the
    one a script reads before its loop), then moves to each following frame in order (the
    trajectory's files sorted by their numbers: ``particles1000.dump`` after
    ``particles900.dump``) and yields its number, 1 to N - 1, and rewinds at the end;
    :meth:`frames` visits every frame from 0, yielding its index. :meth:`goto`
    jumps anywhere (negative counts from the end), :meth:`skip` to the first frame with
    elements. ``system.Particles`` (or any given class name) is the SubSystem of the
    current frame, read when first used. Trajectories of one frame and ready-made objects
    stay the same in every frame.
    """

    def __init__(self, units: str = "si", module: ModuleType | PathLike | None = None, **kwargs: Any) -> None:
        _units.exponent("length", units, "si")  # unknown unit systems are a ConfigError
        user_module = None if module is None else load_module(module)
        options = {k: v for k, v in kwargs.items() if not k[:1].isupper()}
        named = {k: v for k, v in kwargs.items() if k[:1].isupper()}
        if not named:
            raise ConfigError(
                "System needs at least one SubSystem, e.g. System(Particles='traj*.dump', Mesh='mesh*.vtk')"
            )
        self._sources = {
            name: _Source(resolve_class(name, user_module), v, options) for name, v in named.items()
        }
        self._given, self._options = named, options  # what System.map's workers reopen
        for source in list(self._sources.values()):  # the contact records a trajectory's file holds
            stored = (
                None
                if source.trajectory is None or "Contacts" in self._sources
                else source.trajectory.contacts()
            )
            if stored is not None and stored.n_frames == 0:  # laid out for contacts, none written
                stored.close()
            elif stored is not None:
                self._sources["Contacts"] = _Source(Contacts, stored, {})
        counts = {name: s.n_frames for name, s in self._sources.items() if s.n_frames > 1}
        if len(set(counts.values())) > 1:
            raise ConfigError(f"System: the trajectories have different numbers of frames: {counts}")
        self._n_frames = max(counts.values(), default=1)
        self._units = units
        self._frame = 0
        self._current: dict[str, SubSystem] = {}

    @property
    def units(self) -> _units.UnitName:
        """The unit system every SubSystem is expressed in (a ``str``).

        ``system.units("micro")`` (the original's method) converts the current frame's
        SubSystems in place, so references to them see the new numbers, and every frame
        read afterwards; ``system.units()`` returns the name.
        """
        return _units.UnitName(self._units, self._convert)

    def _convert(self, units: str) -> None:
        for name, obj in self._current.items():
            if obj is self._sources[name].fixed:  # never change an object the user passed in
                self._current[name] = obj.copy().convert(units)
            else:
                obj.convert(units)
        self._units = units

    @property
    def frame(self) -> int:
        """Index of the current frame."""
        return self._frame

    @property
    def names(self) -> list[str]:
        """Names of the SubSystems (``['Particles', 'Mesh']``)."""
        return list(self._sources)

    def __len__(self) -> int:
        return self._n_frames

    def __getattr__(self, name: str) -> SubSystem:
        sources = self.__dict__.get("_sources", {})
        if name not in sources:
            raise AttributeError(
                f"System has no attribute {name!r}.{did_you_mean(name, sources)} "
                f"Its SubSystems: {', '.join(sources) or 'none'}."
            )
        if name not in self._current:
            self._current[name] = sources[name].build(self._frame, self._units)
        return self._current[name]

    def goto(self, frame: int) -> int:
        """Make ``frame`` (negative counts from the end) the current frame; returns its index."""
        n = self._n_frames
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
            raise ConfigError(f"goto needs a frame number, not {frame!r}")
        if not -n <= frame < n:
            raise SelectionError(f"Frame {frame!r} is out of range: the system has {n} frames (0..{n - 1})")
        frame = int(frame)
        if frame % n != self._frame:
            self._frame = frame % n
            self._current = {}
        return self._frame

    def rewind(self) -> int:
        """Go back to the first frame."""
        return self.goto(0)

    def next(self) -> int:
        """Advance one frame and return its index; StopIteration after the last frame."""
        if self._frame + 1 >= self._n_frames:
            raise StopIteration(f"The system has no frame after {self._frame}")
        return self.goto(self._frame + 1)

    __next__ = next

    def skip(self) -> int:
        """Go to the first frame (from the current one on) in which some SubSystem has elements,
        skipping empty frames as the original did; returns its index. Stays on the last frame
        when every later frame is empty."""
        while (
            not any(len(getattr(self, name)) for name in self._sources) and self._frame + 1 < self._n_frames
        ):
            self.goto(self._frame + 1)
        return self._frame

    @property
    def timestep(self) -> int:
        """Timestep of the current frame: the first SubSystem's that has one, else the frame index."""
        for name in self._sources:
            step = getattr(self, name).meta.get("timestep")
            if step is not None:
                return int(step)
        return self._frame

    @property
    def time(self) -> float:
        """Simulated time of the current frame (in the System's units): the first SubSystem's
        that has one. A :class:`ConfigError` when the files hold none (a LIGGGHTS dump written
        without ``ITEM: TIME``), naming the remedy."""
        for name in self._sources:
            time = getattr(self, name).meta.get("time")
            if time is not None:
                return float(time)
        raise ConfigError(
            f"frame {self._frame} of this System carries no time (its files hold timesteps only, "
            f"{self.timestep} here): multiply system.timestep by the simulation's time step, or pass "
            "dt= to the analysis (Temporal(system).timeseries(..., dt=...))"
        )

    def frames(self) -> Iterator[int]:
        """Visit every frame from the first, yielding its index; rewinds at the end."""
        for frame in range(self._n_frames):
            self.goto(frame)
            yield frame
        self.rewind()

    def __iter__(self) -> Iterator[int]:
        frames = self.frames()
        next(frames)  # frame 0, which a script reads before its loop
        yield from frames

    def __repr__(self) -> str:
        where = f"frame {self._frame} of {self._n_frames}, units={self._units!r}"
        return f"System({', '.join(self._sources)}; {where})"

    def __enter__(self) -> System:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def map(
        self,
        func: Callable[[System], Any],
        frames: parallel.Frames = None,
        client: Any = None,
        workers: int | None = None,
        progress: bool | None = None,
    ) -> list[Any]:
        """``[func(system) for each frame]`` in parallel on a Dask cluster, in frame order.

        ``func`` takes the System at a frame (``lambda s: s.Particles.computeRDF()``) and returns
        anything picklable; ``frames``: None (all), an index, a slice or a list. ``client``: a
        ``dask.distributed.Client``, a scheduler address (``"tcp://host:8786"``), None for a
        ``LocalCluster`` of ``workers`` processes of one thread each (default: one per core),
        or ``"serial"`` to run here, frame after frame. Workers open the trajectories by their
        file names and read only their frames (at most two at a time each); see
        :mod:`pygran_core.analysis.parallel`. A progress bar counts the frames done, on a
        terminal unless ``progress=False``.
        """
        if cluster.is_serial(client):
            return parallel.map_frames(self, None, func, frames, client, workers, progress)
        classes = {name: source.cls for name, source in self._sources.items()}
        source = parallel.recipe(type(self), classes, self._given, self._options, self._units)
        return parallel.map_frames(self, source, func, frames, client, workers, progress)

    def close(self) -> None:
        """Close the trajectories' files."""
        for source in self._sources.values():
            if source.trajectory is not None:
                source.trajectory.close()
