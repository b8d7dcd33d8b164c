"""The :class:`Engine` base class: what every DEM engine shares.

An engine owns a solver. The base class owns the behaviour that must not differ between
engines: the output directory (created, never ``chdir``-ed into), the log of every call in
``<output>/pygran.log``, capability checks that name the engines able to do what was asked,
the checks that need the particles present (ids given to ``set``, overlapping created
particles), handle bookkeeping for ``remove``, and ``run``: the time-step check
(:mod:`~pygran_core.simulation.timestep`), the progress bar, step/time accounting, the
schedule of trajectory frames, monitor samples and checkpoints, between which the solver
runs without returning to Python, and the report of the particles lost in the run. An
engine implements the ``_underscored`` hooks.
"""

from __future__ import annotations

import abc
import contextlib
import ctypes
import dataclasses
import errno
import fcntl
import functools
import hashlib
import itertools
import logging
import os
import signal
import sys
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, ClassVar

import numpy as np

from pygran_core.errors import (
    ConfigError,
    EngineError,
    LostParticlesWarning,
    PyGranError,
    ReadError,
    ServoWarning,
    TimeStepWarning,
    UnsupportedFeature,
    unknown_key,
)
from pygran_core.formats import contacts as _contacts
from pygran_core.io import Frame, TrajectoryWriter, open_trajectory, open_writer
from pygran_core.registry import engines_with
from pygran_core.simulation.calls import (
    CreateSpec,
    InsertSpec,
    MonitorSpec,
    MotionSpec,
    SetSpec,
    ViscousSpec,
    WallSpec,
)
from pygran_core.simulation.checkpoint import (
    Checkpoint,
    checkpoint_path,
    latest_checkpoint,
    read_checkpoint,
    write_checkpoint,
)
from pygran_core.simulation.diagnostics import (
    FACES,
    SERVO_WATCH,
    LostParticles,
    LostWatch,
    TimeStepLimits,
    check_clear,
    check_run_size,
    check_servo_speeds,
    check_spec,
    force_servos,
    lost_cause,
    servo_error,
    servo_swing,
    species_present,
)
from pygran_core.simulation.log import EngineLog
from pygran_core.simulation.materials import MaterialTable, build_table
from pygran_core.simulation.output import TRAJ_SCALARS, TRAJ_VECTORS
from pygran_core.simulation.progress import Progress
from pygran_core.simulation.specs import SimulationSpec, positive_float, positive_int
from pygran_core.simulation.timestep import Assessment

#: Per-particle quantities ``extract`` knows, with their shape per particle.
EXTRACTABLE = {"x": 3, "v": 3, "omega": 3, "f": 3, "torque": 3, "radius": 1, "mass": 1, "id": 1, "type": 1}
#: A run's pieces are listed this many steps at a time (:meth:`Engine._run_chunks`).
RUN_SEGMENT = 100_000


#: The file in an output folder a live simulation holds locked (``flock``), with its process id.
LOCK_NAME = ".pygran.lock"


def claim_output(output: Path) -> IO[str]:
    """Make the folder ``output`` and lock it for this simulation, before any file in it is
    opened for writing; the lock lasts while the returned file is open (the process's end
    releases it, however it ends). A folder that cannot be made or written, or that another
    live simulation holds, is a :class:`ConfigError` saying which. Under an MPI launcher the
    ranks of one run share its folder: rank 0 locks it for all of them."""
    rank = os.environ.get("OMPI_COMM_WORLD_RANK", os.environ.get("PMI_RANK", "0"))
    try:
        output.mkdir(parents=True, exist_ok=True)
        if not os.access(output, os.W_OK | os.X_OK):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
        lock = open(output / LOCK_NAME, "a+", encoding="utf-8")
        if rank != "0":
            return lock  # held open, unlocked: rank 0's lock covers the run
    except OSError as exc:
        what = "a file is in its place or in a parent's" if exc.errno in (errno.EEXIST, errno.ENOTDIR) else ""
        raise ConfigError(
            f"output {str(output)!r} cannot be made or written: {what or exc.strerror or exc}; give a "
            "folder you can write"
        ) from None
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.seek(0)
        holder = lock.read().strip()
        lock.close()
        whose = "of this script, not closed yet" if holder == str(os.getpid()) else f"process {holder}"
        raise ConfigError(
            f"output {str(output)!r} is in use by another live simulation ({whose}), whose files this one "
            "would overwrite: give another output folder, or close that simulation first"
        ) from None
    lock.truncate(0)
    lock.write(str(os.getpid()))
    lock.flush()
    return lock


#: ``prctl``'s option that has Linux signal a process when the thread that started it ends.
PR_SET_PDEATHSIG = 1


def die_with_parent(sig: int = signal.SIGKILL) -> Callable[[], None] | None:
    """A ``preexec_fn`` for :class:`subprocess.Popen` by which Linux sends the child ``sig``
    when this process ends, however it ends (``kill -9`` too), so that a solver's worker never
    outlives the script; ``None`` where there is no ``prctl`` (not Linux). The signal comes
    when the thread that started the child ends: start workers from a thread that lives as
    long as the simulation (the main thread does)."""
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def arm() -> None:
        prctl(PR_SET_PDEATHSIG, int(sig))
        if os.getppid() != parent:  # the parent ended before the signal was armed
            os._exit(1)

    return arm


def before_resume(path: Path) -> Path:
    """Where a resume keeps a single-file trajectory while it copies back the frames it keeps
    (``traj.h5`` -> ``traj.before-resume.h5``)."""
    return path.with_name(f"{path.stem}.before-resume{path.suffix}")


@dataclass(frozen=True)
class Handle:
    """What an engine call such as ``insert`` or ``setupWall`` returns; pass it to ``remove``."""

    kind: str
    id: int
    label: str
    engine_id: int


