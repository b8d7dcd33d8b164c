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
import math
import os
import shutil
import signal
import sys
import warnings
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
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
    did_you_mean,
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
    available_memory,
)
from pygran_core.simulation.checkpoint import (
    Checkpoint,
    checkpoint_path,
    latest_checkpoint,
    read_checkpoint,
    write_checkpoint,
)
from pygran_core.simulation.materials import MaterialTable, build_table
from pygran_core.simulation.progress import Progress
from pygran_core.simulation.specs import SimulationSpec, TrajectorySpec, positive_float, positive_int
from pygran_core.simulation.timestep import Assessment, Body, Limits, characteristic_speed, limits

LOG_NAME = "pygran.log"
_LOG_FORMAT = "%(asctime)s %(levelname)s %(message)s"

#: Per-particle quantities ``extract`` knows, with their shape per particle.
EXTRACTABLE = {"x": 3, "v": 3, "omega": 3, "f": 3, "torque": 3, "radius": 1, "mass": 1, "id": 1, "type": 1}
#: Trajectory columns (``traj`` ``args``) of the quantities of :data:`EXTRACTABLE`.
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
#: The faces of the domain, as lost particles and :meth:`Engine.expect_outflow` name them.
FACES = ("x-", "x+", "y-", "y+", "z-", "z+")
#: Lost particles faster than this many times what the simulation explains (the
#: characteristic velocity, the speeds given, a fall across the box) point to an instability.
FAST_FACTOR = 10.0
#: A run's last steps are this many single steps when a force servo wall is present, so that
#: the force on it is read at each (:meth:`Engine._report_servos`).
SERVO_WATCH = 3
#: A servo's force swinging about its target by more than this fraction of it at each of those
#: steps, one side then the other, is a :class:`ServoWarning`.
SERVO_SWING = 0.05
#: How deep (a fraction of the smaller radius) particles created at given positions may overlap:
#: a settled bed read from a file has its contacts' overlaps (0.2 % in Dosta et al.'s drum).
CREATE_OVERLAP_TOLERANCE = 1e-2
#: The last step a simulation may reach: step counters are 64-bit integers.
MAX_STEP = 2**63 - 1
#: The fewest bytes a trajectory frame takes on disk (its header, with no particle).
FRAME_BYTES = 100
#: The memory a monitor value takes while kept (a Python float in a tuple), in bytes.
SAMPLE_BYTES = 32
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


@dataclass(frozen=True)
class LostParticles:
    """Particles lost during a run: ``count`` in all, and ``where`` by place: a face of the
    domain they left through (``"z-"``: below the lower z bound, see :data:`FACES`),
    ``"non-finite"`` (position or velocity NaN or infinite) or ``"unknown"``. ``max_speed``
    is the largest speed (m/s) they had when last seen, ``None`` if unknown."""

    count: int = 0
    where: Mapping[str, int] = field(default_factory=dict)
    max_speed: float | None = None

    def __add__(self, other: LostParticles) -> LostParticles:
        where = dict(self.where)
        for place, n in other.where.items():
            where[place] = where.get(place, 0) + n
        speeds = [s for s in (self.max_speed, other.max_speed) if s is not None]
        return LostParticles(self.count + other.count, where, max(speeds, default=None))

    def places(self, exclude: frozenset[str] = frozenset()) -> str:
        """``"150 through z-, 3 non-finite"``, leaving out the places in ``exclude``."""
        named = {"non-finite": "{} became non-finite", "unknown": "{} where the engine cannot tell"}
        parts = [
            named.get(place, "{} through " + place).format(n)
            for place, n in sorted(self.where.items())
            if n and place not in exclude
        ]
        return ", ".join(parts)


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


def _user_stacklevel() -> int:
    """The ``stacklevel`` of ``warnings.warn`` that points at the first caller outside PyGran."""
    frame: FrameType | None = sys._getframe(1)
    level = 1
    while frame is not None and frame.f_globals.get("__name__", "").startswith("pygran"):
        frame, level = frame.f_back, level + 1
    return level


