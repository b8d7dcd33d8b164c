"""The LIGGGHTS engine: PyGran's specs as LIGGGHTS commands, run in a worker or under mpirun.

From a plain ``python`` process, LIGGGHTS runs in a worker job (``nprocs`` MPI ranks) that
may die on a LIGGGHTS error without taking the user's session with it: the error becomes an
:class:`EngineError` with LIGGGHTS' message, and a new simulation can be started. When the
script itself runs under ``mpirun`` (the manual's mode), each rank loads LIGGGHTS in
process; ``nSim=k`` then splits ``COMM_WORLD`` into k groups, each running its own
simulation (there, a LIGGGHTS error ends the MPI job, as LIGGGHTS calls ``exit``).

Every command sent is appended to ``<output>/in.pygran``, which reruns unchanged with the
``liggghts`` binary; LIGGGHTS' screen output goes to ``<output>/liggghts.log``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pygran_core.errors import ConfigError, EngineError, UnsupportedFeature
from pygran_core.simulation.engine import Engine
from pygran_liggghts.commands import Commands, fmt, native_meshes, native_particles
from pygran_liggghts.session import LocalSession, WorkerSession, under_mpirun

if TYPE_CHECKING:
    from pygran_core.simulation.calls import (
        CreateSpec,
        InsertSpec,
        MotionSpec,
        SetSpec,
        ViscousSpec,
        WallSpec,
    )
    from pygran_core.simulation.engine import Handle
    from pygran_core.simulation.specs import SimulationSpec

INPUT_NAME = "in.pygran"
LOG_NAME = "liggghts.log"
WORKER_LOG_NAME = "worker.log"


def mpi_placement(spec: SimulationSpec) -> tuple[Any, SimulationSpec]:
    """Under ``mpirun``: this rank's communicator and simulation (one of ``nSim`` runs)."""
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    if world.size < spec.nsim:
        raise ConfigError(f"nSim={spec.nsim} needs at least {spec.nsim} MPI ranks; got {world.size}")
    if spec.nsim == 1:
        return world, spec
    group = world.rank * spec.nsim // world.size
    return world.Split(group, world.rank), spec.runs[group]


