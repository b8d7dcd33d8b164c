"""The native DEM solver: argument checking and numpy I/O around the compiled core.

All quantities are SI. Per-particle outputs are copies ordered by particle id. The time
step loop (:meth:`Solver.run`) runs entirely in compiled code without the GIL, on a team of
threads sharing blocks of particles and their contacts (a thread whose core another program
takes leaves its blocks to the others, and waiting threads sleep rather than spin, so a busy
machine slows a run down instead of stalling it); results are bitwise reproducible for a
given thread count, whichever thread runs a block, also across :meth:`Solver.get_state` /
:meth:`Solver.set_state`.

Conventions (LIGGGHTS):

- velocity Verlet for translation and rotation of spheres (moment of inertia
  ``2/5 m r^2``), gravity, viscous force ``F = -gamma v`` per particle type;
- neighbour search: cell list of side ``>= 2 r + skin`` (r the largest radius but for a few
  particles over twice the smallest, which search the cells in their reach), half neighbour
  list rebuilt when a particle plus a moving wall have moved more than half the skin since
  the last rebuild; at each rebuild particles are wrapped into periodic directions, sorted by
  cell, and those outside a fixed boundary or non-finite are deleted and counted in
  :attr:`Solver.lost` (LIGGGHTS ``boundary f``), by face and with their speed
  (:meth:`Solver.take_lost`); a non-finite particle forces a rebuild at once;
- contact models: ``hooke``, ``hertz`` and ``thornton-ning`` with the formulas of
  :mod:`pygran_core.simulation.models` (``SpringDashpot``, ``HertzMindlin``,
  ``ThorntonNing``), tangential history with the Coulomb limit, SJKR cohesion for
  hooke/hertz and JKR adhesion for Thornton-Ning when ``cohesion_energy > 0``, rolling
  resistance when ``rolling_friction > 0``: LIGGGHTS' ``cdt`` (its torque's component along
  the contact normal removed, as LIGGGHTS does), ``epsd`` or ``epsd2`` (the last two with a
  spring torque in the contact history); pair values from
  :mod:`pygran_core.simulation.models.mixing`, a wall being a body of infinite radius and
  mass of its own type;
- walls: two-sided planes (LIGGGHTS primitive planes: a contact pushes the particle back
  to the side its centre was on when the contact began, even if a deeply plastic contact
  lets the centre sink past the plane), cylinders (inside or outside), and triangle meshes
  (two-sided; face, edge and vertex contacts, a shared edge or vertex counted once) with
  rigid motion: translation, rotation, wiggle, LIGGGHTS' viblin and vibrot
  (:meth:`Solver.set_mesh_vibration`), or a servo's (LIGGGHTS
  ``mesh/surface/stress/servo``, :meth:`Solver.set_servo`). The particles' force on a stress
  or servo mesh is summed at each step (:meth:`Solver.mesh_force`). Meshes are not repeated
  across periodic boundaries;
- clumps (:meth:`Solver.add_clumps`): rigid bodies of overlapping spheres, with the mass,
  centre and inertia of the union of their spheres
  (:func:`pygran_core.simulation.clumps.mass_properties`). Their spheres are particles in
  every output (each with the clump's mass, its velocity at the sphere's centre and its
  angular velocity; forces and torques: the sphere's contacts), never in contact with one
  another; gravity and viscous drag act on the clump, which is integrated with a quaternion
  and its angular momentum by a symplectic splitting (see _clumps.pxi). A clump one of whose
  spheres leaves a fixed boundary is deleted whole and counted once.
"""

from __future__ import annotations

import math
import os

import numpy as np

from pygran_core.errors import ConfigError
from pygran_native import _kernels
from pygran_native._solver import LOST_PLACES, MAX_THREADS, Core
from pygran_native.arguments import array_of, per_particle, vectors_of
from pygran_native.bodies import Bodies
from pygran_native.checkpoint import Checkpoints
from pygran_native.contact_model import model_tables
from pygran_native.walls import Walls

__all__ = ["Solver", "default_threads"]