@dataclass
class Monitor:
    """Scalars sampled during ``run``: ``values[name]`` is an array, one entry per sample."""

    handle: Handle
    spec: MonitorSpec
    path: Any
    samples: list[tuple[float, ...]] = field(default_factory=list)

    @property
    def values(self) -> dict[str, np.ndarray]:
        table = np.array(self.samples, float).reshape(-1, 2 + len(self.spec.quantities))
        names = ("step", "time", *self.spec.quantities)
        return {name: table[:, i] for i, name in enumerate(names)}


def require_capability(engine: str, capabilities: Collection[str], capability: str, what: str | None) -> None:
    """Raise :class:`UnsupportedFeature`, naming the installed engines that can, unless the
    engine ``engine`` has ``capability`` among its ``capabilities``."""
    if capability in capabilities:
        return
    able = [name for name in engines_with(capability) if name != engine]
    alternative = f"Engines that can: {', '.join(able)}." if able else "No installed engine can."
    raise UnsupportedFeature(
        f"The {engine} engine does not support {what or capability} "
        f"(capability {capability!r}). {alternative}"
    )


def _shorten(text: str, width: int = 120) -> str:
    return "`" + (text if len(text) <= width else text[: width - 3] + "...") + "`"


class Engine(abc.ABC):
    """Base class of DEM engines, built from a validated :class:`SimulationSpec`.

    Subclasses set :attr:`name` and :attr:`capabilities` and implement :meth:`_advance`,
    :meth:`_extract` and the hooks of the calls they support; the others raise
    :class:`UnsupportedFeature`. Hooks receive validated specs and return the solver's
    label for what they created.
    """

    name: ClassVar[str] = "engine"
    capabilities: ClassVar[frozenset[str]] = frozenset()
    #: Upper bound on the progress updates (and Python round trips) per ``run`` between events.
    max_run_chunks: ClassVar[int] = 100

    _ids = itertools.count(1)

    def __init__(self, spec: SimulationSpec) -> None:
        self.spec = spec
        self.output = spec.output
        self._output_lock = claim_output(self.output)
        self._run_span = (0, 0)  # the first and last step of the run in progress
        self.dt = spec.dt
        self.step = 0
        self.time = 0.0
        #: (step, time) at the last change of dt: time is computed from it, not summed per chunk.
        self._clock = (0, 0.0)
        self.closed = False
        self._engine_id = next(Engine._ids)
        ranks = os.environ.get("OMPI_COMM_WORLD_SIZE", os.environ.get("PMI_SIZE", "1"))
        self._progress = Progress(spec.progress, self._progress_line, collective=ranks != "1")
        self._progress_to_stderr = False
        self._handles: dict[int, Handle] = {}
        self._handle_ids = itertools.count(1)
        self._monitors: dict[int, Monitor] = {}
        self._writers: dict[str, TrajectoryWriter] = {}
        #: Particles lost in all runs so far, and in the last run.
        self.lost = 0
        self.last_lost = LostParticles()
        #: The last run's time step against the contacts present (``None``: no contact possible).
        self.time_step_check: Assessment | None = None
        self._outflow: frozenset[str] = frozenset()
        self._step_limits = TimeStepLimits(spec)
        self._wall_specs: dict[int, WallSpec] = {}  # by handle id: the wall materials contacts meet
        self._insert_specs: dict[int, InsertSpec] = {}  # by handle id: species that may appear
        self._speeds = 0.0  # the largest speed the script gave particles
        self._broken: set[int] = set()  # ids of non-finite particles counted by a LostWatch
        #: (species, smallest radius, more than one) of the particles present; None: read anew
        self._present: tuple[tuple[int, float, bool], ...] | None = None
        self._messages = EngineLog(self.name, self.output)
        self.log("%s engine opened, output in %s", self.name, self.output)
        try:
            self._check_spec(spec)
        except PyGranError as exc:
            self._to_file(logging.ERROR, f"refused: {exc}")
            self._abandon()
            raise
        #: ``[call, result]`` for every call that changed the simulation, in order.
        self._calls: list[list[Any]] = []
        self._resume: Checkpoint | None = None
        if spec.restart is not None and spec.restart.resume:
            try:
                self._resume_path = latest_checkpoint(spec.restart)
                self._resume = read_checkpoint(self._resume_path)
            except BaseException:
                self._abandon()
                raise
            if self._resume.engine != self.name:
                self._abandon()
                raise ConfigError(
                    f"{self._resume_path} was written by the {self._resume.engine} engine; "
                    f"resume it with engine={self._resume.engine!r}"
                )
            self.log(
                "resuming from %s (step %d): the calls before it are checked and replayed",
                self._resume_path,
                self._resume.step,
            )
        #: Positions and radii of the particles present, kept between runs for createParticles
        #: (``None``: read anew). A new simulation holds none, so its first createParticles
        #: does not wait for the solver to start.
        self._placed: tuple[np.ndarray, np.ndarray] | None = (
            None if self._resume else (np.empty((0, 3)), np.empty(0))
        )

    @functools.cached_property
    def material_table(self) -> MaterialTable:
        """The material types and pair matrices the engine's contacts take (see
        materials.py), built and logged when an engine first reads it."""
        spec = self.spec
        table = build_table(
            [s.material for s in spec.species],
            [(m.name, m.material) for m in spec.meshes],
            spec.pairs,
            spec.model.required,
        )
        self.log("%s", table.describe())
        return table

    def _check_spec(self, spec: SimulationSpec) -> None:
        """Refuse, before the solver starts, whatever of ``spec`` this engine cannot do."""
        check_spec(spec, self.require)

    # -- common behaviour ------------------------------------------------------------

    def log(self, message: str, *args: Any, level: int = logging.INFO) -> None:
        """Record ``message`` in ``<output>/pygran.log``, and on the ``pygran`` logger
        for whoever has configured logging to show it."""
        self._messages.log(message, *args, level=level)

    def _progress_line(self, text: str, stderr: bool = True) -> None:
        """A progress line into ``pygran.log``, and on stderr off a terminal (see :meth:`run`),
        there from the first MPI rank only (under ``mpirun`` every rank runs the script)."""
        self.log("%s", text)
        rank = os.environ.get("OMPI_COMM_WORLD_RANK", os.environ.get("PMI_RANK", "0"))
        if stderr and self._progress_to_stderr and rank == "0":
            print(f"{self.name}: {text}", file=sys.stderr, flush=True)

    def _to_file(self, level: int, message: str) -> None:
        """Record ``message`` in ``pygran.log`` only: what is also raised or warned, so that it
        does not reach the console twice."""
        self._messages.to_file(level, message)

    def _warn(self, message: str, category: type[Warning]) -> None:
        """Issue a warning at the user's line, recorded in ``pygran.log``."""
        self._messages.warn(message, category)

    def require(self, capability: str, what: str | None = None) -> None:
        """Raise :class:`UnsupportedFeature` unless this engine has ``capability``."""
        require_capability(self.name, self.capabilities, capability, what)

    def _check_open(self) -> None:
        if self.closed:
            raise EngineError(f"This {self.name} simulation is closed; create a new one")

    def _new_handle(self, kind: str, label: str) -> Handle:
        """Record a removable object created in the solver and return its handle."""
        handle = Handle(kind, next(self._handle_ids), label, self._engine_id)
        self._handles[handle.id] = handle
        return handle

    def _call(self, kind: str, hook: Any, spec: Any) -> Handle:
        self._check_open()
        self._journal(f"{kind} {spec!r}", spec)
        self.log("%s %s", kind, spec)
        return self._new_handle(kind, hook(spec))

    @property
    def replaying(self) -> bool:
        """Whether the script is being replayed up to the checkpoint it resumes from."""
        return self._resume is not None

    def _journal(self, call: str, spec: Any = None) -> Any:
        """Record a call that changes the simulation: its text, and for a call with a spec a
        digest of every argument (``repr`` shortens arrays of over 1,000 values). While
        :attr:`replaying`, check it is the call the checkpoint's script made at this point and
        return that call's result."""
        if spec is not None:
            call = f"{call} #{content_digest(spec)}"
        index = len(self._calls)
        self._calls.append([call, None])
        if self._resume is None:
            return None
        recorded = self._resume.journal
        if index >= len(recorded) or recorded[index][0] != call:
            was = recorded[index][0] if index < len(recorded) else "nothing more"
            raise ConfigError(
                f"This script is not the one that wrote {self._resume_path}: its call {index + 1} is "
                f"{_shorten(call)} where that script's was {_shorten(was)}. Resume with the same "
                "script, or start afresh without resume."
            )
        self._calls[index][1] = recorded[index][1]
        return recorded[index][1]

    @property
    def handles(self) -> tuple[Handle, ...]:
        """Handles of the objects not yet removed, oldest first."""
        return tuple(self._handles.values())

    # -- calls -------------------------------------------------------------------------

    def insert(self, spec: InsertSpec) -> Handle:
        if spec.mechanism == "by_rate":
            self.require("insert-by-rate", "insertion by rate")
        handle = self._call("insertion", self._insert, spec)
        self._insert_specs[handle.id] = spec
        self._forget_particles()
        spread = np.linalg.norm(spec.velocity.spread) * (3 if spec.velocity.kind == "gaussian" else 1)
        self._speeds = max(self._speeds, float(np.linalg.norm(spec.velocity.mean) + spread))
        return handle

    def create_particles(self, spec: CreateSpec) -> int:
        """Create particles now; returns how many were created.

        Particles created at given positions (``'single'``) or on a lattice must not overlap
        each other or the particles present (by more than :data:`CREATE_OVERLAP_TOLERANCE` of
        the smaller radius): they would repel at high speed.
        """
        self._check_open()
        if spec.style in ("single", "lattice") and not self.replaying:
            self._check_clear(spec)
        recorded = self._journal(f"create {spec!r}", spec)
        if self.replaying:
            return recorded
        count = self._calls[-1][1] = self._create(spec)
        self._present = None  # _placed, used by the next createParticles, is extended below
        if spec.style == "single" and self._placed is not None:
            radius = spec.radius or self.spec.species[spec.species - 1].radius.min
            x, r = self._placed
            self._placed = (np.vstack([x, spec.centres]), np.append(r, np.full(len(spec.centres), radius)))
        else:
            self._placed = None
        self._speeds = max(self._speeds, float(np.linalg.norm(spec.velocity)))
        self.log("create %s: %d particles", spec, count)
        return count

    def _check_clear(self, spec: CreateSpec) -> None:
        """Refuse ``single`` positions or lattice sites that overlap each other or the particles
        present."""
        if self._placed is None:
            x, r = self._extract("x").reshape(-1, 3), self._extract("radius")
            finite = np.isfinite(x).all(axis=1)
            self._placed = (x[finite], r[finite])
        check_clear(self.spec, spec, *self._placed)

    def set_properties(self, spec: SetSpec) -> int:
        """Assign velocity, angular velocity and/or radius to the selected particles; returns how many.

        ``ids`` that no particle has are a :class:`ConfigError`.
        """
        self._check_open()
        present = self._extract("id") if not self.replaying else np.zeros(0, np.int64)
        if spec.ids is not None and not self.replaying:
            missing = sorted(set(spec.ids) - set(present.tolist()))
            if missing:
                have = f"ids {present.min()} to {present.max()}" if len(present) else "no particles"
                raise ConfigError(
                    f"set/velocity ids: no particle has id {', '.join(map(str, missing[:10]))}"
                    f"{' ...' if len(missing) > 10 else ''} "
                    f"(the simulation has {len(present)} particles, {have})"
                )
        recorded = self._journal(f"set {spec!r}", spec)
        if self.replaying:
            return recorded
        ids = spec.select(present, self._extract("type"), self._extract("x"))
        if len(ids):
            self._assign(ids, spec)
            self._forget_particles()
        if spec.velocity is not None:
            self._speeds = max(self._speeds, float(np.linalg.norm(spec.velocity)))
        self.log("set %s: %d particles", spec, len(ids))
        self._calls[-1][1] = len(ids)
        return len(ids)

    def setup_wall(self, spec: WallSpec) -> Handle:
        self.require("mesh-walls" if spec.kind == "mesh" else "primitive-walls", f"{spec.kind} walls")
        handle = self._call("wall", self._wall, spec)
        self._wall_specs[handle.id] = spec
        return handle

    def move_mesh(self, spec: MotionSpec) -> Handle:
        self.require("moving-mesh", "moving meshes")
        return self._call("motion", self._move_mesh, spec)

    def add_viscous(self, spec: ViscousSpec) -> Handle:
        return self._call("viscous", self._viscous, spec)

    def monitor(self, spec: MonitorSpec) -> Monitor:
        handle = self._call("monitor", lambda s: s.file, spec)
        monitor = Monitor(handle, spec, self.output / spec.file)
        monitor.path.parent.mkdir(parents=True, exist_ok=True)  # file="monitors/ke.txt"
        monitor.path.write_text("# step time " + " ".join(spec.quantities) + "\n")
        self._monitors[handle.id] = monitor
        return monitor

    def extract(self, quantity: str) -> np.ndarray:
        """A per-particle quantity (see :data:`EXTRACTABLE`) as a numpy array ordered by id."""
        self._check_open()
        if quantity not in EXTRACTABLE:
            raise unknown_key("quantity", quantity, EXTRACTABLE)
        return self._extract(quantity)

    def command(self, text: str) -> None:
        """Pass a solver-native command through unchanged."""
        self.require("raw-commands", "raw solver commands")
        self._check_open()
        self._journal(f"command {text}")
        self.log("command %s", text)
        self._command(text)
        self._forget_particles()

    def remove(self, handle: Handle | Monitor) -> None:
        """Remove what ``handle`` refers to (an insertion, wall, mesh motion, force, monitor)."""
        self._check_open()
        if isinstance(handle, Monitor):
            handle = handle.handle
        if not isinstance(handle, Handle) or handle.engine_id != self._engine_id:
            raise ConfigError(f"{handle!r} is not a handle returned by this simulation")
        if handle.id not in self._handles:
            raise ConfigError(f"{handle.kind} {handle.label!r} was already removed")
        self._journal(f"remove {handle.kind} {handle.label}")
        if handle.kind == "monitor":
            del self._monitors[handle.id]
        else:
            self._remove(handle)
        del self._handles[handle.id]
        self._wall_specs.pop(handle.id, None)
        self._insert_specs.pop(handle.id, None)
        self._forget_particles()
        self.log("remove %s %s", handle.kind, handle.label)

    # -- running -----------------------------------------------------------------------

    def run(
        self, nsteps: int, dt: float | None = None, *, progress: bool | None = None, check_dt: bool = True
    ) -> None:
        """Advance ``nsteps`` time steps (of ``dt``, or the simulation's time step).

        Before it, the time step is checked against the contacts that can happen
        (:mod:`~pygran_core.simulation.timestep`): a :class:`TimeStepWarning` if it resolves
        them poorly, a :class:`ConfigError` if it cannot resolve them at all, unless
        ``check_dt=False``. Trajectory frames, monitor samples and checkpoints are taken at
        their frequencies (in absolute steps); the solver runs uninterrupted between them and
        between the progress updates: by default a bar on a terminal, elsewhere a line on
        stderr every ``progress={'every': seconds}`` (30 s by default; always also in
        ``pygran.log``); ``progress=True`` asks for the bar, ``False`` for neither.
        Particles lost during the run are reported (see :meth:`expect_outflow`), counted in
        :attr:`lost` and described in :attr:`last_lost`.
        """
        self._check_open()
        nsteps = positive_int(nsteps, "nsteps")
        check_run_size(self.spec, self.step, nsteps, [m.spec for m in self._monitors.values()])
        if dt is not None:
            dt = positive_float(dt, "dt")
        run_dt = dt if dt is not None else self.dt
        if run_dt is None:
            raise ConfigError("No time step: pass dt to run(nsteps, dt) or dt=... to DEM")
        if not self.replaying:
            self._check_time_step(run_dt, check_dt)
        if run_dt != self.dt:
            self._clock, self.dt = (self.step, self.time), run_dt
        self.log("run %d steps of dt=%g from step %d", nsteps, self.dt, self.step)
        terminal = sys.stderr.isatty()
        chosen = progress if progress is not None else self.spec.progress.show
        # by default progress shows as a bar on a terminal, as lines on stderr elsewhere (a
        # file, a batch job's log); True asks for the bar, False for neither; the lines always
        # go to pygran.log
        show = terminal if chosen is None else chosen
        self._progress_to_stderr = chosen is None and not terminal
        from tqdm import tqdm

        start, end = self.step, self.step + nsteps
        self._journal(f"run {nsteps} {self.dt!r}")
        if self._resume is not None:
            if len(self._calls) < len(self._resume.journal):
                self._set_step(end, run_dt)
                return  # a run the checkpoint's script had finished before it
            self._restore(self._resume)  # the run the checkpoint was taken in
        elif self.step == 0:
            self._on_event()
        counted = self._lost_since_last()
        watch = LostWatch(self.spec, self._extract, self.time, self._broken) if counted is None else None
        lost = counted or LostParticles()
        servos: dict[str, list[float]] = {name: [] for name in self._watched_servos()}
        self._progress.begin(self.step, end)
        with tqdm(
            total=nsteps,
            initial=self.step - start,
            unit="step",
            disable=not show,
            desc=f"{self.name} run",
        ) as bar:
            for chunk in self._run_chunks(end):
                try:
                    self._advance(chunk)
                except EngineError:
                    self.log("solver error at step %d", self.step, level=logging.ERROR)
                    raise
                self._set_step(self.step + chunk, run_dt)
                bar.update(chunk)
                self._progress.update(self.step, self.time, lambda: int(self._scalar("n")))
                self._on_event()
                if watch is None:
                    lost += self._lost_since_last() or LostParticles()
                if nsteps > SERVO_WATCH and self.step >= end - SERVO_WATCH:
                    for name, errors in servos.items():
                        errors.append(self._servo_error(name))
        assert self.step == end
        self._progress_line(self._progress.end(self.step), stderr=bool(self._progress.lines))
        self._placed = None  # the particles have moved
        if watch is not None:
            lost = watch.finish(self.time)
        self._report_lost(lost, start, watch is not None)
        self._report_servos(servos)

    # -- servo walls -----------------------------------------------------------------------

    def _watched_servos(self) -> list[str]:
        """The force servos whose controller :meth:`run` watches over its last steps."""
        return list(force_servos(self.spec)) if "servo-walls" in self.capabilities else []

    def _servo_error(self, name: str) -> float:
        """The servo's relative error now (see :func:`.diagnostics.servo_error`)."""
        try:
            force = self.mesh_force(name)  # type: ignore[attr-defined]
        except ConfigError:  # not a wall (yet): nothing to judge
            return 0.0
        return servo_error(force_servos(self.spec)[name], force)

    def _report_servos(self, servos: Mapping[str, list[float]]) -> None:
        """A :class:`ServoWarning` for each servo whose force swung about its target at each of
        the run's last steps (see :func:`.diagnostics.servo_swing`)."""
        for name, errors in servos.items():
            message = servo_swing(name, force_servos(self.spec)[name], errors)
            if message is not None:
                self._warn(message, ServoWarning)

    # -- the time step and lost particles ------------------------------------------------

    def _forget_particles(self) -> None:
        """Read the particles present anew when next needed: a call or run may have changed them."""
        self._present = None
        self._placed = None

    def expect_outflow(self, *faces: str) -> None:
        """Declare that particles leave through these faces of the domain (``"z-"``: below the
        lower z bound; see :data:`FACES`): their loss is logged, not warned. Call it without
        faces to expect none again."""
        for face in faces:
            if face not in FACES:
                raise unknown_key("outflow face", str(face), FACES)
            if self.spec.domain.periodic["xyz".index(face[0])]:
                raise ConfigError(
                    f"outflow face {face!r}: the {face[0]} axis is periodic, nothing leaves there"
                )
        self._outflow = frozenset(faces)
        self.log("outflow expected through %s", ", ".join(sorted(self._outflow)) or "no face")

    def _check_time_step(self, dt: float, check_dt: bool) -> None:
        """Compare ``dt`` with the contacts that can happen now, between the species present
        or being inserted and with the walls (see :class:`.diagnostics.TimeStepLimits`): warn
        once per time step and set of contacts; refuse a step that cannot resolve them. The
        particles present are read from the engine only after a call or a run may have
        changed them (see :attr:`_present`)."""
        if self._present is None:
            self._present = species_present(self.spec, self._extract("type"), self._extract("radius"))
        coming = {k for insert in self._insert_specs.values() for k in insert.species}
        found = self._step_limits(self._present, coming, self._wall_specs.values())
        self.time_step_check = check = None if found is None else found.assess(dt)
        if found is None or check is None or check.level == "ok":
            return
        if check.level == "error" and check_dt:
            message = f"{check.message()} Or pass check_dt=False to run() to run anyway."
            self._to_file(logging.ERROR, f"run refused: {message}")
            raise ConfigError(message)
        if self._step_limits.first_warning(dt, found):
            self._warn(check.message(), TimeStepWarning)

    def _report_lost(self, lost: LostParticles, start: int, estimated: bool) -> None:
        """Count the particles lost in the run from ``start``; warn about those not expected."""
        self.last_lost = lost
        if not lost.count:
            return
        self.lost += lost.count
        self._forget_particles()
        expected = sum(n for place, n in lost.where.items() if place in self._outflow)
        where = lost.places(self._outflow)
        how = (
            f" (as the {self.name} engine does not report lost particles, PyGran found them missing and "
            "estimated where from where they were last seen)"
            if estimated
            else ""
        )
        if expected:
            self.log(
                "%d particle%s left through the expected outflow (%s) in the run from step %d to %d",
                expected,
                "" if expected == 1 else "s",
                ", ".join(sorted(self._outflow)),
                start,
                self.step,
            )
        if expected == lost.count:
            return
        unexpected = lost.count - expected
        message = (
            f"{unexpected} particle{'s' if unexpected > 1 else ''} lost in the run from step {start} to "
            f"{self.step}: "
            f"{where}{how}; {self._lost_cause(lost)}. {self.lost} lost in all."
        )
        self._warn(message, LostParticlesWarning)

    def _lost_cause(self, lost: LostParticles) -> str:
        """The likely cause of ``lost`` (see :func:`.diagnostics.lost_cause`)."""
        remaining = np.linalg.norm(self._extract("v").reshape(-1, 3), axis=1)
        return lost_cause(self.spec, lost, self.time_step_check, self._speeds, remaining, self._outflow)

    def _set_step(self, step: int, dt: float) -> None:
        """Move the clock to ``step``, ``dt`` after ``dt`` since the last change of time step."""
        self.step = step
        self.time = self._clock[1] + (step - self._clock[0]) * dt

    def _frequencies(self) -> list[int]:
        freqs = [m.spec.freq for m in self._monitors.values()]
        traj = self.spec.traj
        if traj.pfile is not None or traj.mfile is not None or traj.cfile is not None:
            freqs.append(traj.freq)
        if self.spec.restart is not None:
            freqs.append(self.spec.restart.freq)
        return freqs

    def _run_chunks(self, end: int) -> Iterator[int]:
        """The pieces of :meth:`_chunks` from this step to ``end``, listed a segment of
        :data:`RUN_SEGMENT` steps at a time (a run of 10**15 steps lists no step in advance)."""
        self._run_span = (self.step, end)
        while self.step < end:
            yield from self._chunks(min(end - self.step, RUN_SEGMENT))

    def _chunks(self, nsteps: int) -> list[int]:
        """Split the next ``nsteps`` steps of a run at every event step, and the run (from
        :meth:`_run_chunks`) into at most :attr:`max_run_chunks` pieces."""
        start, end = self.step, self.step + nsteps
        first, last = self._run_span
        stops = {end}
        for freq in self._frequencies():
            stops.update(range((start // freq + 1) * freq, end, freq))
        total = last - first
        pieces = min(total, self.max_run_chunks)
        stops.update(first + (total * k) // pieces for k in range(1, pieces))
        if self._watched_servos() and total > SERVO_WATCH:
            stops.update(range(last - SERVO_WATCH, last))  # single steps, read by _watch_servos
        ordered = sorted(s for s in stops if start < s <= end)
        return [b - a for a, b in zip([start, *ordered], ordered)]

    def _on_event(self) -> None:
        """Take the trajectory frame, monitor samples and checkpoint due at this step."""
        traj = self.spec.traj
        if self.step % traj.freq == 0:
            if traj.pfile is not None:
                self._write("particles", traj.pfile, self._frame)
            if traj.mfile is not None and self.spec.meshes:
                self._write("meshes", traj.mfile, self._mesh_frame)
            if traj.cfile is not None:
                self._write("contacts", traj.cfile, self._contacts_frame)
            if traj.pfile is not None or traj.mfile is not None or traj.cfile is not None:
                # a dump stores the step only, as LIGGGHTS writes it: the log keeps each frame's time
                self._to_file(logging.INFO, f"trajectory frame at step {self.step}, time {self.time!r} s")
        for monitor in self._monitors.values():
            if self.step % monitor.spec.freq == 0:
                species = monitor.spec.species
                values = (
                    self._scalar(q) if species is None else self._species_scalar(q, species)
                    for q in monitor.spec.quantities
                )
                row = (float(self.step), self.time, *values)
                monitor.samples.append(row)
                with monitor.path.open("a") as handle:
                    handle.write(" ".join(repr(v) for v in row) + "\n")
        restart = self.spec.restart
        if restart is not None and self.step > 0 and self.step % restart.freq == 0:
            self._checkpoint(checkpoint_path(restart, self.step))

    # -- checkpoints ----------------------------------------------------------------------

    def _checkpoint(self, path: Any) -> None:
        """Write everything needed to continue from this step to ``path`` (HDF5)."""
        width = {h: 2 + len(m.spec.quantities) for h, m in self._monitors.items()}
        checkpoint = Checkpoint(
            engine=self.name,
            step=self.step,
            time=self.time,
            dt=self.dt,
            journal=[list(call) for call in self._calls],
            monitors={h: np.array(m.samples, float).reshape(-1, width[h]) for h, m in self._monitors.items()},
            state=self._state(),
            facts=self._facts(),
        )
        write_checkpoint(path, checkpoint)
        self.log("checkpoint at step %d: %s", self.step, path)

    def _restore(self, checkpoint: Checkpoint) -> None:
        """Continue from ``checkpoint``, the one being resumed: the engine's state, the clock,
        the monitors, and the trajectory files cut back to the checkpoint's step."""
        self._resume = None
        unknown = sorted(set(checkpoint.monitors) - set(self._monitors))
        if unknown:
            raise ReadError(f"{self._resume_path}: monitors {unknown} are not among the script's monitors")
        for handle_id, samples in checkpoint.monitors.items():
            quantities = self._monitors[handle_id].spec.quantities
            if samples.ndim != 2 or samples.shape[1] != 2 + len(quantities):
                raise ReadError(
                    f"{self._resume_path}: monitor {handle_id} has samples of shape {samples.shape}, "
                    f"not rows of {2 + len(quantities)} (step, time, {', '.join(quantities)})"
                )
        if checkpoint.facts != self._facts():
            self.log(
                "resuming with %s where the checkpoint had %s: the run continues, but not bitwise",
                self._facts(),
                checkpoint.facts,
                level=logging.WARNING,
            )
        self.step, self.time, self.dt = checkpoint.step, checkpoint.time, checkpoint.dt
        self._clock = (int(checkpoint.state["clock"][0]), float(checkpoint.state["clock"][1]))
        self._restore_state(checkpoint.state)
        self._forget_particles()
        for handle_id, samples in checkpoint.monitors.items():
            monitor = self._monitors[handle_id]
            monitor.samples = [tuple(float(v) for v in row) for row in samples]
            lines = [" ".join(repr(v) for v in row) + "\n" for row in monitor.samples]
            monitor.path.write_text(
                "# step time " + " ".join(monitor.spec.quantities) + "\n" + "".join(lines)
            )
        traj = self.spec.traj
        for key, path in (("particles", traj.pfile), ("meshes", traj.mfile), ("contacts", traj.cfile)):
            if key == "contacts" and path == traj.pfile:
                continue  # in the particle file: cut with it
            if path is not None and (path.is_file() or before_resume(path).is_file()):
                self._cut_trajectory(key, path)
            elif path is not None and (key != "meshes" or self.spec.meshes):  # a file per frame
                path.parent.mkdir(parents=True, exist_ok=True)
                self._writers[key] = self._open_writer(key, path)
                self._writers[key].resume(self.step)
        self.log("resumed from %s at step %d", self._resume_path, self.step)

    def _cut_trajectory(self, key: str, path: Any) -> None:
        """Keep the frames of a single-file trajectory up to this step and append from there.

        Files written a frame each need nothing: later frames are overwritten as they come.
        """
        before = before_resume(path)
        moved = [(path, before)]
        walls = _contacts.wall_file(path), _contacts.wall_file(before)
        if key == "contacts" and (walls[0].is_file() or walls[1].is_file()):  # a contacts dump's walls
            moved.append(walls)
        for now, kept_as in moved:
            if kept_as.exists():  # an earlier resume was killed while copying: the original is there
                now.unlink(missing_ok=True)
            else:
                os.replace(now, kept_as)
        writer = self._writers[key] = self._open_writer(key, path)
        kept = 0
        try:
            with open_trajectory(before) as old, contextlib.ExitStack() as stack:
                contacts = old.contacts() if self._contacts_with(key) else None
                if contacts is not None:
                    stack.callback(contacts.close)
                for index in range(len(old)):
                    frames = [old[index]]
                    if contacts is not None and index < len(contacts):
                        frames.append(contacts[index])
                    if any(f.timestep is not None and f.timestep > self.step for f in frames):
                        break
                    for frame in frames:
                        writer.write_frame(frame)
                    kept += 1
        except ReadError as exc:
            self.log(
                "resume: %s; %d frames kept in %s, the original is left as %s",
                exc,
                kept,
                path,
                before,
                level=logging.WARNING,
            )
            return
        for _, kept_as in moved:
            kept_as.unlink()
        self.log("resume: %d frames up to step %d kept in %s", kept, self.step, path)

    def _contacts_with(self, key: str) -> bool:
        """Whether the trajectory ``key`` holds the contact records too (one H5MD file)."""
        return key == "particles" and self.spec.traj.cfile == self.spec.traj.pfile

    def _open_writer(self, key: str, path: Any) -> TrajectoryWriter:
        return open_writer(path, contacts=True) if self._contacts_with(key) else open_writer(path)

    def _write(self, key: str, path: Any, make_frame: Any) -> None:
        if key == "contacts" and self._contacts_with("particles"):
            key = "particles"  # the particle file's /contacts group
        if key not in self._writers:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._writers[key] = self._open_writer(key, path)
        self._writers[key].write_frame(make_frame())

    def _abandon(self) -> None:
        """Release the log and the output folder of an engine whose construction failed (its
        subclass calls this on a failure after the base class's constructor)."""
        self._messages.close()
        self._output_lock.close()
        self.closed = True

    def close(self) -> None:
        """Finish output files and release the solver; closing twice is harmless."""
        if self.closed:
            return
        try:
            for writer in self._writers.values():
                writer.close()
            self._close()
        finally:
            self.closed = True
            self.log("%s engine closed at step %d", self.name, self.step)
            self._messages.close()
            self._output_lock.close()

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- engine hooks ----------------------------------------------------------------

    @abc.abstractmethod
    def _advance(self, nsteps: int) -> None:
        """Integrate ``nsteps`` steps of :attr:`dt` in the solver."""

    @abc.abstractmethod
    def _extract(self, quantity: str) -> np.ndarray:
        """A per-particle quantity ordered by id: (N, 3) for vectors, (N,) for scalars."""

    def _unsupported(self, what: str) -> UnsupportedFeature:
        return UnsupportedFeature(f"The {self.name} engine does not implement {what}")

    def _insert(self, spec: InsertSpec) -> str:
        raise self._unsupported("insert")

    def _create(self, spec: CreateSpec) -> int:
        raise self._unsupported("createParticles")

    def _assign(self, ids: np.ndarray, spec: SetSpec) -> None:
        """Give the particles with these ids the spec's velocity, omega and/or radius."""
        raise self._unsupported("set/velocity")

    def _wall(self, spec: WallSpec) -> str:
        raise self._unsupported("setupWall")

    def _move_mesh(self, spec: MotionSpec) -> str:
        raise self._unsupported("moveMesh")

    def _viscous(self, spec: ViscousSpec) -> str:
        raise self._unsupported("addViscous")

    def _command(self, text: str) -> None:
        raise self._unsupported("raw commands")

    def _scalar(self, quantity: str) -> float:
        """A monitored scalar (see :data:`~pygran_core.simulation.calls.MONITOR_QUANTITIES`)."""
        if quantity == "n":
            return float(len(self._extract("id")))
        if quantity == "time":
            return self.time
        if quantity == "ke":
            v = self._extract("v")
            return float(0.5 * np.sum(self._extract("mass") * np.einsum("ij,ij->i", v, v)))
        raise self._unsupported(f"the monitor quantity {quantity!r}")

    def _species_scalar(self, quantity: str, species: tuple[int, ...]) -> float:
        """A monitored scalar of the particles of ``species`` only (engines that declare
        ``monitor-species``): ``n``, ``time``, ``ke`` and, for spheres, ``ke_rot``."""
        if quantity == "time":
            return self.time
        chosen = np.isin(self._extract("type"), species)
        if quantity == "n":
            return float(np.count_nonzero(chosen))
        if quantity in ("ke", "ke_rot"):
            mass = self._extract("mass")[chosen]
            if quantity == "ke":
                speed = self._extract("v")[chosen]
                return float(0.5 * np.sum(mass * np.einsum("ij,ij->i", speed, speed)))
            if any(s.style == "multisphere" for s in self.spec.species if s.type in species):
                raise self._unsupported("a ke_rot monitor of multisphere species")
            spin = self._extract("omega")[chosen]
            inertia = 0.4 * mass * self._extract("radius")[chosen] ** 2
            return float(0.5 * np.sum(inertia * np.einsum("ij,ij->i", spin, spin)))
        raise self._unsupported(f"the monitor quantity {quantity!r} of some species")

    def _frame(self) -> Frame:
        """The particles now (those of species ``traj`` ``sel`` unless ``"all"``), as a
        trajectory frame with the ``traj`` columns in their order."""
        traj = self.spec.traj
        arrays: dict[str, np.ndarray] = {}
        for quantity, names in TRAJ_VECTORS.items():
            if set(traj.args) & set(names):
                values = self._extract(quantity)
                arrays.update({n: values[:, i] for i, n in enumerate(names)})
        for name in TRAJ_SCALARS:
            if name in traj.args:
                arrays[name] = self._extract(name)
        if "density" in traj.args:
            densities = np.array([0.0, *(species.density for species in self.spec.species)])
            arrays["density"] = densities[self._extract("type")]
        chosen = slice(None) if traj.sel == "all" else self._extract("type") == traj.sel
        box, boundary = self._bounds()
        return Frame(
            {name: arrays[name][chosen] for name in traj.args},
            timestep=self.step,
            time=self.time,
            box=box,
            boundary=boundary,
        )

    def _mesh_frame(self) -> Frame:
        raise self._unsupported("mesh output")

    def _contacts_frame(self) -> Frame:
        """The contacts now (:meth:`_contacts`, checked), as a contacts frame of this step."""
        try:
            arrays = _contacts.checked(self._contacts(), f"the {self.name} engine's contact records")
        except ValueError as exc:
            raise EngineError(str(exc)) from None
        box, boundary = self._bounds()
        return Frame(
            arrays,
            timestep=self.step,
            time=self.time,
            box=box,
            boundary=boundary,
            attrs={"kind": _contacts.KIND},
        )

    def _contacts(self) -> dict[str, np.ndarray]:
        """Every contact now, as the columns of :data:`pygran_core.formats.contacts.COLUMNS`
        (engines with ``contact-output``): pairs once each, walls with ``id2 = -(k + 1)`` for
        the k-th wall set up."""
        raise self._unsupported("contact output")

    def _bounds(self) -> tuple[np.ndarray, tuple[str, ...]]:
        """The box bounds and the boundary flags as a trajectory frame gives them."""
        box = np.array(self.spec.domain.box, float)
        return box, tuple(flag * 2 if len(flag) == 1 else flag for flag in self.spec.domain.boundary)

    def _state(self) -> dict[str, np.ndarray]:
        """The engine's state for a checkpoint, as named arrays (engines with ``restart``
        extend it)."""
        return {"clock": np.array(self._clock, float)}

    def _restore_state(self, state: dict[str, np.ndarray]) -> None:
        """Put back a :meth:`_state` result; the script's calls up to it have been replayed."""

    def _facts(self) -> dict[str, Any]:
        """What must be the same on resume for a bitwise continuation (e.g. thread count)."""
        return {}

    def check_servo_speeds(self, dt: float) -> None:
        """Refuse servo walls too fast for ``dt`` (see :func:`.diagnostics.check_servo_speeds`)."""
        check_servo_speeds(self.spec, dt)

    def _lost_since_last(self) -> LostParticles | None:
        """Particles the solver lost (left a fixed boundary, became non-finite, were deleted)
        since the last call. ``None``: this engine does not count them, and :meth:`run`
        finds them by comparing the particles from one piece of the run to the next."""
        return None

    def _remove(self, handle: Handle) -> None:
        """Delete the solver object behind ``handle``."""
        raise UnsupportedFeature(f"The {self.name} engine cannot remove a {handle.kind}")

    def _close(self) -> None:
        """Release solver resources; engines holding any override."""


def content_digest(value: Any) -> str:
    """A SHA-256 digest (16 hex digits) of ``value``'s full content: dataclass fields (those
    shown in its ``repr``), mappings, sequences and numpy arrays (dtype, shape and bytes) all
    the way down; ``repr`` of the rest."""
    digest = hashlib.sha256()

    def feed(item: Any) -> None:
        if isinstance(item, np.ndarray):
            digest.update(f"array {item.dtype.str} {item.shape}:".encode())
            digest.update(np.ascontiguousarray(item).tobytes())
        elif dataclasses.is_dataclass(item) and not isinstance(item, type):
            digest.update(f"{type(item).__qualname__}(".encode())
            for field in dataclasses.fields(item):
                if not field.repr:
                    continue  # derived from the simulation's state at the call, not an argument
                digest.update(f"{field.name}=".encode())
                feed(getattr(item, field.name))
            digest.update(b")")
        elif isinstance(item, Mapping):
            digest.update(f"{{{len(item)}:".encode())
            for key, entry in item.items():
                feed(key)
                feed(entry)
        elif isinstance(item, (list, tuple)):
            digest.update(f"[{len(item)}:".encode())
            for entry in item:
                feed(entry)
        else:
            digest.update(f"{type(item).__name__}:{item!r};".encode())

    feed(value)
    return digest.hexdigest()[:16]
