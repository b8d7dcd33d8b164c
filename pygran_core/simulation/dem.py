"""``simulation.DEM``: the engine-neutral front end of a DEM simulation (manual, chapter 4).

``DEM(**params)`` validates every keyword into a :class:`~.specs.SimulationSpec`, picks the
engine (``engine=``; by default ``native`` if installed, else the only installed engine),
and forwards each call, validated into its own spec, to that engine. Errors in the input
are :class:`~pygran_core.errors.ConfigError` raised before the solver sees anything.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from pygran_core import registry
from pygran_core.errors import ConfigError, PluginNotFound
from pygran_core.simulation import calls
from pygran_core.simulation.engine import Engine, Handle, LostParticles, Monitor
from pygran_core.simulation.engine_hooks import require_capability
from pygran_core.simulation.models import ContactModel
from pygran_core.simulation.specs import SimulationSpec, optional_bool, parse_simulation, step_count
from pygran_core.simulation.timestep import Assessment

DEFAULT_ENGINE = "native"
DEFAULT_MODEL = "SpringDashpot"


def resolve_engine(name: str | None) -> str:
    """The engine to use: ``name``, else ``native`` if installed, else the only one installed."""
    installed = registry.available("engine")
    if name is not None:
        if not isinstance(name, str):
            raise ConfigError(f"engine must be an engine's name such as 'native', got {name!r}")
        registry.lookup("engine", name)
        return name
    if DEFAULT_ENGINE in installed:
        return DEFAULT_ENGINE
    if len(installed) == 1:
        return next(iter(installed))
    if not installed:
        raise PluginNotFound(f"No DEM engine is installed. {registry.install_hint(DEFAULT_ENGINE)}")
    raise ConfigError(
        f"Several engines are installed ({', '.join(sorted(installed))}): choose one with engine=..."
    )


def resolve_model(model: Any) -> type[ContactModel]:
    """A contact model class from a class, a registered model name, or an instance (whose
    ``rolling`` and ``limitForce`` options are kept: :meth:`ContactModel.configure`)."""
    if isinstance(model, str):
        return registry.get_model(model).model
    if isinstance(model, type) and issubclass(model, ContactModel):
        return model
    if isinstance(model, ContactModel):
        return type(model).configure(rolling=model.rolling, limitForce=model.limit_force)
    raise ConfigError(
        "model must be a contact model class such as simulation.models.HertzMindlin, its name, "
        f"or an instance such as HertzMindlin(material, rolling='epsd2'); got {model!r}"
    )


def require(engine: str, capability: str, what: str) -> None:
    """Refuse, before the engine starts, what the installed engine ``engine`` lacks: the
    :class:`~pygran_core.errors.UnsupportedFeature` of :meth:`Engine.require`, naming the
    engines that can."""
    require_capability(engine, registry.get_engine(engine).capabilities, capability, what)


def required_capabilities(params: Mapping[str, Any]) -> list[tuple[str, str]]:
    """``(capability, what)`` that the forms of ``params`` need of an engine, read before any
    other check so that the answer does not depend on which other key is wrong."""
    needed = []
    species = params.get("species", ())
    for entry in (
        (species,) if isinstance(species, Mapping) else species if isinstance(species, Sequence) else ()
    ):
        if isinstance(entry, Mapping) and str(entry.get("style", "")).startswith("multisphere"):
            needed.append(("multisphere", "multisphere particles"))
    meshes = params.get("mesh")
    for entry in meshes.values() if isinstance(meshes, Mapping) else ():
        if isinstance(entry, Mapping) and entry.get("mtype") == "mesh/surface/stress/servo":
            needed.append(("servo-walls", "servo walls (mesh/surface/stress/servo)"))
    return needed


class AveragedMonitor:
    """What PyGran 1.x's ``monitor(var=..., nevery=, nrepeat=, nfreq=)`` returns: the
    LIGGGHTS ``fix ave/time`` averages (:class:`~.calls.AverageSpec`) of an engine monitor's
    samples, in :attr:`values` and in :attr:`path`, which is rewritten after every run."""

    def __init__(self, spec: calls.AverageSpec, samples: Monitor, path: Any, since: int) -> None:
        self.spec, self.samples, self.path, self.since = spec, samples, path, since
        path.parent.mkdir(parents=True, exist_ok=True)  # file="monitors/ke.dat"

    @property
    def values(self) -> dict[str, np.ndarray]:
        """``{'step': output steps, var: averages}``."""
        raw = self.samples.values
        steps, means = self.spec.average(raw["step"], raw[self.spec.quantity], self.since)
        return {"step": steps, self.spec.var: means}

    def write(self) -> None:
        """Write the averages as LIGGGHTS' ``fix ave/time ... file`` does."""
        values = self.values
        lines = [f"# Time-averaged data for fix {self.spec.name}", f"# TimeStep c_{self.spec.name}"]
        lines += [f"{step} {float(mean)!r}" for step, mean in zip(values["step"], values[self.spec.var])]
        self.path.write_text("\n".join(lines) + "\n")


