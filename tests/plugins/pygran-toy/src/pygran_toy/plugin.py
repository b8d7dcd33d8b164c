"""A complete third-party plugin: a toy engine, a reader and a writer.

The toy engine moves a few spheres in pure numpy, O(N^2) in the number of spheres: velocity
Verlet under gravity and the contact forces between spheres of the simulation's
:class:`~pygran_core.simulation.models.SpringDashpot` model, from the model's own
``normal_force`` and ``tangential_force`` (tangential history, Coulomb limit). It has no
walls. A sphere whose centre leaves the box is deleted and reported as lost.

The ``.toy`` format is a text file per frame: a ``# toy`` line, then ``x y z`` per particle.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pygran_core import Engine, hookimpl
from pygran_core.hookspecs import EngineSpec, ReaderSpec, WriterSpec
from pygran_core.io import Frame, Trajectory, TrajectoryWriter
from pygran_core.simulation.engine import LostParticles
from pygran_core.simulation.specs import given


class ToyEngine(Engine):
    """Spheres under gravity and spring-dashpot contacts with each other (see the module)."""

    name = "toy"
    capabilities = frozenset({"spring-dashpot"})

    def __init__(self, spec):
        super().__init__(spec)
        self.gravity = spec.gravity.vector if spec.gravity is not None else np.zeros(3)
        self.ids = np.zeros(0, np.int64)
        self.types = np.zeros(0, np.int64)
        self.x, self.v, self.omega = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
        self.radius, self.mass = np.zeros(0), np.zeros(0)
        self.force, self.torque = np.zeros((0, 3)), np.zeros((0, 3))
        self.history = {}  # (id, id) of a touching pair -> its tangential displacement
        self._models = {}  # ((type, radius), (type, radius)) -> the pair's contact model
        self._forces_stale = False  # spheres were added since the forces were computed
        self._next_id = 1  # ids are never reused, as in LIGGGHTS
        self._unreported = LostParticles()

    def _create(self, request):
        if request.style != "single":
            raise self._unsupported(f"createParticles style {request.style!r}")
        species = self.spec.species[request.species - 1]
        centres = request.centres
        n = len(centres)
        radius = request.radius or species.radius.mean
        self.ids = np.append(self.ids, np.arange(self._next_id, self._next_id + n))
        self._next_id += n
        self.types = np.append(self.types, np.full(n, request.species))
        self.x = np.vstack([self.x, centres])
        self.v = np.vstack([self.v, np.tile(request.velocity, (n, 1))])
        self.omega = np.vstack([self.omega, np.tile(request.omega, (n, 1))])
        self.radius = np.append(self.radius, np.full(n, radius))
        mass = species.density * 4 / 3 * math.pi * radius**3
        self.mass = np.append(self.mass, np.full(n, mass))
        self.force = np.vstack([self.force, np.tile(mass * self.gravity, (n, 1))])
        self.torque = np.vstack([self.torque, np.zeros((n, 3))])
        self._forces_stale = True
        return n

    def _advance(self, nsteps):
        if self._forces_stale:
            self._compute_forces(0.0)
            self._forces_stale = False
        dt = given(self.dt, "the toy engine's time step")
        for _ in range(nsteps):  # velocity Verlet
            self._kick(0.5 * dt)
            self.x = self.x + dt * self.v
            self._drop_lost()
            self._compute_forces(dt)
            self._kick(0.5 * dt)

    def _kick(self, dt):
        inertia = 0.4 * self.mass * self.radius**2
        self.v = self.v + dt * self.force / self.mass[:, None]
        self.omega = self.omega + dt * self.torque / inertia[:, None]

    def _model(self, one, other):
        """The contact model of spheres ``(type, radius)`` ``one`` and ``other``."""
        key = tuple(sorted((one, other)))
        if key not in self._models:
            spheres = [
                dict(
                    self.spec.species[int(kind) - 1].material,
                    radius=r,
                    density=self.spec.species[int(kind) - 1].density,
                )
                for kind, r in key
            ]
            self._models[key] = self.spec.model(spheres[0], partner=spheres[1])
        return self._models[key]

    def _compute_forces(self, dt):
        """Gravity and contact forces and torques; the tangential displacement of each
        touching pair grows by its sliding velocity times ``dt``."""
        self.force = self.mass[:, None] * self.gravity
        self.torque = np.zeros_like(self.x)
        i, j = np.triu_indices(len(self.x), 1)
        apart = self.x[j] - self.x[i]
        distance = np.linalg.norm(apart, axis=1)
        touching = distance < self.radius[i] + self.radius[j]
        if not touching.any():
            self.history = {}
            return
        i, j, apart, distance = i[touching], j[touching], apart[touching], distance[touching]
        ri, rj = self.radius[i], self.radius[j]
        overlap = ri + rj - distance
        normal = apart / distance[:, None]  # from i to j
        relative = (
            self.v[i]
            - self.v[j]
            + np.cross(ri[:, None] * self.omega[i] + rj[:, None] * self.omega[j], normal)
        )
        rate = np.einsum("ij,ij->i", relative, normal)  # positive while approaching
        sliding = relative - rate[:, None] * normal
        pairs = list(zip(self.ids[i].tolist(), self.ids[j].tolist()))
        xi = np.array([self.history.get(pair, np.zeros(3)) for pair in pairs]).reshape(-1, 3)
        xi = xi - np.einsum("ij,ij->i", xi, normal)[:, None] * normal + dt * sliding
        normal_force, tangential_force = np.zeros(len(i)), np.zeros((len(i), 3))
        kinds = np.column_stack([self.types[i], ri, self.types[j], rj])
        for kind in np.unique(kinds, axis=0):
            chosen = (kinds == kind).all(axis=1)
            model = self._model((kind[0], kind[1]), (kind[2], kind[3]))
            normal_force[chosen] = model.normal_force(overlap[chosen], rate[chosen])
            tangential_force[chosen], xi[chosen] = model.tangential_force(
                overlap[chosen], xi[chosen], sliding[chosen], normal_force[chosen]
            )
        on_i = tangential_force - normal_force[:, None] * normal
        np.add.at(self.force, i, on_i)
        np.add.at(self.force, j, -on_i)
        turning = np.cross(normal, tangential_force)
        np.add.at(self.torque, i, ri[:, None] * turning)
        np.add.at(self.torque, j, rj[:, None] * turning)
        self.history = dict(zip(pairs, xi))

    def _drop_lost(self):
        """Delete the spheres whose centre left the box, or whose position or velocity is not finite."""
        box = np.asarray(self.spec.domain.box, float)
        finite = np.asarray(np.isfinite(self.x).all(axis=1) & np.isfinite(self.v).all(axis=1))
        below, above = self.x < box[:, 0], self.x > box[:, 1]
        gone = ~finite | (below | above).any(axis=1)
        if not gone.any():
            return
        where: dict[str, int] = {}
        for k in np.flatnonzero(gone):
            if not finite[k]:
                place = "non-finite"
            else:
                axis = int(np.flatnonzero(below[k] | above[k])[0])
                place = "xyz"[axis] + ("-" if below[k, axis] else "+")
            where[place] = where.get(place, 0) + 1
        speeds = np.linalg.norm(self.v[gone & finite], axis=1)
        self._unreported += LostParticles(
            int(gone.sum()), where, float(speeds.max()) if len(speeds) else None
        )
        keep = ~gone
        for name in ("ids", "types", "x", "v", "omega", "radius", "mass", "force", "torque"):
            setattr(self, name, getattr(self, name)[keep])

    def _lost_since_last(self):
        lost, self._unreported = self._unreported, LostParticles()
        return lost

    def _extract(self, quantity):
        values = {
            "x": self.x,
            "v": self.v,
            "omega": self.omega,
            "f": self.force,
            "torque": self.torque,
            "radius": self.radius,
            "mass": self.mass,
            "id": self.ids,
            "type": self.types,
        }
        return values[quantity].copy()


class ToyTrajectory(Trajectory):
    def __init__(self, paths, **options):
        self.paths = list(paths)

    @property
    def n_frames(self):
        return len(self.paths)

    def _read_frame(self, index):
        xyz = np.loadtxt(self.paths[index], comments="#", ndmin=2)
        return Frame({"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}, timestep=index)


class ToyWriter(TrajectoryWriter):
    def __init__(self, path, **options):
        self.path = Path(path)
        self.count = 0

    def write_frame(self, frame):
        xyz = np.column_stack([frame.arrays[k] for k in "xyz"])
        target = self.path.with_name(f"{self.path.stem}{self.count}{self.path.suffix}")
        np.savetxt(target, xyz, header="toy")
        self.count += 1


def can_open(path):
    try:
        with open(path, "rb") as handle:
            return handle.read(5) == b"# toy"
    except OSError:
        return False


@hookimpl
def pygran_engines():
    yield EngineSpec(name="toy", factory=ToyEngine, capabilities=ToyEngine.capabilities)


@hookimpl
def pygran_readers():
    yield ReaderSpec(name="toy", extensions=(".toy",), open=ToyTrajectory, can_open=can_open)


@hookimpl
def pygran_writers():
    yield WriterSpec(name="toy", extensions=(".toy",), open=ToyWriter)
