"""The :class:`Engine` base class: the run loop every DEM engine shares, and its collaborators.

An engine owns a solver and implements the hooks of :mod:`~pygran_core.simulation.engine_hooks`.
The base class owns what must not differ between engines: the output folder (made and locked,
never ``chdir``-ed into), capability checks, the checks of calls that need the particles
present (ids given to ``set``, overlapping created particles), handles for ``remove``, and
``run``: progress, step and time accounting, and the events (trajectory frames, monitor
samples, insertions, checkpoints) between which the solver runs without returning to Python.
It hands the rest to collaborators, each in its own module:

- :class:`~pygran_core.simulation.log.EngineLog`: the messages, in ``<output>/pygran.log``;
- :class:`~pygran_core.simulation.output.Output`: trajectories and monitors;
- :class:`~pygran_core.simulation.resume.Journal`: the calls, their replay on resume, checkpoints;
- :mod:`~pygran_core.simulation.diagnostics`: refusals, the time step, lost particles, servo swing;
- :class:`~pygran_core.simulation.scene.Scene`: what the base knows of the contents (walls,
  insertions, the particles present), and the obstacles new particles must clear;
- :class:`~pygran_core.simulation.insertion.Inserter`: placing particles, held by the engines
  whose solver cannot.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import functools
import itertools
import logging
import os
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from pygran_core.errors import (
    ConfigError,
    EngineError,
    LostParticlesWarning,
    PyGranError,
    ServoWarning,
    TimeStepWarning,
    unknown_key,
)
from pygran_core.io import Frame
from pygran_core.simulation.calls import (
    CreateSpec,
    InsertSpec,
    MonitorSpec,
    MotionSpec,
    SetSpec,
    ViscousSpec,
    WallSpec,
)
from pygran_core.simulation.checkpoint import Checkpoint, checkpoint_path
from pygran_core.simulation.diagnostics import (
    SERVO_WATCH,
    LostParticles,
    RunWatch,
    check_ids,
    check_run_size,
    check_servo_speeds,
    check_servos_are_walls,
    force_servos,
    outflow_faces,
)
from pygran_core.simulation.engine_hooks import EngineHooks, Handle
from pygran_core.simulation.insertion import Obstacles
from pygran_core.simulation.log import EngineLog, progress_shown
from pygran_core.simulation.materials import MaterialTable, build_table
from pygran_core.simulation.mpi import launch_rank, launch_size
from pygran_core.simulation.output import Monitor, Output, mesh_frame, particle_frame
from pygran_core.simulation.progress import Progress
from pygran_core.simulation.resume import Journal
from pygran_core.simulation.scene import Scene
from pygran_core.simulation.specs import SimulationSpec, given, positive_float, positive_int
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
    rank = launch_rank()
    try:
        output.mkdir(parents=True, exist_ok=True)
        if not os.access(output, os.W_OK | os.X_OK):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
        lock = open(output / LOCK_NAME, "a+", encoding="utf-8")
        if rank != 0:
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


class Handles:
    """The handles of the objects a simulation's calls made and has not removed, by id."""

    _engines = itertools.count(1)

    def __init__(self) -> None:
        self.engine_id = next(Handles._engines)
        self.live: dict[int, Handle] = {}
        self._ids = itertools.count(1)

    def new(self, kind: str, label: str) -> Handle:
        """Record a removable object the solver calls ``label`` and return its handle."""
        handle = Handle(kind, next(self._ids), label, self.engine_id)
        self.live[handle.id] = handle
        return handle

    def live_one(self, handle: Any) -> Handle:
        """``handle``, refused unless it is one of these not yet removed."""
        if not isinstance(handle, Handle) or handle.engine_id != self.engine_id:
            raise ConfigError(f"{handle!r} is not a handle returned by this simulation")
        if handle.id not in self.live:
            raise ConfigError(f"{handle.kind} {handle.label!r} was already removed")
        return handle


