"""The LIGGGHTS engine: PyGran's specs as LIGGGHTS commands, run in a worker or under mpirun.

From a plain ``python`` process, LIGGGHTS runs in a worker job (``nprocs`` MPI ranks) that
may die on a LIGGGHTS error without taking the user's session with it: the error becomes an
:class:`EngineError` with LIGGGHTS' message, and a new simulation can be started. When the
script itself runs under ``mpirun`` (the manual's mode), each rank loads LIGGGHTS in
process; ``nSim=k`` then splits ``COMM_WORLD`` into k groups, each running its own
simulation (there, a LIGGGHTS error ends the MPI job, as LIGGGHTS calls ``exit``).

Commands go to LIGGGHTS through a :class:`~.channel.Channel`, which queues them while the
worker starts and records them in ``<output>/in.pygran``. A run is split into chunks (``run N
pre no`` after the first when no command came in between, so LIGGGHTS skips its set-up),
each ended after every insertion event, so that the particles lost are seen first (see
:meth:`.FixInsertions.lost`). Mesh frames are LIGGGHTS' own files, indexed in a
``.pvd`` as PyGran's VTK series are (see :class:`.MeshIndex`).

LIGGGHTS' ``fix insert`` keeps new particles clear of other particles, not of mesh walls: an
insertion into a region that a mesh wall crosses is made by PyGran instead, as the placing
engines make it (see :mod:`.placings`).
"""

from __future__ import annotations

import os
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pygran_core.errors import (
    ConfigError,
    ReadError,
    UnsupportedFeature,
)
from pygran_core.io import Frame
from pygran_core.simulation.checkpoint import decode_text, encode_text, state_entry
from pygran_core.simulation.engine import Engine, LostParticles
from pygran_core.simulation.mpi import MPI_LAUNCH_VARIABLES, launch_communicator
from pygran_core.simulation.output import NativeTrajectory, bounds
from pygran_core.simulation.specs import control_characters, given
from pygran_liggghts.channel import LOG_NAME, Channel
from pygran_liggghts.commands import (
    BODY_ENERGY,
    CONTACTS_DIR,
    Commands,
    fmt,
    native_meshes,
    native_particles,
)
from pygran_liggghts.contact_dumps import read_contacts
from pygran_liggghts.creation import Creator
from pygran_liggghts.insertions import FixInsertions
from pygran_liggghts.library import ADDON_CAPABILITIES, Addon, load_addon, probe_addon
from pygran_liggghts.mesh_index import MeshIndex
from pygran_liggghts.placings import Placings
from pygran_liggghts.walls import Walls

if TYPE_CHECKING:
    from pygran_core.simulation.calls import (
        CreateSpec,
        InsertSpec,
        MotionSpec,
        SetSpec,
        ViscousSpec,
        WallSpec,
    )
    from pygran_core.simulation.checkpoint import Checkpoint
    from pygran_core.simulation.engine import Handle
    from pygran_core.simulation.specs import RestartSpec, SimulationSpec

#: The checkpoint entry naming LIGGGHTS' own restart file.
RESTART_KEY = "liggghts/restart"
#: Checkpoint entries ``<TARGET_KEY>/<k>``: the target of the k-th insert call (by pack).
TARGET_KEY = "liggghts/targets"


def restart_file(path: Path, checkpoint: Checkpoint, directory: Path) -> Path:
    """The LIGGGHTS restart file that checkpoint ``checkpoint`` (read from ``path``) names, in
    the checkpoint folder ``directory``: a checkpoint naming anything but a file beside it is a
    :class:`ReadError`, a missing file a :class:`ConfigError`."""
    entry = state_entry(path, checkpoint.state, RESTART_KEY, "u", (None,))
    try:
        name = decode_text(entry)
    except UnicodeDecodeError:
        name = ""
    if not name or Path(name).name != name or name in (".", ".."):
        raise ReadError(
            f"{path}: the checkpoint's state entry {RESTART_KEY!r} is "
            f"{bytes(entry)[:80]!r}, not the name of a LIGGGHTS restart file beside it"
        )
    if not (directory / name).is_file():
        raise ConfigError(f"{path} needs the LIGGGHTS restart file {directory / name}, which is missing")
    return directory / name