class DEM:
    """A DEM simulation on one engine; a context manager that closes the engine.

    The keywords are those of the manual's chapter 4 (``box``, ``boundary``, ``gravity``,
    ``species``, ``mesh``, ``traj``, ``output``, ``restart``, ``dt``, ...), plus ``engine``,
    ``seed`` (every random choice derives from it), ``threads``/``nprocs`` and
    ``progress``. Other keys are the script's own (``'stages'``, ``'nsteps'``): kept in
    :attr:`pargs` with everything else given, and named once in ``pygran.log``. Every mesh
    is a wall from the start unless its entry says ``'import': False``. Each method returns
    what the engine created: a :class:`Handle` to pass to :meth:`remove`, a
    :class:`Monitor`, a count or an array.
    """

    def __init__(self, **params: Any) -> None:
        #: Every keyword given, the script's own keys included (PyGran 1.x's ``pargs``).
        self.pargs: dict[str, Any] = dict(params)
        engine_name = resolve_engine(params.pop("engine", None))
        for capability, what in required_capabilities(params):
            require(engine_name, capability, what)
        model = resolve_model(params.pop("model", DEFAULT_MODEL))
        self.spec: SimulationSpec = parse_simulation(params, engine_name, model)
        self._seeds = np.random.SeedSequence(self.spec.seed)
        factory = registry.get_engine(engine_name).factory
        self.engine: Engine = factory(self.spec)
        #: The wall of each mesh that is one, and the species it was made with.
        self._mesh_walls: dict[str, tuple[Handle, int]] = {}
        self._averages: dict[str, AveragedMonitor] = {}
        try:
            if self.spec.user_keys:
                self.engine.log(
                    "keys of the script's own, not simulation keywords (kept in DEM.pargs): %s",
                    ", ".join(map(repr, self.spec.user_keys)),
                )
            self._note(list(self.spec.notes))
            for mesh in self.spec.meshes:
                if mesh.wall:
                    self.setupWall(wtype="mesh", species=1, mesh=mesh.name)
        except BaseException:
            self.engine.close()
            raise

    def _note(self, notes: list[str]) -> None:
        """Log what parsing changed in what the script gave (step counts truncated)."""
        for note in notes:
            self.engine.log("%s", note)

    def _seed(self) -> int:
        """A fresh seed for one call, derived reproducibly from the simulation's ``seed``."""
        return int(self._seeds.spawn(1)[0].generate_state(1)[0])

    # -- particles ---------------------------------------------------------------------

    def insert(self, species: Any = "all", value: Any = None, **kwargs: Any) -> Handle:
        """Insert particles by pack or by rate into a region (manual 4.2.1); returns a handle.

        ``value`` particles ``particles_in_region`` come on top of those in the region now
        (two species inserted one after the other into one region give both), as PyGran 1.x
        did; see :class:`~.calls.InsertSpec` for when insertions happen."""
        request = {"species": species, **kwargs} | ({} if value is None else {"value": value})
        notes: list[str] = []
        spec = calls.parse_insert(request, self.spec, self._seed(), notes)
        if spec.mechanism == "by_pack" and spec.target == "particles_in_region":
            present = int(np.count_nonzero(spec.region.contains(self.engine.extract("x").reshape(-1, 3))))
            if present:
                spec = replace(spec, value=spec.value + present)
                notes.append(f"insert {spec.requested:g} particles on top of the {present} in the region")
        handle = self.engine.insert(spec)
        self._note(notes)
        return handle

    def createParticles(self, species: Any, style: str, *args: Any, **kwargs: Any) -> int:
        """Create particles now: ``'single'`` at x, y, z (or one per row of an ``(N, 3)`` array
        of positions, or an ``(N, 4)`` array ``radius x y z`` or a ``read_spheres`` table: each
        radius to the species of that radius); ``'lattice'`` or ``'random'`` in a region.
        Returns how many were created."""
        if style == "single" and calls.sphere_rows(args) is not None:
            requests = calls.parse_create_rows(species, args, kwargs, self.spec, self._seed())
            return sum(self.engine.create_particles(request) for request in requests)
        return self.engine.create_particles(
            calls.parse_create(species, style, args, kwargs, self.spec, self._seed())
        )

    def set(self, **kwargs: Any) -> int:
        """Assign ``vel=(vx, vy, vz)``, ``omega=(wx, wy, wz)`` and/or ``radius=r`` to the particles
        of ``species``, inside ``region`` and/or with ``ids`` (none of them: every particle).
        Returns how many particles changed."""
        return self.engine.set_properties(calls.parse_set(kwargs, self.spec))

    def velocity(self, **kwargs: Any) -> int:
        """:meth:`set` for velocities: ``vel=`` and/or ``omega=`` (no ``radius``)."""
        if "radius" in kwargs:
            raise ConfigError("velocity() assigns vel and omega; use set(radius=...) for radii")
        return self.set(**kwargs)

    # -- walls and meshes ----------------------------------------------------------------

    def setupWall(
        self,
        wtype: str = "primitive",
        species: Any = 1,
        plane: str | None = None,
        peq: float | None = None,
        **kwargs: Any,
    ) -> Handle:
        """A primitive wall (``plane='zplane', peq=0``, or a cylinder) or a mesh wall. A mesh
        that is a wall already gives its wall's handle (made anew for another species when
        the mesh has no material of its own)."""
        request = {"wtype": wtype, "species": species, "plane": plane, "peq": peq, **kwargs}
        spec = calls.parse_wall(request, self.spec)
        if spec.kind == "mesh" and spec.mesh in self._mesh_walls:
            handle, made_with = self._mesh_walls[spec.mesh]
            mesh = next(m for m in self.spec.meshes if m.name == spec.mesh)
            if handle in self.engine.handles:
                if mesh.material or made_with == spec.species:
                    self.engine.log("mesh %r is a wall already: its handle is returned", spec.mesh)
                    return handle
                self.engine.remove(handle)
        handle = self.engine.setup_wall(spec)
        if spec.mesh is not None:
            self._mesh_walls[spec.mesh] = (handle, spec.species)
        return handle

    def moveMesh(self, name: str, *args: Any, **kwargs: Any) -> Handle:
        """Move mesh ``name`` as LIGGGHTS' ``move/mesh`` styles (see :class:`~.calls.MotionSpec`):
        ``rotate=('origin', x, y, z), axis=..., period=...`` (or ``rotate=True`` with
        ``origin``, ``axis``, ``period`` or ``omega``), ``linear=(vx, vy, vz)``,
        ``wiggle=('amplitude', ax, ay, az), period=...``, ``viblin=('axis', ax, ay, az),
        order=n, amplitude=..., phase=..., period=...`` or ``vibrot=('origin', ...)`` likewise;
        or PyGran 1.x's ``moveMesh(name, *args)`` with LIGGGHTS' words, style first:
        ``moveMesh('wall', 'viblin', 'axis 0 0 1', 'order 1', 'amplitude 1e-5', ...)``."""
        if args:
            if kwargs:
                raise ConfigError(
                    "moveMesh takes LIGGGHTS' words (name, *args) or keywords, not both: "
                    f"got {args!r} and {sorted(kwargs)}"
                )
            kwargs = calls.positional_motion(args)
        spec = calls.parse_motion(name, kwargs, self.spec)
        if spec.kind in ("viblin", "vibrot"):
            self.engine.require("mesh-vibration", f"{spec.kind} mesh motion")
        return self.engine.move_mesh(spec)

    # -- forces, monitors, raw commands ---------------------------------------------------

    def addViscous(self, **kwargs: Any) -> Handle:
        """A drag force ``-gamma * scale * v`` on ``species`` (default all)."""
        return self.engine.add_viscous(calls.parse_viscous(kwargs, self.spec))

    add_viscous = addViscous

    def monitor(self, **kwargs: Any) -> Monitor | AveragedMonitor:
        """Sample ``quantities`` (``ke``, ``n``, ...) every ``freq`` steps into ``file`` and memory;
        or, PyGran 1.x's form, ``monitor(var='ke', species='all', name=..., file=...,
        nevery=..., nrepeat=..., nfreq=...)``: LIGGGHTS' time averages (:class:`AveragedMonitor`)."""
        notes: list[str] = []
        if not any(key in kwargs for key in calls.AVERAGE_KEYS if key not in ("name", "file")):
            monitor = self.engine.monitor(calls.parse_monitor(kwargs, notes))
            self._note(notes)
            return monitor
        spec = calls.parse_average(kwargs, self.spec, notes)
        every_species = set(spec.species) == {s.type for s in self.spec.species}
        if not every_species:
            self.engine.require("monitor-species", "monitors of some species only")
        if spec.name in self._averages:
            raise ConfigError(f"monitor name {spec.name!r} is taken: give each monitor its own name=")
        averaged = AveragedMonitor(
            spec, self.engine.monitor(spec.samples(every_species)), self.engine.output / spec.file, self.step
        )
        self._averages[spec.name] = averaged
        self._note(notes)
        return averaged

    def command(self, text: str) -> None:
        """Pass a solver-native command through (engines with ``raw-commands``)."""
        self.engine.command(text)

    # -- running and results ------------------------------------------------------------------

    def run(
        self, nsteps: float, dt: float | None = None, *, progress: bool | None = None, check_dt: bool = True
    ) -> None:
        """Advance ``nsteps`` steps of ``dt`` (default: the ``dt`` given to DEM). A float
        ``nsteps`` (``1e5``, ``nsteps / 3``) is truncated to whole steps as LIGGGHTS does.
        ``check_dt=False`` runs a time step too long for the contacts anyway (see
        :meth:`Engine.run`)."""
        notes: list[str] = []
        steps = step_count(nsteps, "run nsteps", notes)
        self._note(notes)
        try:
            self.engine.run(
                steps,
                dt,
                progress=optional_bool(progress, "run progress"),
                check_dt=bool(optional_bool(check_dt, "run check_dt", allow_none=False)),
            )
        finally:
            for averaged in self._averages.values():
                averaged.write()

    def expect_outflow(self, *faces: str) -> None:
        """Declare the faces of the box particles leave through (``"z-"``, ...): their loss is
        logged, not warned (see :meth:`Engine.expect_outflow`)."""
        self.engine.expect_outflow(*faces)

    def remove(self, handle: Handle | Monitor | AveragedMonitor | str) -> None:
        """Remove an insertion, wall, mesh motion, force or monitor; a mesh's name removes
        its wall (PyGran 1.x's ``remove('hopper')``)."""
        if isinstance(handle, AveragedMonitor):
            if self._averages.get(handle.spec.name) is not handle:
                raise ConfigError(f"monitor {handle.spec.name!r} was already removed")
            del self._averages[handle.spec.name]
            handle = handle.samples
        if isinstance(handle, str):
            wall = self._mesh_walls.get(handle)
            if wall is None or wall[0] not in self.engine.handles:
                names = [m.name for m in self.spec.meshes]
                raise ConfigError(
                    f"remove({handle!r}): no mesh wall of that name; meshes: {', '.join(names) or 'none'}"
                )
            handle = wall[0]
        self.engine.remove(handle)

    def extractCoords(self) -> np.ndarray:
        """Positions, (N, 3), ordered by particle id."""
        return self.engine.extract("x")

    def extractVelocities(self) -> np.ndarray:
        return self.engine.extract("v")

    def extractOmegas(self) -> np.ndarray:
        return self.engine.extract("omega")

    def extractForces(self) -> np.ndarray:
        return self.engine.extract("f")

    def extractRadii(self) -> np.ndarray:
        return self.engine.extract("radius")

    def extractIds(self) -> np.ndarray:
        return self.engine.extract("id")

    @property
    def output(self) -> Any:
        """The output directory (absolute): this run's with ``nSim > 1``."""
        return self.engine.output

    @property
    def step(self) -> int:
        return self.engine.step

    @property
    def time(self) -> float:
        return self.engine.time

    @property
    def lost(self) -> int:
        """Particles lost in all runs so far (left the box, became non-finite, were deleted)."""
        return self.engine.lost

    @property
    def last_lost(self) -> LostParticles:
        """The particles lost in the last run: count, where, largest speed."""
        return self.engine.last_lost

    @property
    def time_step_check(self) -> Assessment | None:
        """The last run's time step against the contacts present (``None``: none possible)."""
        return self.engine.time_step_check

    def close(self) -> None:
        """Finish the output files and release the engine."""
        self.engine.close()

    def __enter__(self) -> DEM:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        spec = self.spec
        return f"DEM(engine={spec.engine!r}, model={spec.model.__name__}, output={str(spec.output)!r})"