def run_pieces(
    start: int, end: int, span: tuple[int, int], every: list[int], events: set[int], most: int, watched: bool
) -> list[int]:
    """The steps from ``start`` to ``end`` of the run over ``span`` (its first and last step)
    in pieces: split at each multiple of the intervals ``every`` and at the ``events``, the
    whole run in at most ``most`` pieces, and its last :data:`~.diagnostics.SERVO_WATCH` steps
    one by one when a servo wall's force is ``watched``."""
    first, last = span
    stops = {end} | events
    for freq in every:
        stops.update(range((start // freq + 1) * freq, end, freq))
    total = last - first
    pieces = min(total, most)
    stops.update(first + (total * k) // pieces for k in range(1, pieces))
    if watched and total > SERVO_WATCH:
        stops.update(range(last - SERVO_WATCH, last))  # single steps, see RunWatch
    ordered = sorted(s for s in stops if start < s <= end)
    return [b - a for a, b in zip([start, *ordered], ordered)]


class Engine(EngineHooks):
    """Base class of DEM engines, built from a validated :class:`SimulationSpec`. A subclass
    sets :attr:`name` and :attr:`capabilities` and implements :meth:`_advance`, :meth:`_extract`
    and the hooks of what it supports (:mod:`~pygran_core.simulation.engine_hooks`); it
    overrides nothing else."""

    def __init__(self, spec: SimulationSpec) -> None:
        self.spec = spec
        self.output = spec.output
        self._output_lock = claim_output(self.output)
        self.dt = spec.dt
        self.step = 0
        self.time = 0.0
        #: (step, time) at the last change of dt: time is computed from it, not summed per chunk.
        self._clock = (0, 0.0)
        self._run_span = (0, 0)  # the first and last step of the run in progress
        self.closed = False
        self._handles = Handles()
        #: Particles lost in all runs so far, and in the last run.
        self.lost = 0
        self.last_lost = LostParticles()
        #: The last run's time step against the contacts present (``None``: no contact possible).
        self.time_step_check: Assessment | None = None
        self.messages = EngineLog(self.name, self.output, self._writes_output())
        self._progress = Progress(spec.progress, self.messages.progress, collective=launch_size() > 1)
        self.files = Output(spec, self.messages, self._writes_output(), self._native_trajectories())
        self.log("%s engine opened, output in %s", self.name, self.output)
        try:
            self._check_spec(spec)
            if spec.dt is not None:
                check_servo_speeds(spec, spec.dt)
        except PyGranError as exc:
            self.messages.to_file(logging.ERROR, f"refused: {exc}")
            self._abandon()
            raise
        try:
            self.journal = Journal(self.name, spec.restart, self.messages)
        except BaseException:
            self._abandon()
            raise
        self.scene = Scene(spec, self._extract, fresh=not self.replaying)

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

    def log(self, message: str, *args: Any, level: int = logging.INFO) -> None:
        """Record ``message % args`` in ``<output>/pygran.log``, and on the ``pygran`` logger
        for whoever has configured logging to show it."""
        self.messages.log(message, *args, level=level)

    def _check_open(self) -> None:
        if self.closed:
            raise EngineError(f"This {self.name} simulation is closed; create a new one")

    def _new_handle(self, kind: str, label: str) -> Handle:
        return self._handles.new(kind, label)

    def _call(self, kind: str, hook: Callable[[Any], str], spec: Any) -> Handle:
        self._check_open()
        self.journal.record(f"{kind} {spec!r}", spec)
        self.log("%s %s", kind, spec)
        return self._new_handle(kind, hook(spec))

    @property
    def replaying(self) -> bool:
        """Whether the script is being replayed up to the checkpoint it resumes from."""
        return self.journal.replaying

    @property
    def handles(self) -> tuple[Handle, ...]:
        """Handles of the objects not yet removed, oldest first."""
        return tuple(self._handles.live.values())

    # -- calls -------------------------------------------------------------------------

    def insert(self, spec: InsertSpec) -> Handle:
        if spec.mechanism == "by_rate":
            self.require("insert-by-rate", "insertion by rate")
        handle = self._call("insertion", self._insert, spec)
        self.scene.inserts[handle.id] = spec
        self.scene.forget()
        spread = np.linalg.norm(spec.velocity.spread) * (3 if spec.velocity.kind == "gaussian" else 1)
        self.scene.gave(float(np.linalg.norm(spec.velocity.mean) + spread))
        return handle

    def create_particles(self, spec: CreateSpec) -> int:
        """Create particles now; returns how many were created. Particles created at given
        positions (``'single'``) or on a lattice must not overlap each other or the particles
        present (see :func:`.diagnostics.check_clear`): they would repel at high speed."""
        self._check_open()
        if spec.style in ("single", "lattice") and not self.replaying:
            self.scene.check_clear(spec)
        recorded = self.journal.record(f"create {spec!r}", spec)
        if self.replaying:
            return recorded
        count = self._create(spec)
        self.journal.result(count)
        self.scene.created(spec)
        self.scene.gave(float(np.linalg.norm(spec.velocity)))
        self.log("create %s: %d particles", spec, count)
        return count

    def set_properties(self, spec: SetSpec) -> int:
        """Assign velocity, angular velocity and/or radius to the selected particles; returns
        how many. ``ids`` that no particle has are a :class:`ConfigError`."""
        self._check_open()
        present = self._extract("id") if not self.replaying else np.zeros(0, np.int64)
        if spec.ids is not None and not self.replaying:
            check_ids(spec.ids, present)
        recorded = self.journal.record(f"set {spec!r}", spec)
        if self.replaying:
            return recorded
        ids = spec.select(present, self._extract("type"), self._extract("x"))
        if len(ids):
            self._assign(ids, spec)
            self.scene.forget()
        if spec.velocity is not None:
            self.scene.gave(float(np.linalg.norm(spec.velocity)))
        self.log("set %s: %d particles", spec, len(ids))
        self.journal.result(len(ids))
        return len(ids)

    def setup_wall(self, spec: WallSpec) -> Handle:
        self.require("mesh-walls" if spec.kind == "mesh" else "primitive-walls", f"{spec.kind} walls")
        handle = self._call("wall", self._wall, spec)
        self.scene.walls[handle.id] = spec
        return handle

    def move_mesh(self, spec: MotionSpec) -> Handle:
        self.require("moving-mesh", "moving meshes")
        handle = self._call("motion", self._move_mesh, spec)
        self.scene.moving[handle.id] = spec.mesh
        return handle

    def add_viscous(self, spec: ViscousSpec) -> Handle:
        return self._call("viscous", self._viscous, spec)

    def monitor(self, spec: MonitorSpec) -> Monitor:
        return self.files.add_monitor(self._call("monitor", lambda s: s.file, spec), spec, self.output)

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
        self.journal.record(f"command {text}")
        self.log("command %s", text)
        self._command(text)
        self.scene.forget()

    def remove(self, handle: Handle | Monitor) -> None:
        """Remove what ``handle`` refers to (an insertion, wall, mesh motion, force, monitor)."""
        self._check_open()
        handle = self._handles.live_one(handle.handle if isinstance(handle, Monitor) else handle)
        self.journal.record(f"remove {handle.kind} {handle.label}")
        if handle.kind == "monitor":
            del self.files.monitors[handle.id]
        elif handle.kind == "insertion" and self.inserter is not None:
            self.inserter.remove(handle.label)
        else:
            self._remove(handle)
        del self._handles.live[handle.id]
        self.scene.removed(handle.id)
        self.log("remove %s %s", handle.kind, handle.label)

    def expect_outflow(self, *faces: str) -> None:
        """Declare that particles leave through these faces of the domain (``"z-"``: below the
        lower z bound; see :data:`~.diagnostics.FACES`): their loss is logged, not warned. Call
        it without faces to expect none again."""
        self.scene.outflow = outflow_faces(self.spec, faces)
        self.log("outflow expected through %s", ", ".join(sorted(self.scene.outflow)) or "no face")

    # -- running -----------------------------------------------------------------------

    def run(
        self, nsteps: int, dt: float | None = None, *, progress: bool | None = None, check_dt: bool = True
    ) -> None:
        """Advance ``nsteps`` time steps (of ``dt``, or the simulation's time step). Before it,
        ``dt`` is checked against the contacts that can happen (:mod:`.timestep`: a
        :class:`TimeStepWarning`, or a :class:`ConfigError` unless ``check_dt=False``) and the
        servo walls' speed limit. Frames, samples, insertions and checkpoints are taken at their
        frequencies (in absolute steps); the solver runs uninterrupted between them and the
        progress updates (:func:`.log.progress_shown`). Particles lost are reported (see
        :meth:`expect_outflow`), counted in :attr:`lost` and described in :attr:`last_lost`."""
        self._check_open()
        nsteps = positive_int(nsteps, "nsteps")
        check_run_size(self.spec, self.step, nsteps, [m.spec for m in self.files.monitors.values()])
        if dt is not None:
            dt = positive_float(dt, "dt")
        elif self.dt is None:
            replayed = self.journal.replayed_dt()
            self.dt = replayed if replayed is not None else self._default_dt()
        run_dt = dt if dt is not None else self.dt
        if run_dt is None:
            raise ConfigError("No time step: pass dt to run(nsteps, dt) or dt=... to DEM")
        if not self.replaying:
            self._check_time_step(run_dt, check_dt)
            check_servo_speeds(self.spec, run_dt)
            check_servos_are_walls(self.spec, self.scene.mesh_walls())
        if run_dt != self.dt:
            self._clock, self.dt = (self.step, self.time), run_dt
        self.log("run %d steps of dt=%g from step %d", nsteps, self.dt, self.step)
        show, self.messages.progress_to_stderr = progress_shown(progress, self.spec.progress.show)
        from tqdm import tqdm

        start, end = self.step, self.step + nsteps
        self._run_span = (start, end)
        self.journal.record_run(nsteps, self.dt)
        if self.journal.finished_before():
            self._set_step(end, run_dt)
            self._progress.skip(nsteps)
            return  # a run the checkpoint's script had finished before it
        if self.journal.checkpoint is not None:
            self._restore(self.journal.resume())  # the run the checkpoint was taken in
        elif self.step == 0:
            self._on_event()
        if self.inserter is not None:
            self.inserter.make_due(end)  # those due as the run starts
        servos = self.mesh_force if "servo-walls" in self.capabilities else None
        watch = RunWatch(
            self.spec, start, end, self.time, self._extract, self._lost_since_last, self.scene.broken, servos
        )
        self._progress.begin(self.step, end, first=start)
        with tqdm(
            total=nsteps, initial=self.step - start, unit="step", disable=not show, desc=f"{self.name} run"
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
                watch.after_piece(self.step)
        self.messages.progress(self._progress.end(self.step), stderr=bool(self._progress.lines))
        self.scene.forget(moved_only=True)
        self._report_lost(*watch.lost(self.time), start)
        for message in watch.servo_warnings():
            self.messages.warn(message, ServoWarning)

    def _set_step(self, step: int, dt: float) -> None:
        """Move the clock to ``step``, ``dt`` after ``dt`` since the last change of time step."""
        self.step = step
        self.time = self._clock[1] + (step - self._clock[0]) * dt

    def _run_chunks(self, end: int) -> Iterator[int]:
        """The pieces of :meth:`_chunks` from this step to ``end``, listed a segment of
        :data:`RUN_SEGMENT` steps at a time (a run of 10**15 steps lists no step in advance)."""
        self._run_span = (self.step, end)
        while self.step < end:
            yield from self._chunks(min(end - self.step, RUN_SEGMENT))

    def _chunks(self, nsteps: int) -> list[int]:
        """The next ``nsteps`` steps of the run in pieces (see :func:`run_pieces`)."""
        start, end = self.step, self.step + nsteps
        restart = self.spec.restart
        every = self.files.frequencies() + ([restart.freq] if restart is not None else [])
        watched = "servo-walls" in self.capabilities and bool(force_servos(self.spec))
        events = self._event_steps(start, end)
        return run_pieces(start, end, self._run_span, every, events, self.max_run_chunks, watched)

    def _on_event(self) -> None:
        """Make the insertions due at this step (if a step of the run follows), then take the
        trajectory frames, monitor samples and checkpoint due."""
        if self.inserter is not None:
            self.inserter.make_due(self._run_span[1])
        self.files.take(self.step, self.time, self._frames, self._scalar, self._species_scalar)
        restart = self.spec.restart
        if restart is not None and self.step > 0 and self.step % restart.freq == 0:
            self._checkpoint(checkpoint_path(restart, self.step))

    def _frames(self, key: str) -> list[Frame]:
        """The frames of trajectory ``key`` due now."""
        if key == "particles":
            return [particle_frame(self.spec, self._extract, self.step, self.time)]
        if key == "meshes":
            return [mesh_frame(self._meshes("mesh output"), self.step, self.time)]
        return self._contact_frames()

    # -- the walls, the time step and lost particles ---------------------------------------

    def _meshes(self, call: str) -> list[np.ndarray]:
        """The triangles of the mesh walls where they are now (:meth:`_mesh_triangles`), for ``call``."""
        return [
            self.scene.mesh_where(name, self._mesh_triangles(name), self.name, call)
            for name in self.scene.mesh_walls()
        ]

    def obstacles(self, call: str) -> Obstacles:
        """The walls new particles of ``call`` must clear (see :func:`.insertion.wall_obstacles`)."""
        return self.scene.obstacles(self._meshes(call))

    def _check_time_step(self, dt: float, check_dt: bool) -> None:
        """Compare ``dt`` with the contacts that can happen now (:meth:`.Scene.judge_time_step`):
        warn, or refuse a step they cannot resolve."""
        self.time_step_check, refusal, warning = self.scene.judge_time_step(dt, check_dt)
        if refusal is not None:
            self.messages.to_file(logging.ERROR, f"run refused: {refusal}")
            raise ConfigError(refusal)
        if warning is not None:
            self.messages.warn(warning, TimeStepWarning)

    def _report_lost(self, lost: LostParticles, estimated: bool, start: int) -> None:
        """Count the particles lost in the run from ``start``; warn of the unexpected ones."""
        self.last_lost = lost
        if not lost.count:
            return
        self.lost += lost.count
        self.scene.forget()
        expected, warning = self.scene.lost_report(
            self.name, lost, estimated, (start, self.step), self.lost, self.time_step_check
        )
        if expected is not None:
            self.log("%s", expected)
        if warning is not None:
            self.messages.warn(warning, LostParticlesWarning)

    # -- checkpoints ----------------------------------------------------------------------

    def _checkpoint(self, path: Path) -> None:
        """Write everything needed to continue from this step to ``path`` (HDF5): the clock,
        the insertion schedules and the engine's state (:meth:`_state`)."""
        state = {"clock": np.array(self._clock, float), **(self.inserter.state() if self.inserter else {})}
        state.update(self._state())
        checkpoint = Checkpoint(
            self.name, self.step, self.time, self.dt, [], self.files.samples(), state, self._facts()
        )
        self.journal.write(path, checkpoint, self._checkpoint_files())

    def _restore(self, checkpoint: Checkpoint) -> None:
        """Continue from ``checkpoint``, the one being resumed: the clock, the insertion
        schedules, the engine's state, the monitors, and the trajectories cut back to its step."""
        path = given(self.journal.path, "the checkpoint's file")
        self.files.check_samples(checkpoint.monitors, path)
        self.journal.compare_facts(checkpoint, self._facts())
        self.step, self.time, self.dt = checkpoint.step, checkpoint.time, checkpoint.dt
        self._clock = (int(checkpoint.state["clock"][0]), float(checkpoint.state["clock"][1]))
        if self.inserter is not None:
            self.inserter.restore(checkpoint.state, path)
        self._restore_state(checkpoint.state)
        self.scene.forget()
        self.files.restore(checkpoint.monitors, self.step)
        self.log("resumed from %s at step %d", path, self.step)

    def _abandon(self) -> None:
        """Release the log and the output folder of an engine whose construction failed (its
        subclass calls this on a failure after the base class's constructor)."""
        self.messages.close()
        self._output_lock.close()
        self.closed = True

    def close(self) -> None:
        """Finish output files and release the solver; closing twice is harmless."""
        if self.closed:
            return
        try:
            self.files.close()
            self._close()
        finally:
            self.closed = True
            self.log("%s engine closed at step %d", self.name, self.step)
            self.messages.close()
            self._output_lock.close()

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