def spheres_energy(quantity: str, arrays: dict[str, np.ndarray], chosen: np.ndarray) -> float:
    """``ke`` or ``ke_rot`` of the spheres ``chosen`` (a mask) in the gathered ``arrays``
    (``v``, ``omega``, ``radius``, ``mass``)."""
    mass = arrays["mass"][chosen]
    if quantity == "ke":
        v = arrays["v"][chosen]
        return float(0.5 * np.sum(mass * np.einsum("ij,ij->i", v, v)))
    omega = arrays["omega"][chosen]
    return float(
        0.5 * np.sum(0.4 * mass * arrays["radius"][chosen] ** 2 * np.einsum("ij,ij->i", omega, omega))
    )


def launch_world() -> Any:
    """``MPI.COMM_WORLD`` when an MPI launcher started this process, else ``None``: the core's
    :func:`~pygran_core.simulation.mpi.launch_communicator`, and also for a single rank
    (``mpirun -np 1``), from which no worker job can be started."""
    world = launch_communicator()
    if world is None and any(name in os.environ for name in MPI_LAUNCH_VARIABLES):
        from mpi4py import MPI

        world = MPI.COMM_WORLD
    return world


def mpi_placement(world: Any, spec: SimulationSpec) -> tuple[Any, SimulationSpec]:
    """Under ``mpirun`` (``world`` its ranks): this rank's communicator and simulation (one of
    ``nSim`` runs)."""
    if world.size < spec.nsim:
        raise ConfigError(f"nSim={spec.nsim} needs at least {spec.nsim} MPI ranks; got {world.size}")
    if spec.nsim == 1:
        return world, spec
    group = world.rank * spec.nsim // world.size
    return world.Split(group, world.rank), spec.runs[group]


#: What the engine does on LIGGGHTS alone; :func:`capabilities` adds the add-on's.
LIGGGHTS_CAPABILITIES = frozenset(
    {
        "mesh-walls",
        "moving-mesh",
        "mesh-vibration",
        "servo-walls",
        "primitive-walls",
        "periodic",
        "polydisperse",
        "pair-tables",
        "multisphere",
        "spring-dashpot",
        "hertz-mindlin",
        "cohesion",
        "rolling-friction",
        "rolling-epsd",
        "rolling-epsd2",
        "rolling-epsd3",
        "limit-force",
        "insert-by-rate",
        "monitor-species",
        "mpi",
        "restart",
        "raw-commands",
        "liggghts-dump",
        "neighbor-styles",
        "contact-output",
    }
)


def addon() -> Addon:
    """Whether the Thornton-Ning add-on loads: under ``mpirun`` loaded here, where LIGGGHTS runs,
    else in a probe process, so that libliggghts and the libraries it is linked to (Debian's
    VTK, which crashes pip's) never enter a process that runs LIGGGHTS in a worker."""
    return load_addon() if launch_world() is not None else probe_addon()


@cache
def capabilities() -> frozenset[str]:
    """The engine's capabilities, with the add-on's when it loads (decided on first use)."""
    return LIGGGHTS_CAPABILITIES | (ADDON_CAPABILITIES if addon().loaded else frozenset())


class _Capabilities:
    """:attr:`LiggghtsEngine.capabilities`: :func:`capabilities`, read when first needed, not
    when this module is imported."""

    def __get__(self, engine: LiggghtsEngine | None, owner: type) -> frozenset[str]:
        return capabilities()


