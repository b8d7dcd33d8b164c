"""``DEM(engine='native')``: maps the engine-neutral specs onto the compiled :class:`Solver`.

Material types: species ``k`` (1-based) is solver type ``k - 1``; a mesh with a material
of its own gets a type after the species. Particle ids are 1-based as in LIGGGHTS.
Insertion (``insert``, ``createParticles``) is the engine's
:class:`~pygran_core.simulation.insertion.Inserter`'s, seeded per call from ``seed``.

Multisphere species are the solver's clumps (:meth:`Solver.add_clumps`), one per particle,
inserted and created as the :class:`~pygran_core.simulation.insertion.Inserter` places and
counts clumps. As on LIGGGHTS and YADE, extracts give every sphere of a clump, each with the
clump's mass, and :meth:`NativeEngine.bodies` the clump of each sphere.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError, ReadError, UnsupportedFeature
from pygran_core.formats import contacts as contact_schema
from pygran_core.simulation.calls import MotionSpec, SetSpec, ViscousSpec, WallSpec
from pygran_core.simulation.engine import Engine, Handle, LostParticles
from pygran_core.simulation.insertion import Inserter, multisphere_templates
from pygran_core.simulation.mpi import rank_run
from pygran_core.simulation.specs import SimulationSpec, given
from pygran_native.solver import Solver

#: Contact-model kernel (``ContactModel.kernel``) -> the solver's force law.
SOLVER_LAW = {"spring-dashpot": "hooke", "hertz-mindlin": "hertz", "thornton-ning": "thornton-ning"}


class NativeEngine(Engine):
    """PyGran's own DEM engine (a compiled Cython solver on its own thread team)."""

    name = "native"
    capabilities = frozenset(
        {
            "spring-dashpot",
            "hertz-mindlin",
            "thornton-ning",
            "cohesion",
            "rolling-friction",
            "rolling-epsd",
            "rolling-epsd2",
            "limit-force",
            "periodic",
            "primitive-walls",
            "mesh-walls",
            "moving-mesh",
            "mesh-vibration",
            "monitor-species",
            "servo-walls",
            "polydisperse",
            "pair-tables",
            "insert-by-rate",
            "threads",
            "restart",
            "multisphere",
            "contact-output",
        }
    )

    def __init__(self, spec: SimulationSpec) -> None:
        if spec.nsim > 1:  # each MPI rank makes its own run, on its own threads
            spec = rank_run(spec.runs, spec.engine)
        super().__init__(spec)  # refuses a model whose kernel is not among the capabilities
        try:
            self.inserter = Inserter(self)
            self._templates = multisphere_templates(spec)
            self._law = SOLVER_LAW[given(spec.model.kernel, f"the {spec.model.__name__} model's kernel")]
            gravity = spec.gravity.vector if spec.gravity is not None else np.zeros(3)
            self.solver = Solver(
                np.array(spec.domain.box).T, spec.domain.periodic, gravity, spec.skin, spec.threads, spec.seed
            )
            self._mesh_types = dict(self.material_table.mesh_types)
            self.solver.set_contact_model(self._law, **self._material_arrays())
            # each contact's force kept (24 bytes) only for the contacts' trajectory
            self.solver.record_contacts = spec.traj.cfile is not None
            self._walls: dict[str, int] = {}
            #: Solver wall handle -> the wall's index in the order walls were set up (removed ones
            #: kept): contact records name the wall by it (see :meth:`_contacts`)
            self._wall_index: dict[int, int] = {}
            self._mesh_walls: dict[str, int] = {}
            self._motions: dict[str, str] = {}
            self._drags: dict[str, ViscousSpec] = {}
            self._labels = 0
            self.log("native solver: %d threads, neighbour skin %g m", self.solver.threads, spec.skin)
        except BaseException:
            self._abandon()
            raise

    def _material_arrays(self) -> dict[str, Any]:
        """The solver's contact-model arguments: the material table's entries renamed."""
        table = self.material_table
        arrays: dict[str, Any] = {
            "youngs": table.per_type["youngsModulus"],
            "poisson": table.per_type["poissonsRatio"],
            "friction": table.pairs["coefficientFriction"],
            "rolling_friction": table.pairs["coefficientRollingFriction"],
            "cohesion_energy": table.pairs["cohesionEnergyDensity"],
        }
        # rolling resistance models other than the solver's are refused when a species has rolling
        # friction (Engine._check_spec); without, no pair has any and the model does not matter
        rolling = self.spec.model.rolling
        arrays["rolling"] = rolling if rolling in ("epsd", "epsd2") else "cdt"
        arrays["limit_force"] = self.spec.model.limit_force
        if arrays["rolling"] == "epsd":
            arrays["rolling_damping"] = table.pairs["coefficientRollingViscousDamping"]
        if self._law == "thornton-ning":
            arrays["yield_pressure"] = table.pairs["yieldPress"].diagonal().copy()
        else:
            arrays["restitution"] = table.pairs["coefficientRestitution"]
        if self._law == "hooke":
            arrays["characteristic_velocity"] = float(table.per_type["characteristicVelocity"].max())
        return arrays

    def _label(self, kind: str) -> str:
        self._labels += 1
        return f"{kind}{self._labels}"

    # -- particles ---------------------------------------------------------------------

    def _add_spheres(
        self, species: np.ndarray, centres: np.ndarray, radii: np.ndarray, velocities: np.ndarray, omega: Any
    ) -> None:
        density = np.array([0.0, *(s.density for s in self.spec.species)])  # by species number
        self.solver.add_particles(
            centres,
            radii,
            densities=density[species],
            types=np.asarray(species, np.int32) - 1,
            velocities=velocities,
            omegas=omega,
        )

    def _add_clumps(
        self,
        species: int,
        origins: np.ndarray,
        orientations: np.ndarray,
        velocities: np.ndarray,
        omega: Sequence[float],
    ) -> None:
        self.solver.add_clumps(
            self._templates[species],
            origins,
            self.spec.species[species - 1].density,
            orientations=orientations,
            types=species - 1,
            velocities=velocities,
            omegas=np.tile(np.asarray(omega, float), (len(origins), 1)),
        )

    def bodies(self) -> np.ndarray:
        """The clump of each sphere, ordered by id as :meth:`extract`: the clump's id (1, 2, ...)
        for the spheres of multisphere particles, -1 for single spheres (as the LIGGGHTS
        engine's ``bodies()``; extracts give every sphere of a clump)."""
        self._check_open()
        body = self.solver.bodies
        return np.where(body >= 0, body + 1, -1)

    def clumps(self) -> dict[str, np.ndarray]:
        """Every clump's ``id`` (as :meth:`bodies`), ``mass``, ``centre``, ``inertia`` tensor about
        its centre in the world frame ``(n, 3, 3)``, and its motion (see :meth:`Solver.clumps`)."""
        self._check_open()
        found = self.solver.clumps()
        found["id"] = found["id"] + 1
        return found

    def _assign(self, ids: np.ndarray, spec: SetSpec) -> None:
        solver_ids = np.asarray(ids) - 1  # the solver counts from 0
        if self._templates:
            types = self.solver.types[np.isin(self.solver.ids, solver_ids)] + 1
            bodies = sorted(set(types.tolist()) & set(self._templates))
            if bodies:
                raise UnsupportedFeature(
                    f"set() on the spheres of multisphere species {bodies}: they move with their clumps; "
                    "select the species of single spheres (species=...)"
                )
        if spec.velocity is not None:
            self.solver.set_velocities(solver_ids, np.tile(spec.velocity, (len(solver_ids), 1)))
        if spec.omega is not None:
            self.solver.set_omegas(solver_ids, np.tile(spec.omega, (len(solver_ids), 1)))
        if spec.radius is not None:
            self.solver.set_radii(solver_ids, spec.radius)

    # -- walls and meshes ----------------------------------------------------------------

    def _wall(self, spec: WallSpec) -> str:
        label = self._label("wall")
        if spec.kind == "plane":
            axis = "xyz".index(given(spec.plane, "a plane wall's plane")[0])
            peq = given(spec.peq, "a plane wall's position peq")
            lo, hi = self.spec.domain.box[axis]
            normal = np.zeros(3)
            normal[axis] = 1.0 if peq - lo <= hi - peq else -1.0
            point = np.zeros(3)
            point[axis] = peq
            self._walls[label] = self.solver.add_plane(point, normal, spec.species - 1)
        elif spec.kind == "cylinder":
            self._walls[label] = self.solver.add_cylinder(
                given(spec.axis, "a cylinder wall's axis"),
                given(spec.centre, "a cylinder wall's centre"),
                given(spec.radius, "a cylinder wall's radius"),
                spec.species - 1,
            )
        else:
            mesh = next(m for m in self.spec.meshes if m.name == spec.mesh)
            if mesh.name in self._mesh_walls:
                raise ConfigError(f"mesh {mesh.name!r} is already a wall")
            triangles = mesh.triangles()
            wall_type = self._mesh_types[mesh.name] if mesh.material else spec.species - 1
            wall = self.solver.add_mesh(
                triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3), wall_type
            )
            servo = mesh.servo
            if servo is not None:
                self.solver.set_servo(
                    wall,
                    control=servo.control,
                    axis=servo.axis,
                    target=servo.target,
                    vel_max=servo.vel_max,
                    com=servo.com,
                    kp=servo.kp,
                    ki=servo.ki,
                    kd=servo.kd,
                    mode=servo.mode,
                    ratio=servo.ratio,
                )
            elif mesh.mtype != "mesh/surface":
                self.solver.set_stress(wall)
            self._mesh_walls[mesh.name] = self._walls[label] = wall
        self._wall_index[self._walls[label]] = len(self._wall_index)
        return label

    def _move_mesh(self, spec: MotionSpec) -> str:
        if spec.mesh not in self._mesh_walls:
            raise ConfigError(
                f"mesh {spec.mesh!r} is not a wall yet: "
                f"call setupWall(wtype='mesh', mesh={spec.mesh!r}) first"
            )
        if any(mesh.servo for mesh in self.spec.meshes if mesh.name == spec.mesh):
            raise ConfigError(
                f"mesh {spec.mesh!r} is a servo wall, which its controller moves: it cannot be moved "
                "by moveMesh too (as on LIGGGHTS)"
            )
        if spec.mesh in self._motions.values():
            raise ConfigError(f"mesh {spec.mesh!r} already moves; remove() that motion first")
        wall = self._mesh_walls[spec.mesh]
        if spec.kind == "rotate":
            self.solver.set_mesh_motion(
                wall, angular_velocity=spec.omega * np.asarray(spec.axis), origin=spec.origin
            )
        elif spec.kind == "wiggle":
            self.solver.set_mesh_motion(wall, amplitude=spec.amplitude, period=spec.period)
        elif spec.kind in ("viblin", "vibrot"):
            self.solver.set_mesh_vibration(
                wall, spec.kind, spec.axis, spec.amplitudes, spec.phases, spec.periods, spec.origin
            )
        else:
            self.solver.set_mesh_motion(wall, velocity=spec.velocity)
        label = self._label("motion")
        self._motions[label] = spec.mesh
        return label

    def _viscous(self, spec: ViscousSpec) -> str:
        label = self._label("viscous")
        self._drags[label] = spec
        self._apply_viscous()
        return label

    def _apply_viscous(self) -> None:
        gamma = np.zeros(self.solver.ntypes)
        for spec in self._drags.values():
            for s in spec.species:
                gamma[s - 1] += spec.gamma * spec.scale
        self.solver.set_viscous(gamma)

    def _remove(self, handle: Handle) -> None:
        label = handle.label
        if label in self._walls:
            wall = self._walls.pop(label)
            self.solver.remove_wall(wall)
            for name in [n for n, w in self._mesh_walls.items() if w == wall]:
                del self._mesh_walls[name]
        elif label in self._motions:
            mesh = self._motions.pop(label)
            if mesh in self._mesh_walls:
                self.solver.set_mesh_motion(self._mesh_walls[mesh])
        elif label in self._drags:
            del self._drags[label]
            self._apply_viscous()

    # -- running and output ----------------------------------------------------------------

    def _advance(self, nsteps: int) -> None:
        self.solver.run(nsteps, given(self.dt, "the time step"))  # run() refuses to start without one

    def mesh_force(self, name: str) -> np.ndarray:
        """The force (N, x y z) the particles exert on mesh ``name`` at the last step (``mtype``
        ``mesh/surface/stress`` or ``mesh/surface/stress/servo``), as on LIGGGHTS."""
        mesh = next((m for m in self.spec.meshes if m.name == name), None)
        if mesh is None or mesh.mtype == "mesh/surface" or name not in self._mesh_walls:
            stress = [m.name for m in self.spec.meshes if m.mtype != "mesh/surface"]
            raise ConfigError(
                f"mesh_force({name!r}): the force is summed on walls of mtype mesh/surface/stress or "
                f"mesh/surface/stress/servo; such meshes here: {stress or 'none'}"
            )
        return self.solver.mesh_force(self._mesh_walls[name])[0]

    def _extract(self, quantity: str) -> np.ndarray:
        solver = self.solver
        if quantity == "id":
            return solver.ids + 1
        if quantity == "type":
            return solver.types.astype(np.int64) + 1
        extract = {  # only the one asked for
            "x": lambda: solver.positions,
            "v": lambda: solver.velocities,
            "omega": lambda: solver.omegas,
            "f": lambda: solver.forces,
            "torque": lambda: solver.torques,
            "radius": lambda: solver.radii,
            "mass": lambda: solver.masses,
        }
        return extract[quantity]()

    def _contacts(self) -> dict[str, np.ndarray]:
        """The contacts of the last step (:meth:`Solver.contact_forces`) with the engine's ids:
        particles from 1, the k-th wall set up as ``-(k + 1)``; none before the first step."""
        if self.step == 0:
            return contact_schema.empty()
        found = self.solver.contact_forces()
        id2, wall = found["id2"], found["id2"] < 0
        index = np.zeros(max(self._wall_index, default=-1) + 1, np.int64)  # solver handle -> k
        index[list(self._wall_index)] = list(self._wall_index.values())
        id2[~wall] += 1
        id2[wall] = contact_schema.wall_id(index[-id2[wall] - 1])
        found["id1"] += 1
        return found

    def _state(self) -> dict[str, np.ndarray]:
        return {f"solver/{k}": v for k, v in self.solver.get_state().items()}

    def _restore_state(self, state: dict[str, np.ndarray]) -> None:
        try:
            self.solver.set_state(
                {k[len("solver/") :]: v for k, v in state.items() if k.startswith("solver/")}
            )
        except ReadError as exc:
            raise ReadError(f"{self.journal.path}: {exc}") from None

    def _lost_since_last(self) -> LostParticles:
        """The particles the solver deleted since the last call: by the face of the box they
        were beyond, or non-finite, and the largest speed of the first (see Solver.take_lost)."""
        where, speed = self.solver.take_lost()
        return LostParticles(sum(where.values()), where, speed)

    def _facts(self) -> dict[str, Any]:
        return {"threads": self.solver.threads}

    def _scalar(self, quantity: str) -> float:
        if quantity == "ke" and self._templates:  # a clump's energy is its own, not its spheres'
            return self.solver.kinetic_energy()[0]
        if quantity == "ke_rot":
            return self.solver.kinetic_energy()[1]
        if quantity == "contacts":
            return float(len(self.solver.contacts()[0]))
        return super()._scalar(quantity)

    def _species_scalar(self, quantity: str, species: tuple[int, ...]) -> float:
        """As :meth:`Engine._species_scalar`; with multisphere species, energies are the clumps'
        own (not their spheres')."""
        if quantity in ("ke", "ke_rot") and self._templates:
            return self.solver.kinetic_energy([k - 1 for k in species])[quantity == "ke_rot"]
        return super()._species_scalar(quantity, species)

    def _mesh_triangles(self, name: str) -> np.ndarray | None:
        return self.solver.mesh_triangles(self._mesh_walls[name]) if name in self._mesh_walls else None
