"""``DEM(engine='yade')``: maps the engine-neutral specs onto YADE, run in a worker process.

Contact models (pair values from the reference models of
:mod:`pygran_core.simulation.models`, so YADE integrates the same forces):

- ``HertzMindlin``: ``FrictMat`` (friction angle ``atan(mu)``),
  ``Ip2_FrictMat_FrictMat_MindlinPhys`` and ``Law2_ScGeom_MindlinPhys_Mindlin``: the
  reference's ``k_n = 4/3 E* a`` and ``k_t = 8 G* a``, damping ``2 beta_n sqrt(m* S_n)`` and
  ``2 beta_s sqrt(m* k_t)`` (``S_n = 2 E* a``; ``m*`` of a wall contact is the sphere's
  mass). Unlike the reference, YADE's law never lets the normal force turn attractive
  (it clamps it at zero), so ``beta_n`` is :func:`clamped_damping_ratio` of the pair
  restitution, with which the clamped law realises it (within 0.2 % for e >= 0.3), while
  ``beta_s`` is the reference's ``sqrt(5/6) |beta|``. The clamp ends a contact's force
  early and the sphere then coasts out of the overlap: contacts last longer than the
  reference's by a factor that depends on the restitution only (measured: 1.0099 at
  e = 0.5, 1.036 at 0.3, 1.074 at 0.2, 1.18 at 0.1; none at e = 1).
- ``SpringDashpot``: ``FrictViscoMat`` with ``Law2_ScGeom_FrictViscoPhys_CundallStrackVisco``
  (linear spring, unclamped normal dashpot): ``k_n`` per material pair from the
  reference model and ``betan = -beta``, so ``gamma_n = 2 |beta| sqrt(m* k_n)`` with YADE's
  pair mass; ``k_t = k_n``, no tangential dashpot. Stiffness depends on the radius, so each
  species must have one radius, and ``betan`` is per material, so all materials must
  share one restitution coefficient; otherwise :class:`UnsupportedFeature`.

Walls are fixed YADE facets met through ``Ig2_Facet_Sphere_ScGeom(hertzian=True)``, which
gives a facet a reference radius of 1e8 sphere radii, so a wall contact has the
reference's ``R* = R`` (without it a facet counts as ``2R``, so ``R* = 2R/3``; YADE's
``Box`` and ``Wall`` count as ``R``, so ``R* = R/2``). A plane is one large facet
(:func:`plane_triangle`), which also works in periodic domains, where YADE's ``Wall`` hangs
the collider: with ``allowBiggerThanPeriod`` a body wider than half the period meets each
sphere at the sphere's unwrapped position, and the collider sorts along a non-periodic
axis (its first sweep along a periodic one misses such pairs). A plane across a periodic
axis, and primitive walls in a domain periodic along every axis, are refused. Cylinders
are polygonal prisms of :data:`CYLINDER_SEGMENTS` facets (reaching :data:`PLANE_REACH`
lengths along a periodic axis); meshes are facets from their STL file (scaled, rotated
about the origin, translated). As everywhere in YADE, a sphere touching two facets across
a shared edge has a contact with each. Mesh motion through ``RotationEngine``,
``TranslationEngine`` or ``HarmonicMotionEngine``. Particle ids are YADE body ids plus
one. Forces include gravity, as LIGGGHTS reports them. After each piece of a run the worker
deletes the spheres that left a fixed boundary or whose position or velocity is no longer
finite, and reports them by face and speed (:meth:`YadeEngine._lost_since_last`).

Multisphere species are YADE clumps (``O.bodies.appendClumped``), one per particle, whose
mass, centre and inertia YADE integrates over the union of the spheres on a grid of
:data:`CLUMP_DISCRETIZATION` cells across, inserted and created as the engine's
:class:`~pygran_core.simulation.insertion.Inserter` places and counts clumps; extracts give
every sphere of a clump, as the LIGGGHTS engine's do. YADE has no rolling-resistance law
matching LIGGGHTS' (see the README), so no rolling-friction capability is declared.

Checkpoints hold the scene as YADE serializes it (``O.sceneToString``: bodies, interactions
with their shear histories, engines, clock), read back on resume after the script's calls
up to it have been replayed. The collider then lists the pairs not yet touching anew, which
changes the order forces are summed in: a resumed run agrees with an uninterrupted one to
rounding (about 1e-13 relative), not bitwise.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError, EngineError, ReadError, UnsupportedFeature
from pygran_core.simulation.calls import MotionSpec, SetSpec, ViscousSpec, WallSpec
from pygran_core.simulation.checkpoint import encode_text, state_entry, state_json
from pygran_core.simulation.engine import Engine, Handle, LostParticles
from pygran_core.simulation.insertion import Inserter, multisphere_templates
from pygran_core.simulation.models import SpringDashpot, mixing
from pygran_core.simulation.specs import SimulationSpec, given
from pygran_yade.client import Worker
from pygran_yade.worker import from_bytes, to_bytes

#: Sides of the polygonal prism that stands for a primitive cylinder wall.
CYLINDER_SEGMENTS = 96
#: How far plane walls, and cylinders along a periodic axis, reach: in domain lengths.
PLANE_REACH = 1e6
#: YADE integrates an overlapping clump's mass and inertia on a grid of this many cells across
#: its thinnest extent (``appendClumped(discretization=...)``): within 0.2 % of the union's.
CLUMP_DISCRETIZATION = 40
#: The worker's log, in the output directory.
WORKER_LOG = "yade.log"
#: Thornton et al., Powder Technol. 233 (2013) 30, table 2: coefficients h_1..h_10.
THORNTON_H = (
    -6.918798, -16.41105, 146.8049, -796.4559, 2928.711, -7206.864, 11494.29, -11342.18, 6276.757, -1489.915
)  # fmt: skip


def clamped_damping_ratio(e: float) -> float:
    """Normal damping ratio ``c_n / (2 sqrt(m* S_n))`` with which a Hertz contact whose
    force is clamped at zero (YADE's) has restitution ``e``: Thornton et al. (2013), eqs.
    B6 and B7, what YADE itself derives from ``en``."""
    if e >= 1.0:
        return 0.0
    alpha = e * sum(h * e**k for k, h in enumerate(THORNTON_H))
    return math.sqrt(1.0 / (1.0 - (1.0 + e) ** 2 * math.exp(alpha)) - 1.0)


def plane_triangle(axis: int, peq: float, box: np.ndarray, periodic: tuple[bool, ...]) -> np.ndarray:
    """The facet ``(1, 3, 3)`` that stands for the plane ``axis = peq``, centred on the domain.

    Along the plane's periodic axes (all of them in a non-periodic domain) it reaches
    :data:`PLANE_REACH` domain lengths; in a periodic domain, along a non-periodic axis it
    spans 3 lengths, less than half of YADE's cell there (``APERIODIC_CELL`` lengths), so
    that the collider's sweep along that axis finds it, and 2 lengths across the domain.
    Reaching far both ways: an equilateral triangle; one way: a long isosceles one.
    """
    lengths = box[:, 1] - box[:, 0]
    far = PLANE_REACH * float(lengths.max())
    reaches_far = [p or not any(periodic) for p in periodic]
    u, w = sorted((a for a in range(3) if a != axis), key=lambda a: not reaches_far[a])
    corners = np.tile(box.mean(axis=1), (3, 1))
    corners[:, axis] = peq
    if reaches_far[w]:
        angles = np.pi / 2 + 2 * np.pi / 3 * np.arange(3)
        corners[:, u] += 2 * far * np.cos(angles)
        corners[:, w] += 2 * far * np.sin(angles)
    else:  # 2 lengths[w] wide at the centroid, which is the domain's centre
        corners[:, u] += far * np.array([-1.0, -1.0, 2.0])
        corners[:, w] += 1.5 * lengths[w] * np.array([-1.0, 1.0, 0.0])
    return corners[None]


def cylinder_triangles(
    axis: str, centre: tuple[float, float], radius: float, span: tuple[float, float]
) -> np.ndarray:
    """The side of a polygonal prism of :data:`CYLINDER_SEGMENTS` sides along ``axis``."""
    along = "xyz".index(axis)
    across = [a for a in range(3) if a != along]
    angles = np.linspace(0, 2 * math.pi, CYLINDER_SEGMENTS + 1)
    ring = np.zeros((CYLINDER_SEGMENTS + 1, 3))
    ring[:, across[0]] = centre[0] + radius * np.cos(angles)
    ring[:, across[1]] = centre[1] + radius * np.sin(angles)
    low, high = ring.copy(), ring.copy()
    low[:, along], high[:, along] = span
    a, b, c, d = low[:-1], low[1:], high[1:], high[:-1]
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


class YadeEngine(Engine):
    """YADE driven in a worker process (see the module docstring for the mapping)."""

    name = "yade"
    #: Each round trip to YADE costs up to 40 ms (its run loop's polling), so fewer pieces.
    max_run_chunks = 20
    capabilities = frozenset(
        {
            "spring-dashpot",
            "hertz-mindlin",
            "periodic",
            "primitive-walls",
            "mesh-walls",
            "moving-mesh",
            "polydisperse",
            "pair-tables",
            "insert-by-rate",
            "threads",
            "raw-commands",
            "multisphere",
            "restart",
        }
    )

    def __init__(self, spec: SimulationSpec) -> None:
        super().__init__(spec)
        try:
            self.inserter = Inserter(self)
            self._templates = multisphere_templates(spec)
            restitution = self.material_table.pairs.get("coefficientRestitution", np.ones(1))
            if spec.model.kernel == "spring-dashpot" and len(set(restitution.ravel().tolist())) > 1:
                raise UnsupportedFeature(
                    "The yade engine runs SpringDashpot only when every material and pair has the same "
                    "coefficientRestitution (YADE's damping ratio is per material, not per pair)"
                )
        except BaseException:
            self._abandon()
            raise
        n = len(spec.species)
        # materials: species k -> k - 1; walls of species k -> n + k - 1; meshes with their own after
        self._mesh_material = {m.name: 2 * n + i for i, m in enumerate(m for m in spec.meshes if m.material)}
        materials = [s.material for s in spec.species] * 2 + [m.material for m in spec.meshes if m.material]
        densities = [s.density for s in spec.species] * 2 + [1.0] * len(self._mesh_material)
        self._radius_of = {s.type: s.radius for s in spec.species}
        worker = None
        try:  # a failure here leaves no worker, and the output folder free
            worker = self.worker = Worker(self.output / WORKER_LOG, spec.threads or 1)
            self.log("YADE %s worker, pid %d", worker.version, worker.process.pid)
            worker.call(
                "setup",
                model="hertz" if spec.model.kernel == "hertz-mindlin" else "linear",
                materials=[self._yade_material(i, rho) for i, rho in enumerate(densities)],
                matches=self._pairs(materials, n),
                gravity=spec.gravity.vector.tolist() if spec.gravity is not None else [0.0, 0.0, 0.0],
                box=[[float(v) for v in b] for b in spec.domain.box],
                periodic=[bool(p) for p in spec.domain.periodic],
                dt=self.dt or 1.0,
                # the skin is the distance pairs are listed ahead: each bound gets half of it
                verlet=spec.skin / 2 if spec.skin > 0 else None,
            )
            self.log("neighbour lists: skin %g m (verletDist %g m)", spec.skin, spec.skin / 2)
        except BaseException:
            if worker is not None:
                worker.close()
            self._abandon()
            raise
        self._labels = 0
        self._walls: dict[str, list[int]] = {}  # label -> facet ids
        self._mesh_walls: dict[str, str] = {}  # mesh name -> wall label
        self._motions: dict[str, str] = {}  # motion label -> mesh name
        self._engines: set[str] = set()  # labels of YADE engines (motions, drags)
        self._unreported = LostParticles()  # deleted by the worker since the last report

    # -- materials and contact model ------------------------------------------------------

    def _check_spec(self, spec: SimulationSpec) -> None:
        super()._check_spec(spec)  # the model's kernel: hertz-mindlin or spring-dashpot
        if spec.model.kernel == "spring-dashpot":
            if any(s.style == "multisphere" for s in spec.species):
                raise UnsupportedFeature(
                    "The yade engine runs multisphere species with HertzMindlin only: SpringDashpot's "
                    "reference stiffness depends on the particle's radius and mass, which a clump's "
                    "spheres do not share"
                )
            if any(s.radius.kind != "constant" for s in spec.species):
                raise UnsupportedFeature(
                    "The yade engine runs SpringDashpot only with one radius per species: YADE's linear "
                    "law takes one stiffness per material pair, and the reference stiffness depends "
                    "on the radius"
                )

    def _table_type(self, material: int) -> int:
        """The material-table type of YADE material ``material`` (a wall of species k is made
        of species k's material)."""
        n = len(self.spec.species)
        return material if material < n else material - n

    def _yade_material(self, material: int, density: float) -> dict[str, float]:
        table, kind = self.material_table, self._table_type(material)
        props = {
            "young": float(table.per_type["youngsModulus"][kind]),
            "poisson": float(table.per_type["poissonsRatio"][kind]),
            "density": density,
            "frictionAngle": math.atan(table.pairs["coefficientFriction"][kind, kind]),
        }
        if self.spec.model.kernel == "spring-dashpot":
            props["betan"] = float(mixing.damping_ratio(table.pairs["coefficientRestitution"][kind, kind]))
        return props

    def _pairs(self, materials: list[Any], n: int) -> dict[str, list[tuple[int, int, float]]]:
        """YADE's per-material-pair values, as ``{Ip2 attribute: [(i, j, value)]}``: the friction
        angle and the normal and tangential damping ratios (Hertz) or the normal stiffness
        (linear), from the material table's pairs."""
        species, table = self.spec.species, self.material_table
        values: dict[str, list[tuple[int, int, float]]] = {}
        for i in range(len(materials)):
            for j in range(min(i + 1, n)):  # j is always a species: walls never touch walls
                mi, mj = materials[i], materials[j]
                ti, tj = self._table_type(i), self._table_type(j)
                values.setdefault("frictAngle", []).append(
                    (i, j, math.atan(table.pairs["coefficientFriction"][ti, tj]))
                )
                if self.spec.model.kernel == "hertz-mindlin":
                    e = float(table.pairs["coefficientRestitution"][ti, tj])
                    betas = math.sqrt(5 / 6) * float(mixing.damping_ratio(e))
                    pair = {"betan": clamped_damping_ratio(e), "betas": betas}
                else:
                    mine = dict(mj, radius=species[j].radius.values[0], density=species[j].density)
                    partner = (
                        dict(mi, radius=species[i].radius.values[0], density=species[i].density)
                        if i < n
                        else mi
                    )
                    # the spring-dashpot kernel runs SpringDashpot's law, with its stiffness
                    pair = {"kn": SpringDashpot(mine, partner=partner).kn}
                for name, value in pair.items():
                    values.setdefault(name, []).append((i, j, float(value)))
        return values

    def _label(self, kind: str) -> str:
        self._labels += 1
        return f"{kind}{self._labels}"

    # -- particles ---------------------------------------------------------------------

    def _add_spheres(
        self, species: np.ndarray, centres: np.ndarray, radii: np.ndarray, velocities: np.ndarray, omega: Any
    ) -> None:
        for kind in np.unique(species):  # one YADE material per species
            chosen = np.asarray(species) == kind
            self.worker.call(
                "spheres",
                centres=to_bytes(np.asarray(centres, float)[chosen]),
                radii=to_bytes(np.asarray(radii, float)[chosen]),
                velocities=to_bytes(np.asarray(velocities, float)[chosen]),
                omegas=to_bytes(np.tile(np.asarray(omega, float), (int(chosen.sum()), 1))),
                material=int(kind) - 1,
                species=int(kind),
            )

    def _add_clumps(
        self,
        species: int,
        origins: np.ndarray,
        orientations: np.ndarray,
        velocities: np.ndarray,
        omega: Sequence[float],
    ) -> None:
        self.worker.call(
            "clumps",
            centres=to_bytes(np.asarray(origins, float)),
            orientations=to_bytes(np.asarray(orientations, float)),
            template=to_bytes(self._templates[species]),
            velocities=to_bytes(np.asarray(velocities, float)),
            omegas=to_bytes(np.tile(np.asarray(omega, float), (len(origins), 1))),
            material=species - 1,
            species=species,
            discretization=CLUMP_DISCRETIZATION,
        )

    def bodies(self) -> np.ndarray:
        """The clump of each sphere, ordered by id as :meth:`extract`: the clump's YADE body id
        plus one for the spheres of multisphere particles, -1 for single spheres (as the
        LIGGGHTS engine's ``bodies()``; extracts give every sphere of a clump)."""
        self._check_open()
        return self._extract("body")

    def clumps(self) -> dict[str, np.ndarray]:
        """Every clump's ``id`` (as :meth:`bodies`), ``mass``, ``centre`` and ``inertia`` tensor
        about its centre in the world frame ``(n, 3, 3)``, as YADE computed them."""
        self._check_open()
        found = {key: from_bytes(value) for key, value in self.worker.call("clump_properties").items()}
        found["id"] = found["id"] + 1
        return found

    def _assign(self, ids: np.ndarray, spec: SetSpec) -> None:
        types = self._extract("type")[np.isin(self._extract("id"), ids)]
        bodies = sorted({int(t) for t in types if self.spec.species[int(t) - 1].style == "multisphere"})
        if bodies:
            raise UnsupportedFeature(
                f"set() on the spheres of multisphere species {bodies}: they move with their clumps; "
                "select the species of single spheres (species=...)"
            )
        self.worker.call(
            "assign",
            ids=to_bytes(np.asarray(ids, np.int64) - 1),  # YADE body ids count from 0
            velocity=None if spec.velocity is None else [float(v) for v in spec.velocity],
            omega=None if spec.omega is None else [float(v) for v in spec.omega],
            radius=spec.radius,
        )

    # -- walls and meshes ----------------------------------------------------------------

    def _wall(self, spec: WallSpec) -> str:
        label = self._label("wall")
        box = np.array(self.spec.domain.box, float)
        material = len(self.spec.species) + spec.species - 1
        periodic = self.spec.domain.periodic
        if spec.kind != "mesh" and all(periodic):
            raise self._unsupported("primitive walls in a domain periodic along every axis")
        if spec.kind == "plane":
            if spec.plane is None or spec.peq is None:
                raise ConfigError(f"a plane wall needs plane and peq: {spec}")
            axis = "xyz".index(spec.plane[0])
            if periodic[axis]:
                raise self._unsupported("a plane wall across a periodic axis")
            triangles = plane_triangle(axis, spec.peq, box, periodic)
        elif spec.kind == "cylinder":
            if spec.axis is None or spec.centre is None or spec.radius is None:
                raise ConfigError(f"a cylinder wall needs axis, centre and radius: {spec}")
            along = "xyz".index(spec.axis)
            span = box[along]
            if periodic[along]:
                span = span + PLANE_REACH * (span[1] - span[0]) * np.array([-1.0, 1.0])
            triangles = cylinder_triangles(spec.axis, spec.centre, spec.radius, tuple(span))
        else:
            mesh = next(m for m in self.spec.meshes if m.name == spec.mesh)
            if mesh.name in self._mesh_walls:
                raise ConfigError(f"mesh {mesh.name!r} is already a wall")
            triangles = mesh.triangles()
            material = self._mesh_material.get(mesh.name, material)
            self._mesh_walls[mesh.name] = label
        self._walls[label] = self.worker.call("facets", triangles=to_bytes(triangles), material=material)
        return label

    def _move_mesh(self, spec: MotionSpec) -> str:
        if spec.mesh not in self._mesh_walls:
            raise ConfigError(
                f"mesh {spec.mesh!r} is not a wall yet: "
                f"call setupWall(wtype='mesh', mesh={spec.mesh!r}) first"
            )
        if spec.mesh in self._motions.values():
            raise ConfigError(f"mesh {spec.mesh!r} already moves; remove() that motion first")
        label = self._label("motion")
        kind, params = {
            "rotate": ("rotate", {"axis": spec.axis, "omega": spec.omega, "origin": spec.origin}),
            "linear": ("translate", {"velocity": spec.velocity}),
            "wiggle": ("wiggle", {"amplitude": spec.amplitude, "period": spec.period}),
        }[spec.kind]
        self.worker.call(
            "motion", label=label, kind=kind, ids=self._walls[self._mesh_walls[spec.mesh]], params=params
        )
        self._motions[label] = spec.mesh
        self._engines.add(label)
        return label

    def _viscous(self, spec: ViscousSpec) -> str:
        clumps = [k for k in spec.species if k in self._templates]
        if clumps:
            raise self._unsupported(
                f"addViscous on multisphere species {clumps} (YADE's LinearDragEngine drags single bodies)"
            )
        if any(self._radius_of[s].kind in ("normal", "lognormal") for s in spec.species):
            raise self._unsupported(
                "addViscous on a continuous size distribution (YADE's LinearDragEngine scales with the "
                "radius, so each radius needs its own engine)"
            )
        label = self._label("viscous")
        self.worker.call("drag_force", label=label, gamma=spec.gamma * spec.scale, species=list(spec.species))
        self._engines.add(label)
        return label

    def _remove(self, handle: Handle) -> None:
        label = handle.label
        if label in self._walls:
            self.worker.call("erase", ids=self._walls.pop(label))
            for mesh in [name for name, wall in self._mesh_walls.items() if wall == label]:
                del self._mesh_walls[mesh]
                for motion in [k for k, name in self._motions.items() if name == mesh]:
                    self._remove_engine(motion)
        elif label in self._engines:
            self._remove_engine(label)

    def _remove_engine(self, label: str) -> None:
        self.worker.call("remove_engine", label=label)
        self._engines.discard(label)
        self._motions.pop(label, None)

    def _command(self, text: str) -> None:
        self.worker.call("command", text=text)

    # -- running and output ----------------------------------------------------------------

    def _default_dt(self) -> float:
        """A fifth of YADE's p-wave estimate (``utils.PWaveTimeStep``) for the particles
        present, logged."""
        dt = 0.2 * float(self.worker.call("scalar", quantity="pwave_dt"))
        self.log("no time step given: using 0.2 x PWaveTimeStep = %g s", dt)
        return dt

    def _advance(self, nsteps: int) -> None:
        self._unreported += LostParticles(**self.worker.call("run", nsteps=nsteps, dt=self.dt))

    def _lost_since_last(self) -> LostParticles:
        """The spheres the worker deleted after each piece of a run (see ``Simulation.run``)."""
        lost, self._unreported = self._unreported, LostParticles()
        return lost

    def _extract(self, quantity: str) -> np.ndarray:
        return from_bytes(self.worker.call("extract", quantity=quantity))

    def _scalar(self, quantity: str) -> float:
        if quantity in ("contacts", "ke", "ke_rot"):  # a clump's energy is its own, not its spheres'
            return float(self.worker.call("scalar", quantity=quantity))
        return super()._scalar(quantity)

    def _mesh_triangles(self, name: str) -> np.ndarray | None:
        if name not in self._mesh_walls:
            return None
        return from_bytes(self.worker.call("facet_vertices", ids=self._walls[self._mesh_walls[name]]))

    # -- checkpoints ----------------------------------------------------------------------

    def _state(self) -> dict[str, np.ndarray]:
        """YADE's own serialization of the scene, the worker's bookkeeping (see
        ``Simulation.save``) and each wall's facets: a replayed script creates no particles,
        so the walls it makes again get other body ids than those of the scene read back."""
        saved = self.worker.call("save")
        return {
            "yade/scene": np.frombuffer(saved["scene"], np.uint8).copy(),
            "yade/book": encode_text(json.dumps(saved["book"])),
            "yade/walls": encode_text(json.dumps(self._walls)),
        }

    def _restore_state(self, state: dict[str, np.ndarray]) -> None:
        path = given(self.journal.path, "the checkpoint's file")
        scene = state_entry(path, state, "yade/scene", "u", (None,)).tobytes()
        walls = state_json(path, state, "yade/walls", dict)
        book = state_json(path, state, "yade/book", dict)
        if not all(isinstance(ids, list) and all(isinstance(i, int) for i in ids) for ids in walls.values()):
            raise ReadError(f"{path}: the state entry 'yade/walls' does not map each wall to its body ids")
        try:
            self.worker.call("load", scene=scene, book=book)
        except EngineError as exc:
            raise ReadError(f"{path}: YADE cannot read the scene back: {exc}") from None
        self._walls = walls

    def _close(self) -> None:
        self.worker.close()