class LiggghtsEngine(Engine):
    """A simulation on LIGGGHTS 3.x (``libliggghts``), see the module docstring."""

    name = "liggghts"
    capabilities = frozenset(
        {
            "mesh-walls",
            "moving-mesh",
            "primitive-walls",
            "periodic",
            "polydisperse",
            "spring-dashpot",
            "hertz-mindlin",
            "cohesion",
            "rolling-friction",
            "insert-by-rate",
            "mpi",
            "restart",
            "raw-commands",
        }
    )
    #: Each run chunk is a LIGGGHTS ``run``; few chunks keep the overhead negligible.
    max_run_chunks = 10

    def __init__(self, spec: SimulationSpec) -> None:
        comm = None
        if under_mpirun():
            comm, spec = mpi_placement(spec)
        elif spec.nsim > 1:
            raise ConfigError(
                f"nSim={spec.nsim} runs one simulation per group of ranks: start the script "
                f"with mpirun -np {spec.nsim} (or more)"
            )
        super().__init__(spec)
        self._failure: EngineError | None = None
        self._session: Any = None
        try:
            if spec.traj.mfile is not None and spec.meshes and spec.traj.mfile.suffix != ".vtk":
                raise ConfigError(f"LIGGGHTS writes meshes as .vtk files, not {spec.traj.mfile.name}")
            if comm is not None and spec.nprocs not in (None, comm.size):
                raise ConfigError(f"nprocs={spec.nprocs} differs from the {comm.size} MPI ranks of this run")
            self.commands = Commands(spec)
            resume = self._resume_file()
            self._root = comm is None or comm.rank == 0
            self._input = (self.output / INPUT_NAME).open("w") if self._root else None
            args = ["-screen", str(self.output / LOG_NAME), "-log", "none"]
            if comm is not None:
                self._session = LocalSession(args, comm)
            else:
                self._session = WorkerSession(
                    args, spec.nprocs or 1, self.output / LOG_NAME, self.output / WORKER_LOG_NAME
                )
            self._prepared = False
            self._pending: list[str] = []
            self._timestep = spec.dt
            self._execute(self.commands.setup(resume))
            if resume is not None:
                self.step = self._request("timestep")
                self.time = self.step * (self.dt or 0.0)
                self.log("resumed from %s at step %d", resume, self.step)
        except BaseException:
            self.close()
            raise

    # -- talking to LIGGGHTS ---------------------------------------------------------------

    def _request(self, name: str, *params: Any) -> Any:
        if name != "execute" and self._pending:
            self._execute([])
        if self._failure is not None:
            raise EngineError(f"This LIGGGHTS simulation stopped after an error: {self._failure}")
        try:
            return self._session.request(name, *params)
        except EngineError as exc:
            self._failure = exc
            self.log("%s", exc)
            raise

    def _execute(self, lines: list[str]) -> None:
        """Run the pending lines and ``lines`` in LIGGGHTS, and record them in ``in.pygran``."""
        lines, self._pending = [*self._pending, *lines], []
        if self._input is not None:
            self._input.write("".join(line + "\n" for line in lines))
            self._input.flush()
        self._prepared = False
        self._max_id = self._request("execute", lines)

    def _resume_file(self) -> Path | None:
        restart = self.spec.restart
        if restart is None or not restart.resume:
            return None
        if restart.lastfile is not None:
            if not restart.lastfile.is_file():
                raise ConfigError(f"restart lastfile {restart.lastfile} does not exist")
            return restart.lastfile
        files = sorted(
            restart.directory.glob("*.restart"),
            key=lambda p: int(m.group(1)) if (m := re.search(r"\.(\d+)\.restart$", p.name)) else -1,
        )
        if not files:
            raise ConfigError(f"restart resume=True but {restart.directory} holds no .restart file")
        return files[-1]

    # -- engine hooks ------------------------------------------------------------------------

    def _advance(self, nsteps: int) -> None:
        lines = []
        if self.dt != self._timestep:
            lines.append(f"timestep {fmt(self.dt)}")
            self._timestep = self.dt
        # pre no: nothing changed since the last run, so LIGGGHTS may skip its setup
        pre = "pre no " if self._prepared and not lines and not self._pending else ""
        self._execute([*lines, f"run {nsteps} {pre}post no"])
        self._prepared = True

    def _extract(self, quantity: str) -> np.ndarray:
        return self._request("gather", [quantity])[quantity]

    def _scalar(self, quantity: str) -> float:
        if quantity == "ke_rot":
            arrays = self._request("gather", ["omega", "radius", "mass"])
            inertia = 0.4 * arrays["mass"] * arrays["radius"] ** 2
            return float(0.5 * np.sum(inertia * np.einsum("ij,ij->i", arrays["omega"], arrays["omega"])))
        if quantity == "n":
            return float(self._request("natoms"))
        return super()._scalar(quantity)

    def _insert(self, spec: InsertSpec) -> str:
        label, lines = self.commands.insert(spec, self.dt)
        self._execute(lines)
        return label

    def _create(self, spec: CreateSpec) -> int:
        if any(spec.omega):
            raise UnsupportedFeature(
                "LIGGGHTS cannot set the angular velocity of created particles; "
                "use insert(..., omega=...) instead"
            )
        if spec.style == "random":
            raise UnsupportedFeature(
                "The liggghts engine does not implement createParticles 'random' "
                "(LIGGGHTS' create_atoms random lets particles overlap); use insert()"
            )
        species = self.spec.species[spec.species - 1]
        first = self._max_id + 1
        if spec.style == "single":
            lines = [
                f"create_atoms {spec.species} single {' '.join(fmt(v) for v in spec.position)} units box"
            ]
            box = np.array(self.spec.domain.box)
            if np.all((box[:, 0] < spec.position) & (spec.position < box[:, 1])):
                # inside the box LIGGGHTS gives it the next id: no round trip needed
                self._pending += lines
                self._max_id = first
            else:
                self._execute(lines)
        else:
            rid, region = self.commands.region(spec.region)
            self._execute(
                [f"lattice sc {fmt(spec.spacing)}", region, f"create_atoms {spec.species} region {rid}"]
            )
        last = self._max_id
        count = max(0, last - first + 1)
        if count == 0:
            return 0
        atoms = f"{first}*{last}" if count > 1 else str(first)
        if spec.radius is not None or species.radius.kind == "constant":
            radius = spec.radius if spec.radius is not None else species.radius.values[0]
            lines = [f"set atom {atoms} diameter {fmt(2 * radius)}"]
        else:
            radii = species.radius.sample(count, np.random.default_rng(spec.seed))
            lines = [f"set atom {first + i} diameter {fmt(2 * r)}" for i, r in enumerate(radii)]
        lines.append(f"set atom {atoms} density {fmt(species.density)}")
        if any(spec.velocity):
            vx, vy, vz = (fmt(v) for v in spec.velocity)
            lines.append(f"set atom {atoms} vx {vx} vy {vy} vz {vz}")
        self._pending += lines  # sent with the next request
        return count

    def _assign(self, ids: np.ndarray, spec: SetSpec) -> None:
        if spec.omega is not None:
            raise UnsupportedFeature("LIGGGHTS 3.8 rejects setting angular velocities (set ... omega)")
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

    def _wall(self, spec: WallSpec) -> str:
        label, lines = self.commands.wall(spec)
        self._execute(lines)
        return label

    def _move_mesh(self, spec: MotionSpec) -> str:
        label, lines = self.commands.motion(spec)
        self._execute(lines)
        return label

    def _viscous(self, spec: ViscousSpec) -> str:
        label, lines = self.commands.viscous(spec)
        self._execute(lines)
        return label

    def _command(self, text: str) -> None:
        self._execute([text])

    def _remove(self, handle: Handle) -> None:
        self._execute([f"unfix {handle.label}"])

    def _checkpoint(self, path: Any) -> None:
        name = Path(path)
        self._execute([f"write_restart {name.with_name(f'{name.stem}.{self.step}.restart')}"])

    def _write(self, key: str, path: Any, make_frame: Any) -> None:
        # .dump particles and .vtk meshes are written by LIGGGHTS' own dump commands
        native = native_particles(self.spec) if key == "particles" else native_meshes(self.spec)
        if native:
            return
        if self._root:
            super()._write(key, path, make_frame)
        else:
            make_frame()  # gathering is collective: every rank takes part

    def _close(self) -> None:
        try:
            if self._session is not None and self._failure is None:
                if self._pending:
                    self._execute([])
                self._session.close()
        finally:
            if getattr(self, "_input", None) is not None:
                self._input.close()