class LiggghtsEngine(Engine):
    """A simulation on LIGGGHTS 3.x (``libliggghts``), see the module docstring."""

    name = "liggghts"
    capabilities = _Capabilities()
    #: Each run chunk is a LIGGGHTS ``run``; few chunks keep the overhead negligible.
    max_run_chunks = 10

    def __init__(self, spec: SimulationSpec) -> None:
        comm = None
        world = launch_world()
        if world is not None:
            comm, spec = mpi_placement(world, spec)
        elif spec.nsim > 1:
            raise ConfigError(
                f"nSim={spec.nsim} runs one simulation per group of ranks: start the script "
                f"with mpirun -np {spec.nsim} (or more)"
            )
        #: Whether this process writes the simulation's files and messages (rank 0 of its group)
        self._root = comm is None or comm.rank == 0
        self._mesh_index = MeshIndex(self, self._root)  # before the base class takes its due()
        super().__init__(spec)
        self._timestep = spec.dt
        #: Where the resumed step's frame starts in LIGGGHTS' ``.dump``, until a run writes it again
        self._rewritten_frame: int | None = None
        #: By-pack one-offs of a resumed script, made before its checkpoint: no fix in LIGGGHTS
        self._fixless: set[str] = set()
        #: label -> (the insert call's number, the target given to LIGGGHTS) of each by-pack
        #: insertion present: checkpoints keep the targets, which a resumed script's replayed
        #: calls would otherwise count anew from the restart's particles
        self._targets: dict[str, tuple[int, float]] = {}
        self._insert_calls = 0
        self._computed = False  # whether a run has set up LIGGGHTS' computes
        self._unreported = LostParticles()  # lost particles not yet reported to the front end
        self._contacts_step = -1  # the last step whose contact records (traj cfile) were read
        try:
            if spec.traj.mfile is not None and spec.meshes and spec.traj.mfile.suffix != ".vtk":
                raise ConfigError(f"LIGGGHTS writes meshes as .vtk files, not {spec.traj.mfile.name}")
            if comm is not None and spec.nprocs not in (None, comm.size):
                raise ConfigError(f"nprocs={spec.nprocs} differs from the {comm.size} MPI ranks of this run")
            self.commands = Commands(spec, self.material_table)
            self.log("neighbour lists: skin %g m, style %s", spec.skin, spec.nns_type)
            if spec.traj.cfile is not None and self._root:  # frames of an earlier run are stale
                for stale in (self.output / CONTACTS_DIR).glob("pg_*.dump"):
                    stale.unlink()
            resume = None
            if self.journal.checkpoint is not None:
                resume = restart_file(
                    given(self.journal.path, "the checkpoint"),
                    self.journal.checkpoint,
                    self._restart.directory,
                )
            #: LIGGGHTS read a restart file and has not run since: it refuses create_atoms then
            self._restored = resume is not None
            self._channel = Channel(self.output, comm, spec.nprocs or 1, self._root, self.log)
            screen = self.output / LOG_NAME if self._root else None
            self._fixes = FixInsertions(self, self._channel, self.commands, screen)
            self._walls = Walls(spec, self.commands, self._channel)
            ranks = comm.size if comm is not None else spec.nprocs or 1
            self._creator = Creator(
                self,
                self._channel,
                self.commands,
                ranks,
                self._root,
                self._allow_create,
                self._holds_histories,
            )
            self._placings = Placings(self, self.commands, self._walls, self._creator)
            self._execute(self.commands.setup(resume))
        except BaseException:
            self.close()
            raise

    def _why_missing(self, capability: str) -> str:
        """Why an add-on's capability is missing: the add-on did not load."""
        return f"On LIGGGHTS: {addon().reason}" if capability in ADDON_CAPABILITIES else ""

    def _writes_output(self) -> bool:
        """Messages and files once per simulation, from rank 0 of its group."""
        return self._root

    # -- talking to LIGGGHTS ---------------------------------------------------------------

    def _execute(self, lines: list[str]) -> None:
        """Run ``lines`` now, or once the worker has started (see :meth:`.Channel.execute`)."""
        self._channel.execute(lines)

    # -- engine hooks ------------------------------------------------------------------------

    def _advance(self, nsteps: int) -> None:
        dt = given(self.dt, "the time step")  # run() refuses to start without one
        self._placings.make_due(self.step)  # PyGran's insertions due as this piece starts
        lines = self._walls.contact_computes() + self._creator.regroup()
        if dt != self._timestep:
            lines.append(f"timestep {fmt(dt)}")
            self._timestep = dt
        # pre no: nothing changed since the last run (no command in between), so LIGGGHTS
        # may skip its set-up (init, neighbour lists, forces): those of the last step hold;
        # except with a servo wall in mode auto, whose speed in contact LIGGGHTS derives at
        # init from the smallest particle present
        auto = any(mesh.servo and mesh.servo.mode == "auto" for mesh in self.spec.meshes)
        pre = "pre no " if self._channel.prepared and not lines and not auto else ""
        self._fixes.starting(dt)
        self._channel.queue(lines)
        start = self.step
        # a run stops after each insertion event, so that the particles it makes are seen
        # before they can leave: each one lost has a start to be placed from
        stops = sorted(self._fixes.stops(start, start + nsteps))
        pieces = [b - a for a, b in zip([start, *stops], [*stops, start + nsteps])]
        again = "" if auto else "pre no "
        runs = [f"run {n} {pre if k == 0 else again}post no" for k, n in enumerate(pieces)]
        self._before_run()
        losses = self._channel.run(runs, sorted(self._fixes.specs))
        self._computed = True
        self._restored = False
        if any(count for count, _, _ in losses):
            self._unreported += self._fixes.lost(losses, pieces, dt)
        self._fixes.report(start, start + nsteps)
        self._mesh_index.update()  # the frame LIGGGHTS wrote as this run started

    def _event_steps(self, start: int, end: int) -> set[int]:
        """The events of PyGran's insertions, each made as the piece of the run it starts begins."""
        return self._placings.event_steps(start, end)

    def _lost_since_last(self) -> LostParticles:
        """The particles LIGGGHTS lost since the last call, counted exactly in every run
        (``thermo_modify lost warn`` keeps it going; see :meth:`~.worker.Session.run`)."""
        lost, self._unreported = self._unreported, LostParticles()
        return lost

    def _extract(self, quantity: str) -> np.ndarray:
        return self._channel.gather(quantity)[quantity]

    def bodies(self) -> np.ndarray:
        """The body each particle belongs to, ordered by id as :meth:`extract`: LIGGGHTS'
        body id (1, 2, ...) for the spheres of multisphere particles, -1 for single spheres.
        (``extract('x')`` and the trajectory give every sphere of a multisphere particle.)"""
        self._check_open()
        if not self.commands.body_types:
            return np.full(len(self._extract("id")), -1)
        return self._extract("mol")

    def _scalar(self, quantity: str) -> float:
        if quantity in ("ke", "ke_rot"):
            return self._energy(quantity, None)
        return float(self._channel.request("natoms")) if quantity == "n" else super()._scalar(quantity)

    def _species_scalar(self, quantity: str, species: tuple[int, ...]) -> float:
        if quantity in ("ke", "ke_rot"):
            return self._energy(quantity, species)
        return super()._species_scalar(quantity, species)

    def _energy(self, quantity: str, species: tuple[int, ...] | None) -> float:
        """``ke`` or ``ke_rot`` of the single spheres (of ``species``; ``None``: of all), plus,
        with multisphere species, those of the bodies from LIGGGHTS' computes (each sphere of a
        body carries the body's mass and angular velocity, so the bodies' energies cannot be
        summed over their spheres; the computes take every body, so no species of them is chosen)."""
        bodies = bool(self.commands.body_types)
        chosen_bodies = sorted(set(species or ()) & set(self.commands.body_types))
        if chosen_bodies:
            raise UnsupportedFeature(
                f"a monitor of multisphere species {chosen_bodies} on LIGGGHTS: its energies of "
                "multisphere bodies are over every body; monitor species='all', or species of single spheres"
            )
        names = ["v", "omega", "radius", "mass", *(["mol"] if bodies else []), *(["type"] if species else [])]
        arrays = self._channel.gather(*names)
        single = arrays["mol"] < 0 if bodies else np.ones(len(arrays["mass"]), bool)
        if species:
            single &= np.isin(arrays["type"], species)
        energy = spheres_energy(quantity, arrays, single)
        if bodies and species is None:
            if not self._computed:  # LIGGGHTS sets its computes up as a run starts
                self._set_up()
            energy += self._channel.request("scalar", BODY_ENERGY[quantity])
        return energy

    def _insert(self, spec: InsertSpec) -> str:
        number = self._insert_calls
        self._insert_calls += 1
        reached = self._placings.reached(spec)
        if reached:
            return self._placings.add(spec, reached)
        if spec.mechanism == "by_pack" and self.journal.checkpoint is not None:  # replaying: the kept target
            kept = self.journal.checkpoint.state.get(f"{TARGET_KEY}/{number}")
            spec = spec if kept is None else replace(spec, value=float(kept))
        elif spec.mechanism == "by_pack":
            spec = self._fixes.target(spec)
        label, lines = self.commands.insert(spec, self.dt)
        if self.replaying and spec.mechanism == "by_pack" and not spec.freq:
            # done before the checkpoint: its particles are in the restart file, and a new
            # insert/pack would fill its region up again
            self._fixless.add(label)
            return label
        self._execute(lines)
        self._fixes.add(label, spec)
        if spec.mechanism == "by_pack":
            self._targets[label] = (number, spec.value)
        return label

    def _create(self, spec: CreateSpec) -> int:
        return self._creator.create(spec)

    def _allow_create(self) -> None:
        """Let LIGGGHTS create atoms: after reading a restart file it refuses ``create_atoms``
        until a run has set it up."""
        if self._restored:
            self._set_up()
            self._restored = False

    def _holds_histories(self) -> bool:
        """Whether LIGGGHTS keeps contact histories now: of mesh walls, or the pair style's
        once a run has set it up."""
        return bool(self._walls.meshes) or self._computed

    def _set_up(self) -> None:
        """Run 0 steps: LIGGGHTS sets itself up (its computes too) as a run starts, and its
        dumps write this step's frames as the next run would."""
        self._before_run()
        self._execute(["run 0 post no"])
        self._computed = True

    def _assign(self, ids: np.ndarray, spec: SetSpec) -> None:
        if self.commands.body_types:
            types = self._extract("type")[np.isin(self._extract("id"), ids)]
            bodies = sorted(set(types.tolist()) & set(self.commands.body_types))
            if bodies:
                raise UnsupportedFeature(
                    f"set() on the spheres of multisphere species {bodies}: LIGGGHTS moves them with "
                    "their bodies; select the species of single spheres (species=...)"
                )
        group = self.commands.new_id("set")
        lines = [f"group {group} id {' '.join(str(int(i)) for i in ids)}"]
        if spec.velocity is not None:
            vx, vy, vz = (fmt(v) for v in spec.velocity)
            lines.append(f"set group {group} vx {vx} vy {vy} vz {vz}")
        if spec.radius is not None:
            lines.append(f"set group {group} diameter {fmt(2 * spec.radius)}")
            types = self._extract("type")[np.isin(self._extract("id"), ids)]
            for species in np.unique(types):  # the mass follows the new size at the species' density
                density = fmt(self.spec.species[int(species) - 1].density)
                lines.append(f"set type {int(species)} density {density}")
        lines.append(f"group {group} delete")
        self._execute(lines)
        if spec.omega is not None:
            self._channel.set_omega(np.asarray(ids), spec.omega, f"{len(ids)} atoms chosen by set()")

    def _wall(self, spec: WallSpec) -> str:
        return self._walls.add(spec)

    def _move_mesh(self, spec: MotionSpec) -> str:
        return self._walls.move(spec, self._placings.crossing(spec.mesh))

    def mesh_force(self, name: str) -> np.ndarray:
        """See :meth:`.Walls.force`."""
        self._check_open()
        return self._walls.force(name)

    def _viscous(self, spec: ViscousSpec) -> str:
        label, lines = self.commands.viscous(spec)
        self._execute(lines)
        return label

    def _command(self, text: str) -> None:
        bad = control_characters(text)
        if bad:
            raise ConfigError(
                f"command {text!r} holds {', '.join(bad)}: LIGGGHTS takes one command a call, and the "
                "saved input would read a line break as a second one; call command() once per line"
            )
        self._channel.queue([text])
        self._channel.flush()  # now: the user expects its effect (and errors) at once

    def _remove(self, handle: Handle) -> None:
        if self._placings.remove(handle.label) or handle.label in self._fixless:
            self._fixless.discard(handle.label)
            return
        self._walls.remove(handle.label)
        self._fixes.remove(handle.label)
        self._targets.pop(handle.label, None)

    @property
    def _restart(self) -> RestartSpec:
        """The checkpoint settings, which restart files are written and read with."""
        return given(self.spec.restart, "restart=... (the checkpoint settings)")

    def _restart_name(self) -> str:
        """This step's LIGGGHTS restart file, named after the checkpoint's."""
        stem = Path(self._restart.fname.replace("*", "")).stem.rstrip(".")
        return f"{stem}.{self.step}.restart"

    def _state(self) -> dict[str, np.ndarray]:
        """LIGGGHTS writes its own restart file (atoms, fix states by id) beside the checkpoint."""
        self._execute([f"write_restart {self.commands.path(self._restart.directory / self._restart_name())}"])
        targets = {f"{TARGET_KEY}/{number}": np.array(value) for number, value in self._targets.values()}
        return {RESTART_KEY: encode_text(self._restart_name()), **targets}

    def _restore_state(self, state: dict[str, np.ndarray]) -> None:
        """LIGGGHTS has read its restart file already; the contacts of the resumed step are in
        the trajectory cut back, and LIGGGHTS writes them again as the next run starts, as it
        writes the mesh frame of that step again when one is due there (the index holds it)."""
        self._contacts_step = self.step
        if self.step % self.spec.traj.freq == 0:
            self._mesh_index.again(self.step, self.time)

    def _checkpoint_files(self) -> list[Path]:
        return [self._restart.directory / self._restart_name()]

    def _native_trajectories(self) -> dict[str, NativeTrajectory]:
        """LIGGGHTS writes ``.dump`` particles and ``.vtk`` meshes itself (see
        :func:`.native_particles`, :func:`.native_meshes`)."""
        found = {}
        if native_particles(self.spec):
            found["particles"] = NativeTrajectory(self._cut_dump)
        if native_meshes(self.spec):
            found["meshes"] = NativeTrajectory(self._cut_meshes, self._mesh_index.due)
        return found

    def _cut_dump(self, original: Path, path: Path, step: int) -> int:
        """Copy the frames of LIGGGHTS' ``.dump`` up to ``step``. LIGGGHTS writes the frame of
        that step again as its next run starts (a new dump writes the frame of the step it
        starts at): that frame is cut off then (see :meth:`_before_run`), and stays if nothing
        more runs (a finished study run again)."""
        from pygran_core.formats.dump import format_frame
        from pygran_core.io import open_trajectory

        kept = 0
        with path.open("wb") as out, open_trajectory(original) as old:
            for index in range(len(old)):
                frame = old[index]
                if frame.timestep is not None and frame.timestep > step:
                    break
                if frame.timestep == step:
                    self._rewritten_frame = out.tell()
                out.write(format_frame(frame, index).encode("ascii"))
                kept += 1
        return kept

    @staticmethod
    def _cut_meshes(original: Path, path: Path, step: int) -> int:
        """Copy the frames of LIGGGHTS' single ``.vtk`` of meshes before ``step``: LIGGGHTS
        writes the frame of that step again as its next run starts."""
        from pygran_core.io import open_trajectory, open_writer

        kept = 0
        with open_writer(path) as writer, open_trajectory(original) as old:
            for index in range(len(old)):
                frame = old[index]
                if frame.timestep is not None and frame.timestep >= step:
                    break
                writer.write_frame(frame)
                kept += 1
        return kept

    def _before_run(self) -> None:
        """Cut off the frame of the resumed step kept in LIGGGHTS' ``.dump``: the run about to
        start writes it again."""
        if self._rewritten_frame is not None and self.spec.traj.pfile is not None:
            os.truncate(self.spec.traj.pfile, self._rewritten_frame)
            self._rewritten_frame = None

    def _contact_frames(self) -> list[Frame]:
        """LIGGGHTS' dumps of the contacts, from the first run on, read on rank 0."""
        return self._written_contacts() if self._root else []

    def _written_contacts(self) -> list[Frame]:
        """The contact frames LIGGGHTS has written since the last call (the first run writes
        the frame of the step it starts at; see :func:`.read_contacts`), with ``id2 = -(k + 1)``
        for the mesh-wall contacts of the k-th wall set up."""
        walls = self._walls.contact_numbers()
        box, boundary = bounds(self.spec)
        frames = []
        for step, records in read_contacts(self.output / CONTACTS_DIR, walls, self._contacts_step, self.step):
            time = self._clock[1] + (step - self._clock[0]) * self.dt if self.dt is not None else None
            frames.append(
                Frame(
                    records, timestep=step, time=time, box=box, boundary=boundary, attrs={"kind": "contacts"}
                )
            )
            self._contacts_step = step
        return frames

    def _close(self) -> None:
        channel = getattr(self, "_channel", None)  # None if __init__ failed before it
        if channel is not None:
            channel.close()
