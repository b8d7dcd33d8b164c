"""``DEM(engine='native')``: maps the engine-neutral specs onto the compiled :class:`Solver`.

Material types: species ``k`` (1-based) is solver type ``k - 1``; a mesh with a material
of its own gets a type after the species. Particle ids are 1-based as in LIGGGHTS.
Insertion (``insert``, ``createParticles``) places spheres with
:func:`pygran_core.simulation.insertion.place_spheres`, seeded per call from ``seed``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError
from pygran_core.io import Frame, open_trajectory
from pygran_core.simulation.calls import CreateSpec, InsertSpec, MotionSpec, Region, ViscousSpec, WallSpec
from pygran_core.simulation.engine import Engine, Handle
from pygran_core.simulation.insertion import Obstacles, place_spheres
from pygran_core.simulation.specs import MeshSpec, SimulationSpec
from pygran_native.solver import Solver

MODEL_KIND = {"SpringDashpot": "hooke", "HertzMindlin": "hertz", "ThorntonNing": "thornton-ning"}
#: Default interval between insertions by rate, in simulated seconds.
RATE_INTERVAL = 1e-2


@dataclass
class _Insertion:
    """An active insertion: what to insert, when next, and how much is still owed."""

    spec: InsertSpec
    freq: int
    next_step: int
    end_step: int | None
    owed: float = 0.0
    rng: np.random.Generator = field(default_factory=np.random.default_rng)


def _rotation(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    """Rotation matrix about ``axis`` by ``degrees`` (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    angle = math.radians(degrees)
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def mesh_triangles(mesh: MeshSpec) -> np.ndarray:
    """A mesh's triangles (T, 3, 3) in place: scaled, then rotated about the origin, then translated."""
    frame = open_trajectory(mesh.file, format="stl", scale=mesh.scale).read_frame(0)
    points, cells = frame.arrays["points"], frame.arrays["cells"]
    if mesh.rotate is not None:
        points = points @ _rotation(*mesh.rotate).T
    return points[cells[:, :3]] + np.asarray(mesh.translate)


class NativeEngine(Engine):
    """PyGran's own DEM engine (compiled Cython/OpenMP solver)."""

    name = "native"
    capabilities = frozenset(
        {
            "spring-dashpot",
            "hertz-mindlin",
            "thornton-ning",
            "cohesion",
            "rolling-friction",
            "periodic",
            "primitive-walls",
            "mesh-walls",
            "moving-mesh",
            "polydisperse",
            "insert-by-rate",
            "threads",
        }
    )

    def __init__(self, spec: SimulationSpec) -> None:
        super().__init__(spec)
        if spec.model.__name__ not in MODEL_KIND:
            raise self._unsupported(
                f"the contact model {spec.model.__name__} (it has kernels for {', '.join(MODEL_KIND)})"
            )
        if not spec.species:
            raise ConfigError(
                "The native engine needs at least one species: species=({'material': ..., 'radius': ...},)"
            )
        gravity = spec.gravity.vector if spec.gravity is not None else np.zeros(3)
        self.solver = Solver(
            np.array(spec.domain.box).T, spec.domain.periodic, gravity, spec.skin, spec.threads, spec.seed
        )
        self._mesh_types = {m.name: len(spec.species) + i for i, m in enumerate(spec.meshes)}
        materials = [s.material for s in spec.species] + [
            m.material or spec.species[0].material for m in spec.meshes
        ]
        self.solver.set_contact_model(MODEL_KIND[spec.model.__name__], **self._material_arrays(materials))
        self._insertions: dict[str, _Insertion] = {}
        self._walls: dict[str, int] = {}
        self._planes: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._mesh_walls: dict[str, int] = {}
        self._motions: dict[str, str] = {}
        self._drags: dict[str, ViscousSpec] = {}
        self._labels = 0
        self.log("native solver: %d threads, skin %g m", self.solver.threads, spec.skin)

    def _material_arrays(self, materials: list[Any]) -> dict[str, Any]:
        kind = MODEL_KIND[self.spec.model.__name__]

        def column(key: str, default: float | None) -> np.ndarray:
            values = [m.get(key, default) for m in materials]
            if None in values:
                raise ConfigError(f"The {self.spec.model.__name__} model needs {key!r} in every material")
            return np.array(values, float)

        arrays: dict[str, Any] = {
            "youngs": column("youngsModulus", None),
            "poisson": column("poissonsRatio", None),
            "friction": column("coefficientFriction", 0.0),
            "rolling_friction": column("coefficientRollingFriction", 0.0),
            "cohesion_energy": column("cohesionEnergyDensity", 0.0),
        }
        if kind == "thornton-ning":
            arrays["yield_pressure"] = column("yieldPress", None)
        else:
            arrays["restitution"] = column("coefficientRestitution", None)
        if kind == "hooke":
            arrays["characteristic_velocity"] = float(column("characteristicVelocity", None).max())
        return arrays

    def _label(self, kind: str) -> str:
        self._labels += 1
        return f"{kind}{self._labels}"

    # -- particles ---------------------------------------------------------------------

    def _obstacles(self) -> Obstacles:
        """Planes and mesh triangles new particles must clear (cylinders are not checked)."""
        triangles = [self.solver.mesh_triangles(m) for m in self._mesh_walls.values()]
        planes = list(self._planes.values())
        return Obstacles(
            np.reshape([p for p, _ in planes], (-1, 3)),
            np.reshape([n for _, n in planes], (-1, 3)),
            np.concatenate(triangles) if triangles else np.zeros((0, 3, 3)),
        )

    def _place(
        self,
        region: Region,
        species: np.ndarray,
        radii: np.ndarray,
        rng: np.random.Generator,
        velocity: np.ndarray,
        omega: Any,
        all_in: bool = True,
    ) -> int:
        """Add spheres of ``species``/``radii`` at free places in ``region``; returns how many fit."""
        existing = (self.solver.positions, self.solver.radii)
        index, centres = place_spheres(region, radii, rng, existing, self._obstacles(), all_in)
        if len(index):
            density = np.array([self.spec.species[s - 1].density for s in species[index]])
            self.solver.add_particles(
                centres,
                radii[index],
                densities=density,
                types=species[index] - 1,
                velocities=velocity[index],
                omegas=np.tile(omega, (len(index), 1)),
            )
        return len(index)

    def _draw(self, spec: InsertSpec, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        species = rng.choice(np.array(spec.species), size=count, p=np.array(spec.weights))
        radii = np.empty(count)
        for s in spec.species:
            chosen = species == s
            radii[chosen] = self.spec.species[s - 1].radius.sample(int(chosen.sum()), rng)
        return species, radii

    def _by_mass(self, spec: InsertSpec) -> bool:
        return spec.target in ("mass_in_region", "massrate")

    def _amount(self, spec: InsertSpec, species: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Each particle's share of the target: 1, its volume or its mass."""
        if spec.target in ("particles_in_region", "particlerate"):
            return np.ones(len(radii))
        volume = 4 / 3 * math.pi * radii**3
        if not self._by_mass(spec):
            return volume
        return volume * np.array([self.spec.species[s - 1].density for s in species])

    def _count_for(
        self, spec: InsertSpec, amount: float, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Species and radii of particles that make up at most ``amount`` of the target."""
        if spec.target in ("particles_in_region", "particlerate"):
            return self._draw(spec, int(amount), rng)
        typical = np.dot(
            spec.weights,
            [
                4
                / 3
                * math.pi
                * self.spec.species[s - 1].radius.mean ** 3
                * (self.spec.species[s - 1].density if self._by_mass(spec) else 1.0)
                for s in spec.species
            ],
        )
        species, radii = self._draw(spec, int(1.2 * amount / typical) + 2, rng)
        count = int(np.searchsorted(np.cumsum(self._amount(spec, species, radii)), amount, side="right"))
        return species[:count], radii[:count]

    def _pack_amount(self, spec: InsertSpec) -> float:
        """How much the region still lacks of the by-pack target."""
        inside = spec.region.contains(self.solver.positions)
        if spec.target == "particles_in_region":
            return max(spec.value - np.count_nonzero(inside), 0)
        volume = 4 / 3 * math.pi * self.solver.radii[inside] ** 3
        if spec.target == "volumefraction_region":
            return max(spec.value * spec.region.volume() - volume.sum(), 0.0)
        return max(spec.value - self.solver.masses[inside].sum(), 0.0)

    def _insert_now(self, job: _Insertion, amount: float) -> float:
        """Insert up to ``amount`` of the job's target; returns the amount drawn (placed or not)."""
        spec = job.spec
        species, radii = self._count_for(spec, amount, job.rng)
        velocity = spec.velocity.sample(len(radii), job.rng)
        made = self._place(spec.region, species, radii, job.rng, velocity, spec.omega, spec.all_in)
        self.log("insert at step %d: %d of %d particles", self.step, made, len(radii))
        if made < len(radii):
            self.log("region full: %d particles did not fit", len(radii) - made, level=30)
        return float(self._amount(spec, species, radii).sum())

    def _insert(self, spec: InsertSpec) -> str:
        label = self._label("insert")
        rng = np.random.default_rng(spec.seed)
        if spec.mechanism == "by_pack":
            job = _Insertion(spec, spec.freq or 0, self.step, None, rng=rng)
            self._insert_now(job, self._pack_amount(spec))
            if spec.freq:
                job.next_step = self.step + spec.freq
                self._insertions[label] = job
            return label
        if self.dt is None:
            raise ConfigError("Insertion by rate needs the time step: pass dt=... to DEM before insert()")
        freq = spec.freq or max(1, round(RATE_INTERVAL / self.dt))
        end = None if spec.duration is None else self.step + round(spec.duration / self.dt)
        self._insertions[label] = _Insertion(spec, freq, self.step, end, rng=rng)
        self._on_insertions()
        return label

    def _on_insertions(self) -> None:
        for label, job in list(self._insertions.items()):
            if job.end_step is not None and self.step >= job.end_step:
                del self._insertions[label]
                continue
            if self.step != job.next_step:
                continue
            if job.spec.mechanism == "by_pack":
                self._insert_now(job, self._pack_amount(job.spec))
            else:
                job.owed += job.spec.value * job.freq * self.dt
                job.owed -= self._insert_now(job, job.owed)
            job.next_step = self.step + job.freq

    def _create(self, spec: CreateSpec) -> int:
        species = self.spec.species[spec.species - 1]
        rng = np.random.default_rng(spec.seed)
        if spec.style == "single":
            radius = spec.radius or species.radius.sample(1, rng)[0]
            self.solver.add_particles(
                [spec.position],
                [radius],
                densities=species.density,
                types=spec.species - 1,
                velocities=[spec.velocity],
                omegas=[spec.omega],
            )
            return 1
        if spec.style == "lattice":
            bounds = spec.region.bounds()
            axes = [np.arange(lo + spec.spacing / 2, hi, spec.spacing) for lo, hi in bounds]
            centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            radii = np.full(len(centres), spec.radius or species.radius.mean)
            inside = spec.region.contains(centres, radii)
            self.solver.add_particles(
                centres[inside],
                radii[inside],
                densities=species.density,
                types=spec.species - 1,
                velocities=np.tile(spec.velocity, (inside.sum(), 1)),
                omegas=np.tile(spec.omega, (inside.sum(), 1)),
            )
            return int(inside.sum())
        radii = np.full(spec.count, spec.radius) if spec.radius else species.radius.sample(spec.count, rng)
        types = np.full(spec.count, spec.species)
        return self._place(
            spec.region, types, radii, rng, np.tile(spec.velocity, (spec.count, 1)), spec.omega
        )

    # -- walls and meshes ----------------------------------------------------------------

    def _wall(self, spec: WallSpec) -> str:
        label = self._label("wall")
        if spec.kind == "plane":
            axis = "xyz".index(spec.plane[0])
            lo, hi = self.spec.domain.box[axis]
            normal = np.zeros(3)
            normal[axis] = 1.0 if spec.peq - lo <= hi - spec.peq else -1.0
            point = np.zeros(3)
            point[axis] = spec.peq
            wall = self.solver.add_plane(point, normal, spec.species - 1)
            self._planes[wall] = (point, normal)
            self._walls[label] = wall
        elif spec.kind == "cylinder":
            self._walls[label] = self.solver.add_cylinder(
                spec.axis, spec.centre, spec.radius, spec.species - 1
            )
        else:
            mesh = next(m for m in self.spec.meshes if m.name == spec.mesh)
            if mesh.name in self._mesh_walls:
                raise ConfigError(f"mesh {mesh.name!r} is already a wall")
            triangles = mesh_triangles(mesh)
            wall_type = self._mesh_types[mesh.name] if mesh.material else spec.species - 1
            self._mesh_walls[mesh.name] = self.solver.add_mesh(
                triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3), wall_type
            )
            self._walls[label] = self._mesh_walls[mesh.name]
        return label

    def _move_mesh(self, spec: MotionSpec) -> str:
        if spec.mesh not in self._mesh_walls:
            raise ConfigError(
                f"mesh {spec.mesh!r} is not a wall yet: "
                f"call setupWall(wtype='mesh', mesh={spec.mesh!r}) first"
            )
        if spec.mesh in self._motions.values():
            raise ConfigError(f"mesh {spec.mesh!r} already moves; remove() that motion first")
        if spec.kind == "wiggle":
            raise self._unsupported("wiggling meshes (time-dependent velocity)")
        wall = self._mesh_walls[spec.mesh]
        if spec.kind == "rotate":
            self.solver.set_mesh_motion(
                wall, angular_velocity=spec.omega * np.asarray(spec.axis), origin=spec.origin
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
        if label in self._insertions:
            del self._insertions[label]
        elif label in self._walls:
            wall = self._walls.pop(label)
            self.solver.remove_wall(wall)
            self._planes.pop(wall, None)
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

    def _frequencies(self) -> list[int]:
        return super()._frequencies() + [job.freq for job in self._insertions.values() if job.freq]

    def _on_event(self) -> None:
        self._on_insertions()
        super()._on_event()

    def _advance(self, nsteps: int) -> None:
        self.solver.run(nsteps, self.dt)

    def _extract(self, quantity: str) -> np.ndarray:
        solver = self.solver
        if quantity == "id":
            return solver.ids + 1
        if quantity == "type":
            return solver.types.astype(np.int64) + 1
        return {
            "x": solver.positions,
            "v": solver.velocities,
            "omega": solver.omegas,
            "f": solver.forces,
            "torque": solver.torques,
            "radius": solver.radii,
            "mass": solver.masses,
        }[quantity]

    def _scalar(self, quantity: str) -> float:
        if quantity == "ke_rot":
            return self.solver.kinetic_energy()[1]
        if quantity == "contacts":
            return float(len(self.solver.contacts()[0]))
        return super()._scalar(quantity)

    def _mesh_frame(self) -> Frame:
        triangles = [self.solver.mesh_triangles(w) for w in self._mesh_walls.values()]
        meshid = (
            np.concatenate([np.full(len(t), i) for i, t in enumerate(triangles)])
            if triangles
            else np.zeros(0)
        )
        corners = np.concatenate(triangles) if triangles else np.zeros((0, 3, 3))
        cells = np.arange(3 * len(corners)).reshape(-1, 3)
        arrays = {
            "points": corners.reshape(-1, 3),
            "cells": cells,
            "cell_types": np.full(len(cells), 5),
            "meshid": meshid,
        }
        return Frame(
            arrays,
            timestep=self.step,
            time=self.time,
            attrs={"kind": "mesh", "point_data": [], "cell_data": ["meshid"]},
        )