def default_threads() -> int:
    """Threads of a solver not told otherwise: ``OMP_NUM_THREADS`` when it is set, else the
    CPUs this process may run on now (``os.sched_getaffinity``: ``taskset``, a batch job's
    cpuset), not every core of the machine."""
    if os.environ.get("OMP_NUM_THREADS"):
        return _kernels.openmp_threads()
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


class Solver(Walls, Bodies, Checkpoints):
    """A DEM simulation of spheres in a box; see the module docstring for conventions.

    ``box`` is ``[[xlo, ylo, zlo], [xhi, yhi, zhi]]``; ``periodic`` per axis; ``gravity``
    the acceleration vector; ``skin`` the neighbour-list skin; ``threads`` the threads of
    :meth:`run` (default: :func:`default_threads`); ``seed`` seeds :attr:`rng`, the
    solver's random stream (its state is part of :meth:`get_state`).

    Its parts: :class:`~pygran_native.walls.Walls` (walls, their motion, stress and servo
    meshes), :class:`~pygran_native.bodies.Bodies` (clumps) and
    :class:`~pygran_native.checkpoint.Checkpoints` (get_state, set_state).
    """

    def __init__(
        self,
        box,
        periodic=(False, False, False),
        gravity=(0.0, 0.0, 0.0),
        skin: float = 0.0,
        threads: int | None = None,
        seed: int = 0,
    ) -> None:
        box = array_of(box, "box", (2, 3)).copy()
        if not np.all(box[1] > box[0]):
            raise ConfigError(f"box: every upper bound must exceed the lower one, got {box.tolist()}.")
        periodic = tuple(bool(p) for p in array_of(periodic, "periodic", (3,), bool))
        gravity = array_of(gravity, "gravity", (3,))
        if not (math.isfinite(skin) and skin > 0):
            raise ConfigError(f"skin: must be > 0, got {skin!r}.")
        threads = default_threads() if threads is None else threads
        if not (isinstance(threads, (int, np.integer)) and 1 <= threads <= MAX_THREADS):
            raise ConfigError(f"threads: must be an integer from 1 to {MAX_THREADS}, got {threads!r}.")
        self.box, self.periodic, self.threads = box, periodic, int(threads)
        self._core = Core(box[0], box[1], periodic, gravity, float(skin), self.threads)
        self.rng = np.random.default_rng(seed)
        self._model = None
        self._next_id = 0
        self._next_body = 0
        self._next_wall = 0
        self._next_vertex = 0
        self._walls = {}
        self._viscous = np.zeros(0)

    # --- set-up ------------------------------------------------------------------------
    def set_contact_model(
        self,
        kind: str,
        *,
        youngs,
        poisson,
        restitution=None,
        friction=0.0,
        rolling_friction=0.0,
        rolling: str = "cdt",
        rolling_damping=0.0,
        limit_force: bool = False,
        cohesion_energy=0.0,
        yield_pressure=None,
        characteristic_velocity: float | None = None,
    ) -> None:
        """Choose the contact model and give per-type material arrays (one entry per type).

        ``kind``: ``"hooke"`` (needs ``restitution`` and ``characteristic_velocity``),
        ``"hertz"`` (needs ``restitution``) or ``"thornton-ning"`` (needs
        ``yield_pressure``; ``cohesion_energy`` is the JKR surface energy in J/m^2, for the
        others the SJKR energy density in J/m^3). ``rolling``: the rolling resistance model,
        ``"cdt"``, ``"epsd"`` (damped by ``rolling_damping``, LIGGGHTS'
        coefficientRollingViscousDamping) or ``"epsd2"``. ``limit_force``: keep the hooke and hertz
        visco-elastic normal force from turning attractive (LIGGGHTS ``limitForce on``; cohesion
        still attracts). Particle and wall types index these
        arrays. Changing the model to one with another history layout clears histories.
        """
        tables, self._model = model_tables(
            kind,
            youngs=youngs,
            poisson=poisson,
            restitution=restitution,
            friction=friction,
            rolling_friction=rolling_friction,
            rolling=rolling,
            rolling_damping=rolling_damping,
            limit_force=limit_force,
            cohesion_energy=cohesion_energy,
            yield_pressure=yield_pressure,
            characteristic_velocity=characteristic_velocity,
        )
        self._core.set_model(*tables)
        nt = self.ntypes
        if self._viscous.shape[0] != nt:
            self._viscous = np.resize(self._viscous, nt) * (np.arange(nt) < self._viscous.shape[0])
        self._core.set_viscous(self._viscous)

    def set_viscous(self, gamma) -> None:
        """Viscous damping ``F = -gamma v`` with ``gamma`` (kg/s) per type."""
        if self._model is None:
            raise ConfigError("gamma: call set_contact_model first.")
        gamma = array_of(
            np.broadcast_to(np.asarray(gamma, float), (self.ntypes,)) if np.ndim(gamma) == 0 else gamma,
            "gamma",
            (self.ntypes,),
        )
        if np.any(gamma < 0):
            raise ConfigError(f"gamma: must be >= 0, got {gamma.tolist()}.")
        self._viscous = gamma.copy()
        self._core.set_viscous(self._viscous)

    # --- particles ---------------------------------------------------------------------
    def add_particles(
        self, positions, radii, densities=None, types=0, velocities=None, omegas=None, masses=None
    ) -> np.ndarray:
        """Add spheres; returns their ids. Give ``densities`` or ``masses`` (scalars broadcast);
        ``velocities`` and ``omegas``: a vector per particle or one for all (default zero)."""
        x = array_of(positions, "positions", (-1, 3))
        n = x.shape[0]
        r = per_particle(radii, "radii", n)
        if np.any(r <= 0):
            raise ConfigError("radii: must be > 0.")
        if (densities is None) == (masses is None):
            raise ConfigError("densities/masses: give exactly one of them.")
        if masses is None:
            rho = per_particle(densities, "densities", n)
            if np.any(rho <= 0):
                raise ConfigError("densities: must be > 0.")
            m = r**3
            m *= 4.0 / 3.0 * np.pi
            m *= rho
        else:
            m = per_particle(masses, "masses", n)
            if np.any(m <= 0):
                raise ConfigError("masses: must be > 0.")
        t = per_particle(types, "types", n, np.int32)
        self._check_types(t, "types")
        v = vectors_of(velocities, "velocities", n)
        w = vectors_of(omegas, "omegas", n)
        self._check_inside(x, "positions")
        first = self._next_id
        self._core.add_particles(x, r, m, t, v, w, first)
        self._next_id += n
        return np.arange(first, first + n, dtype=np.int64)

    def remove_particles(self, ids) -> None:
        """Delete particles by id (with their contacts; a clump's sphere: the whole clump)."""
        index = self._index(ids, "ids")
        mask = np.zeros(self.n, np.uint8)
        mask[index] = 1
        self._core.mark_removed(mask)
        self._core.run(0, 1.0)  # rebuild now so n and the arrays reflect the removal

    def set_velocities(self, ids, velocities) -> None:
        """Assign translational velocities to the particles with these ids (not clumps' spheres)."""
        index = self._free(ids, "ids")
        self._core.set_vectors("v", index, array_of(velocities, "velocities", (len(index), 3)))

    def set_omegas(self, ids, omegas) -> None:
        """Assign angular velocities to the particles with these ids (not clumps' spheres)."""
        index = self._free(ids, "ids")
        self._core.set_vectors("w", index, array_of(omegas, "omegas", (len(index), 3)))

    def set_radii(self, ids, radii) -> None:
        """Assign radii to the particles with these ids (not clumps' spheres); masses follow at
        constant density."""
        index = self._free(ids, "ids")
        r = per_particle(radii, "radii", len(index))
        if np.any(r <= 0):
            raise ConfigError("radii: must be > 0.")
        old_r, old_m = self._core.array("r")[index], self._core.array("m")[index]
        self._core.set_radii(index, r, np.ascontiguousarray(old_m * (r / old_r) ** 3))

    # --- running -----------------------------------------------------------------------
    def run(self, nsteps: int, dt: float) -> None:
        """Advance ``nsteps`` steps of ``dt`` seconds (compiled, no Python in the loop)."""
        if not (isinstance(nsteps, (int, np.integer)) and nsteps >= 0):
            raise ConfigError(f"nsteps: must be a non-negative integer, got {nsteps!r}.")
        if not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f"dt: must be > 0, got {dt!r}.")
        if self._model is None:
            raise ConfigError("set_contact_model must be called before run.")
        self._check_servo_speeds(dt)
        if self.n:
            reach = 2 * self._core.largest_radius() + self._core.skin
            for d in range(3):
                if self.periodic[d] and self.box[1, d] - self.box[0, d] < 2 * reach:
                    raise ConfigError(
                        f"box: the periodic axis {'xyz'[d]} must be at least 2 (2 r_max + skin) "
                        f"= {2 * reach:g} long."
                    )
        self._core.run(int(nsteps), float(dt))

    # --- outputs -----------------------------------------------------------------------
    def _sorted(self, name: str) -> np.ndarray:
        return self._core.by_id(name)

    n = property(lambda self: self._core.n, doc="Number of particles.")
    time = property(lambda self: self._core.time, doc="Simulated time (s).")
    step = property(lambda self: self._core.step, doc="Steps run so far.")
    lost = property(
        lambda self: self._core.lost,
        doc="Particles deleted for leaving a fixed boundary or becoming non-finite.",
    )

    def take_lost(self) -> tuple[dict[str, int], float | None]:
        """Particles lost since the last call (part of :meth:`get_state`): counts by place, a
        face of the box (``"z-"``: below its lower z bound; the one a particle is furthest
        beyond) or ``"non-finite"``, and the largest speed (m/s) of those lost through a face,
        ``None`` if there were none."""
        counts, speed = self._core.take_lost()
        where = {place: int(k) for place, k in zip(LOST_PLACES, counts) if k}
        return where, (speed if sum(where.values()) > where.get("non-finite", 0) else None)

    positions = property(lambda self: self._sorted("x"), doc="(n, 3) positions, by id.")
    velocities = property(lambda self: self._sorted("v"), doc="(n, 3) velocities, by id.")
    omegas = property(lambda self: self._sorted("w"), doc="(n, 3) angular velocities, by id.")
    forces = property(lambda self: self._sorted("f"), doc="(n, 3) forces at the last step, by id.")
    torques = property(lambda self: self._sorted("t"), doc="(n, 3) torques at the last step, by id.")
    radii = property(lambda self: self._sorted("r"), doc="(n,) radii, by id.")
    masses = property(lambda self: self._sorted("m"), doc="(n,) masses, by id.")
    types = property(lambda self: self._sorted("type"), doc="(n,) types, by id.")
    ids = property(lambda self: self._sorted("id"), doc="(n,) ids, ascending.")
    bodies = property(
        lambda self: self._sorted("body"), doc="(n,) the clump of each particle (-1: a free sphere), by id."
    )

    def contacts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Particle-particle contacts at the last step: ``(i_ids, j_ids, overlap, normal_force)``."""
        i, j, overlap, force = self._core.contacts()
        ids = self._core.array("id")
        return ids[i], ids[j], overlap, force

    def contact_forces(self) -> dict[str, np.ndarray]:
        """Contacts at the last step, with the forces the step applied, pairs then walls: ids
        ``id1``, ``id2`` (int64; a wall contact has ``id2 = -(handle + 1)`` with the wall's
        handle), the total contact force on id1 by id2 ``fx, fy, fz`` (normal and tangential; id2
        gets the opposite), the contact point ``cx, cy, cz`` and the branch vector ``bx, by, bz``
        = x1 - x2 (across a periodic boundary, to the image in contact). A pair's point is the
        middle of the overlap on the line of centres; a wall's is on its surface (the closest
        point of the mesh triangle the contact used, the foot point on a plane or cylinder),
        with ``b = x1 - c``; a particle on a flat mesh surface has one contact however many of
        its triangles it reaches. A ConfigError after :meth:`set_state` until a run evaluates
        the forces (they are not part of a checkpoint), and when :attr:`record_contacts` is off."""
        if not self.record_contacts:
            raise ConfigError(
                "contact_forces: the solver does not keep contact forces; set record_contacts = True "
                "and run a step first."
            )
        try:
            return self._core.contact_forces()
        except ValueError:
            raise ConfigError(
                "contact_forces: no step since the state was restored or record_contacts was set; "
                "run a step first."
            ) from None

    @property
    def record_contacts(self) -> bool:
        """Whether a run keeps each contact's force for :meth:`contact_forces` (3 values per
        contact, 24 bytes; on unless set off)."""
        return self._core.recording

    @record_contacts.setter
    def record_contacts(self, on: bool) -> None:
        self._core.set_recording(bool(on))

    def kinetic_energy(self, types=None) -> tuple[float, float]:
        """Translational and rotational kinetic energy (J) of the free spheres and the clumps (of
        ``types`` only, if given)."""
        m, r = self._core.array("m"), self._core.array("r")
        v, w = self._core.array("v"), self._core.array("w")
        if self._core.nbody == 0 and types is None:
            return float(0.5 * np.sum(m * np.sum(v * v, axis=1))), float(
                0.2 * np.sum(m * r * r * np.sum(w * w, axis=1))
            )
        free = self._core.array("body") < 0
        found = self._core.bodies()
        if types is not None:
            free &= np.isin(self._core.array("type"), types)
            found = {key: value[np.isin(found["type"], types)] for key, value in found.items()}
        translation = 0.5 * np.sum(m[free] * np.sum(v[free] ** 2, axis=1))
        rotation = 0.2 * np.sum(m[free] * r[free] ** 2 * np.sum(w[free] ** 2, axis=1))
        translation += 0.5 * np.sum(found["m"] * np.sum(found["v"] ** 2, axis=1))
        rotation += 0.5 * np.sum(found["p"] ** 2 / found["inertia"])
        return float(translation), float(rotation)

    @property
    def memory(self) -> dict[str, int]:
        """Bytes the solver has allocated (capacity), by part: see ``Core.memory``."""
        return {part: int(size) for part, size in self._core.memory().items()}

    @property
    def memory_bytes(self) -> int:
        """Bytes the solver has allocated in all (:attr:`memory`)."""
        return sum(self.memory.values())

    @property
    def list_entries(self) -> tuple[int, int]:
        """Entries of the neighbour list (pairs within reach) and of the wall list."""
        pairs, walls = self._core.list_entries()
        return int(pairs), int(walls)

    @property
    def timings(self) -> dict:
        """Seconds spent in :meth:`run` so far, by phase (wall clock): ``run`` (all of it),
        ``drift`` (first half kicks not fused with the previous step, and passes measuring
        displacements), ``walls`` (moving the
        meshes), ``pairs`` (pair and wall forces), ``particles`` (summing them, gravity,
        viscous forces, integration, clumps' bodies, servo walls; with threads the two loops
        overlap, and ``pairs`` ends when the calling thread starts on the particles),
        ``rebuild`` and its parts ``rebuild_cells``, ``rebuild_sort``, ``rebuild_permute``,
        ``rebuild_count``, ``rebuild_fill``; the CPU seconds of each thread in the pair and
        particle loops (arrays ``pairs_cpu``, ``particles_cpu``, without waits), and the sum
        over steps of the busiest thread's CPU seconds in both (``forces_span``: a lower bound
        of their wall time on otherwise idle cores), and the steps the
        calling thread ran without the others, having found that faster (``solo_steps``: on
        a busy machine or a small system), how often a thread woken next to a teammate
        moved to a CPU of the team's that none was on (``moves``: on a busy machine), and how
        often the pair loop built its sublist of the pairs near contact (``sublist_builds``:
        hertz without rolling resistance skips the other listed pairs until a particle may
        have moved far enough to reach one), and of the steps, how many drifts measured each
        particle's displacement for the rebuild check (``measured_drifts``) and how many passes
        measured them after a drift that did not (``displacement_passes``; the other steps'
        speeds ruled a rebuild out). Not part of :meth:`get_state`."""
        return self._core.timings()

    @property
    def rebuilds(self) -> int:
        """Neighbour-list rebuilds so far."""
        return int(self._core.rebuilds)

    @property
    def grid(self) -> tuple[tuple[int, int, int], float, int]:
        """The last rebuild's cell grid: cells per axis, the largest radius they fit (``inf``:
        every particle's) and how many big particles search the cells within their reach
        (those over twice the smallest radius, when few)."""
        (nx, ny, nz), radius, big = self._core.grid
        return (int(nx), int(ny), int(nz)), float(radius), int(big)