def _point(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{float(c):.6g}" for c in x) + ")"


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
        self._limits: dict[tuple[Any, ...], Limits | None] = {}
        self._warned: set[tuple[float, Limits]] = set()
        self._wall_specs: dict[int, WallSpec] = {}  # by handle id: the wall materials contacts meet
        self._insert_specs: dict[int, InsertSpec] = {}  # by handle id: species that may appear
        self._speeds = 0.0  # the largest speed the script gave particles
        self._broken: set[int] = set()  # ids of non-finite particles counted by a _Watch
        #: (species, smallest radius, more than one) of the particles present; None: read anew
        self._present: tuple[tuple[int, float, bool], ...] | None = None
        self._logger = logging.getLogger(f"pygran.simulation.{self.name}")
        self._log_handler = logging.FileHandler(self.output / LOG_NAME, encoding="utf-8")
        self._log_handler.setFormatter(logging.Formatter(_LOG_FORMAT))
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
        model = spec.model
        if model.kernel is None:
            lost_by = model.kernel_lost_by
            raise UnsupportedFeature(
                f"The contact model {model.__name__} declares no kernel (class attribute kernel)"
                + (f": {lost_by} overrides its parent's force law" if lost_by else "")
                + ", so no engine can run it: subclass SpringDashpot, HertzMindlin or ThorntonNing "
                "without overriding __init__ or their force law (normal_force...), or set kernel to the "
                "capability of an engine that runs its law."
            )
        self.require(model.kernel, f"the {model.__name__} contact model")
        if model.limit_force:
            self.require("limit-force", "limitForce=True")
        if any(spec.domain.periodic):
            self.require("periodic", "periodic boundaries")
        if spec.meshes:
            self.require("mesh-walls", "mesh walls")
        if spec.restart is not None:
            self.require("restart", "restart files")
        if spec.nsim > 1 or spec.nprocs not in (None, 1):
            self.require("mpi", "several MPI ranks (nSim, nprocs)")
        if spec.threads not in (None, 1):
            self.require("threads", "threads")
        if spec.pairs:
            self.require("pair-tables", "per-pair material values (pairs=)")
        if spec.nns_type != "bin":
            self.require("neighbor-styles", f"the neighbour-list style nns_type={spec.nns_type!r}")
        if spec.traj.dump_modify:
            self.require("liggghts-dump", f"dump_modify {spec.traj.dump_modify}")
        if spec.traj.cfile is not None:
            self.require("contact-output", f"contact output (traj cfile {spec.traj.cfile.name!r})")
        if spec.traj.margs != TrajectorySpec.margs:
            self.require(
                "liggghts-dump", f"traj margs {spec.traj.margs} (the columns of LIGGGHTS' mesh dump)"
            )
        unknown = list(dict.fromkeys(c for c in spec.traj.args if c not in TRAJ_COLUMNS))
        if unknown:
            hint = (
                " A string was split into letters: give a sequence of names such as ('id', 'x', 'y', 'z')."
                if all(len(str(c)) <= 1 for c in spec.traj.args)
                else did_you_mean(str(unknown[0]), TRAJ_COLUMNS)
            )
            known = ", ".join(sorted(TRAJ_COLUMNS))
            raise ConfigError(f"traj args: unknown column(s) {unknown}.{hint} Known columns: {known}.")
        for species in spec.species:
            if species.style == "multisphere":
                self.require("multisphere", "multisphere particles")
            if species.radius.kind != "constant":
                self.require("polydisperse", "size distributions")
            if species.material.get("cohesionEnergyDensity", 0) > 0:
                self.require("cohesion", "cohesion")
            if species.material.get("coefficientRollingFriction", 0) > 0:  # cdt, or its own model
                if model.rolling == "cdt":
                    self.require("rolling-friction", "rolling friction")
                else:
                    self.require(f"rolling-{model.rolling}", f"the rolling-friction model {model.rolling}")

    # -- common behaviour ------------------------------------------------------------

    def log(self, message: str, *args: Any, level: int = logging.INFO) -> None:
        """Record ``message`` in ``<output>/pygran.log``, and on the ``pygran`` logger
        for whoever has configured logging to show it."""
        record = self._logger.makeRecord(self._logger.name, level, __file__, 0, message, args, None)
        self._log_handler.handle(record)
        if self._logger.isEnabledFor(level):
            self._logger.handle(record)

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
        record = self._logger.makeRecord(self._logger.name, level, __file__, 0, "%s", (message,), None)
        self._log_handler.handle(record)

    def _warn(self, message: str, category: type[Warning]) -> None:
        """Issue a warning at the user's line, recorded in ``pygran.log``."""
        self._to_file(logging.WARNING, message)
        warnings.warn(message, category, stacklevel=_user_stacklevel())

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
        from scipy.spatial import cKDTree

        centres = spec.centres
        radius = spec.radius or self.spec.species[spec.species - 1].radius.min
        if self._placed is None:
            x, r = self._extract("x").reshape(-1, 3), self._extract("radius")
            finite = np.isfinite(x).all(axis=1)
            self._placed = (x[finite], r[finite])
        present, radii = self._placed
        # every close pair: (index of the new centre, the other's centre, its radius, the gap)
        found: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        if len(present):
            reach = radius + float(radii.max())
            if len(present) * len(centres) <= 1_000_000:
                gaps = np.linalg.norm(present[None, :, :] - centres[:, None, :], axis=2)
                new, old = np.nonzero(gaps < reach)
                gap = gaps[new, old]
            else:
                near = cKDTree(centres).sparse_distance_matrix(cKDTree(present), reach, output_type="ndarray")
                new, old, gap = near["i"], near["j"], near["v"]
            found.append((new, present[old], radii[old], gap))
        if len(centres) > 1:
            among = cKDTree(centres).query_pairs(2 * radius, output_type="ndarray").reshape(-1, 2)
            gap = np.linalg.norm(centres[among[:, 0]] - centres[among[:, 1]], axis=1)
            found.append((among[:, 1], centres[among[:, 0]], np.full(len(among), radius), gap))
        if not found:
            return
        new, others, sizes, gap = (np.concatenate(parts) for parts in zip(*found))
        depth = (sizes + radius - gap) / np.minimum(sizes, radius)
        if not len(depth) or depth.max() <= CREATE_OVERLAP_TOLERANCE:
            return
        worst = int(np.argmax(depth))
        kind = "the particle present" if worst < len(found[0][0]) and len(present) else "the new one"
        raise ConfigError(
            f"createParticles position {_point(centres[new[worst]])} overlaps {kind} at "
            f"{_point(others[worst])} by {100 * min(depth[worst], 2.0):.3g} % of the smaller "
            f"radius ({int((depth > CREATE_OVERLAP_TOLERANCE).sum())} overlapping pairs in all): "
            "overlapping particles repel at high speed. Move the positions apart, at least the sum of "
            "the radii."
        )

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
        self._check_run_size(nsteps)
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
        watch = _Watch(self) if counted is None else None
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
            lost = watch.finish()
        self._report_lost(lost, start, watch is not None)
        self._report_servos(servos)

    # -- servo walls -----------------------------------------------------------------------

    def _watched_servos(self) -> list[str]:
        """The force servos whose controller :meth:`run` watches over its last steps."""
        if "servo-walls" not in self.capabilities:
            return []
        return [m.name for m in self.spec.meshes if m.servo is not None and m.servo.control == "force"]

    def _servo_error(self, name: str) -> float:
        """The servo's relative error now: (force pushing back along its axis - target) / target."""
        servo = next(m.servo for m in self.spec.meshes if m.name == name)
        assert servo is not None
        axis = np.asarray(servo.axis, float) / np.linalg.norm(servo.axis)
        try:
            force = self.mesh_force(name)  # type: ignore[attr-defined]
        except ConfigError:  # not a wall (yet): nothing to judge
            return 0.0
        return float((-(force @ axis) - abs(servo.target)) / abs(servo.target))

    def _report_servos(self, servos: Mapping[str, list[float]]) -> None:
        """A :class:`ServoWarning` for each servo whose force swung about its target, by more
        than :data:`SERVO_SWING` of it, at each of the run's last :data:`SERVO_WATCH` + 1
        readings (one step apart)."""
        for name, errors in servos.items():
            swinging = len(errors) == SERVO_WATCH + 1 and all(
                a * b < 0 and min(abs(a), abs(b)) > SERVO_SWING for a, b in itertools.pairwise(errors)
            )
            if not swinging:
                continue
            servo = next(m.servo for m in self.spec.meshes if m.name == name)
            assert servo is not None
            shown = ", ".join(f"{1 + e:.3g}" for e in errors)
            message = (
                f"servo wall {name!r} does not settle: the force on it swings about its target from step "
                f"to step ({shown} times the target at the run's last {len(errors)} steps). The "
                f"controller (LIGGGHTS', kp={servo.kp:g}, vel_max={servo.vel_max:g} m/s) is unstable on "
                "this bed: the plate's own speed, through the contacts' damping, overturns the force each "
                "step. Lower kp or vel_max (by 2 or more)."
            )
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
        """Compare ``dt`` with the contacts that can happen now (see :meth:`_time_step_limits`):
        warn once per time step and set of contacts; refuse a step that cannot resolve them."""
        found = self._time_step_limits()
        self.time_step_check = check = None if found is None else found.assess(dt)
        if found is None or check is None or check.level == "ok":
            return
        if check.level == "error" and check_dt:
            message = f"{check.message()} Or pass check_dt=False to run() to run anyway."
            self._to_file(logging.ERROR, f"run refused: {message}")
            raise ConfigError(message)
        if (dt, found) not in self._warned:
            self._warned.add((dt, found))
            self._warn(check.message(), TimeStepWarning)

    def _time_step_limits(self) -> Limits | None:
        """The shortest Rayleigh and contact times of the contacts that can happen: between the
        species present (two particles of one) or being inserted, and of them with every
        wall's material; cached by what they depend on. The particles present are read from
        the engine only after a call or a run may have changed them (see :attr:`_present`)."""
        species = self.spec.species
        if self._present is None:
            types, radii = self._extract("type").astype(np.int64), self._extract("radius")
            kinds = [int(k) for k in np.unique(types) if 1 <= k <= len(species)]
            self._present = tuple(
                (k, float(radii[types == k].min()), int(np.count_nonzero(types == k)) > 1) for k in kinds
            )
        coming = {k for insert in self._insert_specs.values() for k in insert.species}
        smallest = {k: r for k, r, _ in self._present}
        several = {k for k, _, many in self._present if many} | coming
        for kind in coming:
            smallest[kind] = min(smallest.get(kind, math.inf), species[kind - 1].radius.min)
        walls = {}
        for wall in self._wall_specs.values():
            mesh = next((m for m in self.spec.meshes if m.name == wall.mesh and m.material), None)
            if mesh is not None:
                walls[f"mesh {mesh.name!r}"] = mesh.material
            else:
                walls[f"walls of species {wall.species}'s material"] = species[wall.species - 1].material
        key = (
            tuple(sorted((k, r, k in several) for k, r in smallest.items())),
            tuple(sorted(walls)),
        )
        if key not in self._limits:
            bodies = {
                k: Body(f"species {k}", species[k - 1].material, r, species[k - 1].density)
                for k, r in smallest.items()
            }
            pairs = [
                (bodies[a], bodies[b]) for a in bodies for b in bodies if a < b or (a == b and a in several)
            ]
            pairs += [
                (body, Body(name, material)) for body in bodies.values() for name, material in walls.items()
            ]
            materials = [s.material for s in species] + [m.material for m in self.spec.meshes if m.material]
            self._limits[key] = limits(self.spec.model, pairs, characteristic_speed(materials))
        return self._limits[key]

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
        """The likely cause of ``lost``: from their speeds and those of the particles left (an
        instability throws both far faster than the simulation explains), non-finite values,
        the time-step check, and the faces they left through."""
        check = self.time_step_check
        step = (
            f"the time step is probably too large: {check.times()}; use dt <= {check.limits.safe_dt:.2g} s"
            if check is not None and check.level != "ok"
            else None
        )
        box = self.spec.domain.lengths
        fall = math.sqrt(2 * self.spec.gravity.magnitude * float(box.max())) if self.spec.gravity else 0.0
        materials = [s.material for s in self.spec.species]
        explained = max(self._speeds, fall, characteristic_speed(materials))
        remaining = np.linalg.norm(self._extract("v").reshape(-1, 3), axis=1)
        fastest = max(lost.max_speed or 0.0, float(remaining[np.isfinite(remaining)].max(initial=0.0)))
        fast = fastest > FAST_FACTOR * explained
        if fast or lost.where.get("non-finite"):
            seen = (
                f"speeds up to {fastest:.3g} m/s, over {FAST_FACTOR:g} times the {explained:.3g} m/s the "
                "simulation explains"
                if fast
                else "non-finite positions or velocities"
            )
            return f"{seen}: " + (
                step
                or "particles probably started overlapping (created on top of each other or with a lattice "
                "spacing below a diameter) or inside a wall"
            )
        faces = sorted(place for place in lost.where if place in FACES and place not in self._outflow)
        if faces:
            at = f" at up to {lost.max_speed:.3g} m/s" if lost.max_speed is not None else ""
            went = f"they left{at} through {', '.join(faces)}"
            if step is not None:
                return f"{went} (a contact too short to resolve lets particles pass through walls): {step}"
            return (
                f"{went}, where no wall holds them: add a wall inside the box, or declare an opening "
                f"with expect_outflow({', '.join(map(repr, faces))})"
            )
        return step or "look for particles created outside the box or beyond a wall"

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

    def _check_run_size(self, nsteps: int) -> None:
        """Refuse, before it starts, a run whose step count overflows the step counters, whose
        trajectory frames cannot fit on the output's disk (at :data:`FRAME_BYTES` each, however
        few the particles) or whose monitor samples cannot fit in memory."""
        if self.step + nsteps > MAX_STEP:
            raise ConfigError(
                f"run nsteps={nsteps} would take the simulation past step {MAX_STEP}, the most the step "
                "counters hold: run fewer steps"
            )
        traj = self.spec.traj
        files = sum(path is not None for path in (traj.pfile, traj.mfile, traj.cfile))
        frames = files * (nsteps // traj.freq)
        free = shutil.disk_usage(self.output).free
        if frames * FRAME_BYTES > free:
            raise ConfigError(
                f"run nsteps={nsteps} would write {frames:.3g} trajectory frames (traj freq {traj.freq}), at "
                f"least {frames * FRAME_BYTES / 1e9:.3g} GB, but {free / 1e9:.3g} GB are free on the disk of "
                f"{self.output}: run fewer steps or raise traj freq"
            )
        samples = sum(nsteps // m.spec.freq * (2 + len(m.spec.quantities)) for m in self._monitors.values())
        memory = available_memory()
        if samples * SAMPLE_BYTES > memory:
            raise ConfigError(
                f"run nsteps={nsteps} would keep {samples:.3g} monitor values in memory, about "
                f"{samples * SAMPLE_BYTES / 1e9:.3g} GB, but {memory / 1e9:.3g} GB are free: run fewer "
                "steps or raise the monitors' freq"
            )

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
        self._log_handler.close()
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
            self._log_handler.close()
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
        """LIGGGHTS' limit on servo walls, for every engine that has them: ``vel_max`` below
        half the neighbour skin per step (a wall must not cross the skin between rebuilds)."""
        limit = self.spec.skin / (2 * dt)
        for mesh in self.spec.meshes:
            if mesh.servo is not None and not mesh.servo.vel_max < limit:
                raise ConfigError(
                    f"mesh {mesh.name!r}: servo vel_max {mesh.servo.vel_max:g} m/s must be below "
                    f"skin / (2 dt) = {limit:g} m/s (a servo wall moves at most half the neighbour "
                    "skin per step, as on LIGGGHTS): lower vel_max or dt, or raise nns_skin"
                )

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


class _Watch:
    """Lost particles of an engine that does not report them (see :meth:`Engine._lost_since_last`),
    over one run: those gone by its end, placed at the face their position and velocity at
    its start (and gravity) were heading for, and those still present whose position or
    velocity has become non-finite, each counted once."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self.start = engine.time
        self.ids, self.x, self.v = self._state()

    def _state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        extract = self.engine._extract
        return extract("id"), extract("x").reshape(-1, 3), extract("v").reshape(-1, 3)

    def finish(self) -> LostParticles:
        """What was lost since the start of the run."""
        ids, x, v = self._state()
        gone = ~np.isin(self.ids, ids)
        where: dict[str, int] = {}
        for place in exit_faces(self.engine.spec, self.x[gone], self.v[gone], self.engine.time - self.start):
            where[place] = where.get(place, 0) + 1
        broken = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        fresh = [i for i in ids[broken].tolist() if i not in self.engine._broken]
        self.engine._broken.update(fresh)
        if fresh:
            where["non-finite"] = where.get("non-finite", 0) + len(fresh)
        return LostParticles(int(gone.sum()) + len(fresh), where)  # speeds when lost: unknown


def exit_faces(spec: SimulationSpec, x: np.ndarray, v: np.ndarray, duration: float) -> list[str]:
    """The face of the box (``"z-"``, ...) each particle at ``x`` moving at ``v`` reaches first
    when it moves so, with gravity, for ``duration``; ``"non-finite"`` or ``"unknown"`` if none."""
    box = np.array(spec.domain.box, float)
    fixed = ~np.array(spec.domain.periodic)
    gravity = spec.gravity.vector if spec.gravity is not None else np.zeros(3)
    lo, hi = box[:, 0], box[:, 1]
    places = []
    for position, step in zip(x, v * duration + 0.5 * gravity * duration**2):
        if not (np.isfinite(position).all() and np.isfinite(step).all()):
            places.append("non-finite")
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = np.where(step > 0, hi, lo)
            reach = np.where(fixed & (step != 0), (bound - position) / step, np.inf)
        outside = fixed & ((position < lo) | (position > hi))
        if outside.any():
            axis = int(np.flatnonzero(outside)[0])
            places.append("xyz"[axis] + ("-" if position[axis] < lo[axis] else "+"))
        elif np.isfinite(reach).any():
            axis = int(np.argmin(reach))
            places.append("xyz"[axis] + ("+" if step[axis] > 0 else "-"))
        else:
            places.append("unknown")
    return places


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
