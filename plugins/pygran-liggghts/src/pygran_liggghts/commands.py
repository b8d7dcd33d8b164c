"""LIGGGHTS input lines generated from PyGran's engine-neutral specs.

:class:`Commands` turns a :class:`~pygran_core.simulation.specs.SimulationSpec` and the
per-call specs into LIGGGHTS 3.x commands. Ids of fixes, regions, groups and dumps are
``pg_<kind><n>`` with one counter per simulation, so the same calls always give the same
input. Materials become ``fix property/global`` tables built with PyGran's shared mixing
rules; paths are absolute (quoted where LIGGGHTS would misread them, see
:meth:`Commands.path`; those it cannot name are refused), so the saved input reruns anywhere
with the ``liggghts`` binary.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ConfigError, UnsupportedFeature, unknown_key
from pygran_core.simulation.calls import (
    InsertSpec,
    MotionSpec,
    Region,
    ViscousSpec,
    WallSpec,
)
from pygran_core.simulation.materials import MaterialTable
from pygran_core.simulation.specs import (
    RadiusDistribution,
    ServoSpec,
    SimulationSpec,
    command_path,
    given,
)
from pygran_liggghts.library import ADDON_MODEL

#: Contact-model kernel (``ContactModel.kernel``) -> LIGGGHTS' ``gran model`` (Thornton-Ning:
#: PyGran's add-on, :data:`~pygran_liggghts.library.ADDON_MODEL`; LIGGGHTS' own
#: ``thornton_ning`` is another law).
MODELS = {"spring-dashpot": "hooke", "hertz-mindlin": "hertz", "thornton-ning": ADDON_MODEL}
#: LIGGGHTS ``rolling_friction`` model -> the material keys it reads besides
#: ``coefficientRollingFriction`` (``epsd3`` also reads the global ``coeffRollingStiffness``,
#: which PyGran's materials do not carry).
ROLLING = {
    "cdt": (),
    "epsd": ("coefficientRollingViscousDamping",),
    "epsd2": (),
    "epsd3": ("coefficientRollingViscousDamping", "coeffRollingStiffness"),
}
#: Size classes a normal or lognormal radius distribution is discretised into (LIGGGHTS
#: 3.x particle templates have one radius each).
SIZE_CLASSES = 9
#: Particle columns LIGGGHTS ``dump custom`` writes.
DUMP_COLUMNS = frozenset(
    "id type x y z vx vy vz fx fy fz omegax omegay omegaz tqx tqy tqz radius mass density".split()
)


def fmt(value: float) -> str:
    """A number as LIGGGHTS reads it back exactly."""
    return repr(float(value)) if not float(value).is_integer() else str(int(value))


def prime(seed: int, offset: int = 0) -> int:
    """A prime above 10000 derived from ``seed`` (LIGGGHTS' random seeds must be such primes)."""
    candidate = 10007 + (seed + 7919 * offset) % 1_000_000
    while any(candidate % d == 0 for d in range(2, math.isqrt(candidate) + 1)):
        candidate += 1
    return candidate


def size_classes(radius: RadiusDistribution) -> list[tuple[float, float]]:
    """``(radius, number fraction)`` classes of a distribution.

    Constant and ``poly`` distributions are exact; ``normal`` and ``lognormal`` ones (cut
    at 3 sigma) become :data:`SIZE_CLASSES` classes of equal width (in r, resp. ln r),
    each at its centre with the probability of its interval.
    """
    if radius.kind == "constant":
        return [(radius.values[0], 1.0)]
    if radius.kind == "poly":
        return list(zip(radius.values, radius.weights))
    centre, spread = radius.values
    if spread == 0:
        return [(centre, 1.0)]
    edges = np.linspace(-3.0, 3.0, SIZE_CLASSES + 1)
    cdf = np.array([0.5 * (1 + math.erf(e / math.sqrt(2))) for e in edges])
    weights = np.diff(cdf) / (cdf[-1] - cdf[0])
    mids = 0.5 * (edges[1:] + edges[:-1])
    radii = centre + spread * mids if radius.kind == "normal" else centre * np.exp(spread * mids)
    return [(float(r), float(w)) for r, w in zip(radii, weights)]


#: Paths LIGGGHTS reads as they are; others are quoted (:meth:`Commands.path`).
PLAIN_PATH = re.compile(r"[\w./+,:=@~-]+")


#: Every region's ``volume_limit`` (m^3): LIGGGHTS' default, 1e-10, refuses to insert into
#: regions smaller than a 0.47 mm cube; this is the original PyGran's.
VOLUME_LIMIT = 1e-20
#: The groups of atoms integrated by ``fix nve/sphere`` and by ``fix multisphere`` (when the
#: simulation has multisphere species).
SPHERES, BODIES = "pg_spheres", "pg_bodies"
#: The computes of the bodies' kinetic energies (monitor quantity -> compute id).
BODY_ENERGY = {"ke": "pg_body_ke", "ke_rot": "pg_body_erotate"}
#: Monte Carlo samples of ``particletemplate/multisphere`` for a body's mass, centre and
#: inertia (LIGGGHTS warns below 1e5).
MONTE_CARLO_TRIES = 1_000_000
#: LIGGGHTS' computes of the contact records (``traj`` ``cfile``): id -> style and keywords.
CONTACT_COMPUTES = {
    "pg_pairs": "pair/gran/local pos id force contactPoint",
    "pg_walls": "wall/gran/local pos id force",
}
#: Where LIGGGHTS writes them (``dump local``, a file per frame), under the output directory.
CONTACTS_DIR = "liggghts-contacts"
#: LIGGGHTS refuses Young's moduli below this (SI) unless told ``soft_particles yes``.
SOFT_LIMIT = 5e6
#: ... and above this unless told ``hard_particles yes``.
HARD_LIMIT = 1e9


class ContactLaw:
    """The contact law of ``spec`` on the material ``table`` as LIGGGHTS writes it: its model
    name, rolling friction model (the model's ``rolling``, default the original PyGran's
    ``cdt``), whether forces are limited and whether the materials give cohesion and rolling
    friction. Combinations LIGGGHTS cannot run are refused here."""

    def __init__(self, spec: SimulationSpec, table: MaterialTable) -> None:
        self.table = table
        self.model = MODELS[given(spec.model.kernel, "the contact model's kernel")]  # others refused
        self.rolling_model = getattr(spec.model, "rolling", "cdt")
        if self.rolling_model not in ROLLING:
            raise unknown_key("rolling-friction model", str(self.rolling_model), ROLLING)
        self.limit_force = bool(getattr(spec.model, "limit_force", False))
        self.cohesion = bool(table.pairs["cohesionEnergyDensity"].any())
        self.rolling = bool(table.pairs["coefficientRollingFriction"].any())
        if self.rolling and "coeffRollingStiffness" in ROLLING[self.rolling_model]:
            raise UnsupportedFeature(
                f"LIGGGHTS' rolling_friction {self.rolling_model} needs coeffRollingStiffness, which "
                "PyGran's materials do not carry; use rolling='epsd' (its stiffness prefactor is 2.25)"
            )
        if self.model == ADDON_MODEL and self.rolling and self.cohesion:
            raise UnsupportedFeature(
                "ThorntonNing with adhesion (cohesionEnergyDensity) and rolling friction together on "
                "LIGGGHTS: its rolling_friction models act only while the bodies overlap, and the adhesive "
                "neck pulls on them after they have parted; drop one of the two, or run on the native engine"
            )

    @property
    def granular(self) -> str:
        """The ``model ...`` arguments shared by ``pair_style gran`` and ``fix wall/gran``."""
        words = f"model {self.model} tangential history"
        if self.cohesion and self.model != ADDON_MODEL:  # Thornton-Ning's adhesion is its own (JKR)
            words += " cohesion sjkr"
        if self.rolling:
            words += f" rolling_friction {self.rolling_model}"
        if self.limit_force:
            words += " limitForce on"
        return words

    def tables(self) -> list[str]:
        """``fix property/global`` tables of the material table's types and pairs that the
        model reads."""
        table, n = self.table, self.table.size

        def pairs(key: str) -> str:
            values = table.pairs[key]
            return f"fix pg_{key} all property/global {key} peratomtypepair {n} " + " ".join(
                fmt(v) for v in values.ravel()
            )

        def per_type(key: str) -> str:
            values = table.per_type[key]
            return f"fix pg_{key} all property/global {key} peratomtype " + " ".join(fmt(v) for v in values)

        lines = [per_type("youngsModulus"), per_type("poissonsRatio"), pairs("coefficientFriction")]
        # Thornton-Ning dissipates by plasticity and adhesion hysteresis, without damping
        lines.append(pairs("yieldPress" if self.model == ADDON_MODEL else "coefficientRestitution"))
        if self.cohesion or self.model == ADDON_MODEL:
            lines.append(pairs("cohesionEnergyDensity"))
        if self.rolling:
            lines.append(pairs("coefficientRollingFriction"))
            if "coefficientRollingViscousDamping" in ROLLING[self.rolling_model]:
                lines.append(pairs("coefficientRollingViscousDamping"))
        if self.model == "hooke":
            velocities = set(table.per_type["characteristicVelocity"].tolist())
            if len(velocities) > 1:
                raise ConfigError(
                    "LIGGGHTS' hooke model takes one characteristicVelocity; "
                    f"the materials give {sorted(velocities)}"
                )
            lines.append(
                f"fix pg_characteristicVelocity all property/global characteristicVelocity scalar "
                f"{fmt(velocities.pop())}"
            )
        return lines


class Commands:
    """LIGGGHTS commands for one simulation; each method returns ``(id, lines)`` or lines."""

    def __init__(self, spec: SimulationSpec, table: MaterialTable) -> None:
        self.spec = spec
        self.table = table
        self._counter = itertools.count(1)
        self.check_paths()
        self.law = ContactLaw(spec, table)
        self.mesh_ids: dict[str, str] = {}
        #: Atom type (1-based) of each mesh: its own material's, else species 1's (a wall of
        #: another species is refused in :meth:`wall`).
        self.mesh_types: dict[str, int] = {}
        self.bare_meshes = {mesh.name for mesh in spec.meshes if not mesh.material}
        for mesh in spec.meshes:
            self.mesh_ids[mesh.name] = self.new_id("mesh")
            self.mesh_types[mesh.name] = table.mesh_types.get(mesh.name, 0) + 1
        if not spec.species:
            raise ConfigError("LIGGGHTS needs at least one species: pass species=({'material': ...},)")
        #: Atom types of the multisphere species (rigid clumps of spheres) and of the others.
        self.body_types = [s.type for s in spec.species if s.style == "multisphere"]
        self.sphere_types = [s.type for s in spec.species if s.style != "multisphere"]

    def new_id(self, kind: str) -> str:
        return f"pg_{kind}{next(self._counter)}"

    def path(self, path: Path) -> str:
        """``path`` as a word of a LIGGGHTS input line: as it is when plain, else in quotes
        (spaces, ``#``, ``&``, one kind of quote). The paths of the simulation were checked
        when it was made (:meth:`check_paths`); others are checked here."""
        text = str(command_path(path, "path"))
        if PLAIN_PATH.fullmatch(text):
            return text
        quote = '"' if '"' not in text else "'"
        return f"{quote}{text}{quote}"

    def check_paths(self) -> None:
        """Refuse, naming the keyword, a path of the simulation LIGGGHTS' input cannot name
        (see :func:`~pygran_core.simulation.specs.command_path`): the saved ``in.pygran``
        must rerun as the live run ran, writing where it wrote."""
        spec = self.spec
        command_path(spec.output, "output", patterns=True, folder=True)
        for mesh in spec.meshes:
            command_path(mesh.file, f"mesh {mesh.name!r} file")
        for key in ("pfile", "mfile"):
            path = getattr(spec.traj, key)
            if path is not None:
                command_path(path, f"traj {key}", patterns=True)
        if spec.restart is not None:
            command_path(spec.restart.directory, "restart dir", patterns=True, folder=True)
            command_path(spec.restart.directory / spec.restart.fname, "restart fname", patterns=True)

    # -- the simulation ------------------------------------------------------------------

    def setup(self, resume: Path | None = None) -> list[str]:
        """Box, materials, contact model, gravity, integrator, meshes and dumps."""
        spec = self.spec
        # atom sorting's bin is half the neighbour cut-off, given here since with no atoms and no
        # insertion yet LIGGGHTS sees a zero cut-off and refuses to run ("bin size = 0.0")
        sort_bin = spec.max_radius + spec.skin / 2
        sort = f" sort 1000 {fmt(sort_bin)}" if sort_bin > 0 else ""
        lines = ["units si", "atom_style granular", f"atom_modify map array{sort}"]
        moduli = self.table.per_type["youngsModulus"]
        # LIGGGHTS refuses moduli outside 5 MPa - 1 GPa in SI units unless told
        if min(moduli) < SOFT_LIMIT:
            lines.append("soft_particles yes")
        if max(moduli) > HARD_LIMIT:
            lines.append("hard_particles yes")
        lines.append("newton off")  # granular pairs with history need it; restart files omit it
        if resume is None:
            bounds = " ".join(fmt(v) for lo_hi in spec.domain.box for v in lo_hi)
            lines += [
                f"boundary {' '.join(spec.domain.boundary)}",
                f"region pg_domain block {bounds} units box volume_limit {fmt(VOLUME_LIMIT)}",
                f"create_box {self.table.size} pg_domain",
            ]
        else:
            lines.append(f"read_restart {self.path(resume)}")
        lines += [
            "communicate single vel yes",
            f"neighbor {fmt(spec.skin)} {spec.nns_type}",
            "neigh_modify delay 0",
            "thermo_style custom step atoms ke",
            "thermo_modify lost warn norm no",  # counted by the worker, reported by the front end
            "compute_modify thermo_temp dynamic yes",
            *self.law.tables(),
            f"pair_style gran {self.law.granular}",
            "pair_coeff * *",
        ]
        if spec.dt is not None:
            lines.append(f"timestep {fmt(spec.dt)}")
        if spec.gravity is not None and spec.gravity.magnitude > 0:
            direction = " ".join(fmt(d) for d in spec.gravity.direction)
            lines.append(f"fix pg_gravity all gravity {fmt(spec.gravity.magnitude)} vector {direction}")
        lines += self._integrators()
        if spec.species:
            # LIGGGHTS stops ('Atom types must start from 1') when neither an atom nor a fix has
            # type 1, e.g. with particles of species 2 only: this unused template has it
            first = spec.species[0]
            volume = 4 / 3 * math.pi * first.radius.max**3
            lines += [
                f"fix pg_type1 all particletemplate/sphere {prime(spec.seed, 700)} atom_type 1 "
                f"density constant {fmt(first.density)} radius constant {fmt(first.radius.max)} "
                f"volume_limit {fmt(volume / 10)}",
                f"fix pg_types all particledistribution/discrete {prime(spec.seed, 701)} 1 pg_type1 1",
            ]
        for mesh in spec.meshes:
            placement = f" scale {fmt(mesh.scale)}" if mesh.scale != 1 else ""
            if mesh.rotate is not None:
                axis, angle = mesh.rotate
                placement += f" rotate axis {' '.join(fmt(a) for a in axis)} angle {fmt(angle)}"
            if any(mesh.translate):
                placement += f" move {' '.join(fmt(t) for t in mesh.translate)}"
            lines.append(
                f"fix {self.mesh_ids[mesh.name]} all {mesh.mtype} file {self.path(mesh.file)} "
                f"type {self.mesh_types[mesh.name]}{placement}{servo_words(mesh.servo)}"
            )
        return lines + self._dumps(append=resume is not None)

    def _integrators(self) -> list[str]:
        """``fix nve/sphere`` for every atom; with multisphere species, for the group of the
        other species' atoms only, and ``fix multisphere`` for the group of the bodies' atoms,
        with one ``particletemplate/multisphere`` per multisphere species (LIGGGHTS wants the
        templates in the group of ``fix multisphere``, numbered 1, 2, ...). Atoms join the
        groups through their templates when inserted, through :meth:`regroup` when created."""
        if not self.body_types:
            return ["fix pg_integrate all nve/sphere"]
        lines = []
        if self.sphere_types:
            lines += [self.regroup(), f"fix pg_integrate {SPHERES} nve/sphere"]
        lines += [
            f"group {BODIES} type {' '.join(map(str, self.body_types))}",
            f"fix pg_multisphere {BODIES} multisphere allow_group_and_set yes",
            f"compute {BODY_ENERGY['ke']} all ke/multisphere",
            f"compute {BODY_ENERGY['ke_rot']} all erotate/multisphere",
        ]
        for number, index in enumerate(self.body_types, start=1):
            species = self.spec.species[index - 1]
            smallest = min(r for *_, r in species.spheres)
            spheres = " ".join(fmt(v) for sphere in species.spheres for v in sphere)
            lines.append(
                f"fix {shape_id(index)} {BODIES} particletemplate/multisphere "
                f"{prime(self.spec.seed, 500 + index)} atom_type {index} "
                f"density constant {fmt(species.density)} "
                f"volume_limit {fmt(4 / 3 * math.pi * smallest**3 / 10)} nspheres {len(species.spheres)} "
                f"ntry {MONTE_CARLO_TRIES} spheres {spheres} type {number}"
            )
        return lines

    def regroup(self) -> str:
        """The line adding the atoms of the species other than multisphere ones to the group
        ``fix nve/sphere`` integrates (with multisphere species)."""
        return f"group {SPHERES} type {' '.join(map(str, self.sphere_types))}"

    def _dumps(self, append: bool = False) -> list[str]:
        """Particle and mesh dumps; ``append`` continues a particle dump (on resume)."""
        traj, lines = self.spec.traj, []
        if traj.pfile is not None and native_particles(self.spec):
            unknown = [a for a in traj.args if a not in DUMP_COLUMNS]
            if unknown:
                raise ConfigError(
                    f"traj args {unknown} are not LIGGGHTS dump custom columns: {sorted(DUMP_COLUMNS)}"
                )
            traj.pfile.parent.mkdir(parents=True, exist_ok=True)
            columns = traj.args + (("mol",) if self.body_types else ())  # the body of each sphere
            lines.append(f"dump pg_dump all custom {traj.freq} {self.path(traj.pfile)} {' '.join(columns)}")
            if traj.sel != "all":  # chosen at every frame: a group would miss particles inserted later
                lines.append(f"dump_modify pg_dump thresh type == {traj.sel}")
            if traj.dump_modify:  # the script's words, on one line: ('append', 'yes') or ('sort id',)
                lines.append(f"dump_modify pg_dump {' '.join(traj.dump_modify)}")
            if append and "*" not in traj.pfile.name:
                lines.append("dump_modify pg_dump append yes")
        if traj.mfile is not None and native_meshes(self.spec):
            traj.mfile.parent.mkdir(parents=True, exist_ok=True)
            lines.append(
                f"dump pg_mesh_dump all mesh/vtk {traj.freq} {self.path(traj.mfile)} {' '.join(traj.margs)}"
            )
        if traj.cfile is not None:
            lines += self.contacts("pg_pairs")
        return lines

    def contacts(self, compute: str) -> list[str]:
        """The compute ``compute`` of :data:`CONTACT_COMPUTES` and its ``dump local``, a file per
        frame in :data:`CONTACTS_DIR`, every number written exactly (LIGGGHTS defines it before
        the first run only; wall contacts need the fix of the mesh walls first)."""
        style = CONTACT_COMPUTES[compute]
        width = 15 if compute == "pg_pairs" else 12
        folder = self.spec.output / CONTACTS_DIR
        folder.mkdir(parents=True, exist_ok=True)
        columns = " ".join(f"c_{compute}[{k}]" for k in range(1, width + 1))
        exact = " ".join(["%.17g"] * width)
        files = self.path(folder / f"{compute}.*.dump")
        return [
            f"compute {compute} all {style}",
            f"dump {compute} all local {self.spec.traj.freq} {files} {columns}",
            f'dump_modify {compute} format "{exact}"',
        ]

    # -- calls -----------------------------------------------------------------------------

    def region(self, region: Region) -> tuple[str, list[str]]:
        """The id of ``region`` and the commands defining it (an intersection's parts first).
        The inside of a mesh is the primitive region its geometry builder inscribed in it
        (LIGGGHTS has no region inside a triangle mesh)."""
        if region.kind == "mesh":
            surface = region.args[0]
            if surface.inscribed is None:
                raise UnsupportedFeature(
                    f"LIGGGHTS inserts into primitive regions only, and mesh {surface.name!r} has no "
                    "primitive inscribed in it: build the mesh with simulation.geometry (drum, box, "
                    "cylinder with caps), whose surfaces carry one, or place the particles with "
                    "createParticles(species, 'random', count, region=...), which takes any closed mesh"
                )
            kind, *args = surface.inscribed
            return self.region(Region(kind, tuple(args)))
        lines: list[str] = []
        if region.kind == "intersect":
            ids = []
            for part in region.args:
                part_id, part_lines = self.region(part)
                ids.append(part_id)
                lines += part_lines
            args = f"{len(ids)} {' '.join(ids)}"
        else:
            args = " ".join(a if isinstance(a, str) else fmt(a) for a in region.args)
        rid = self.new_id("region")
        lines.append(f"region {rid} {region.kind} {args} units box volume_limit {fmt(VOLUME_LIMIT)}")
        return rid, lines

    def _templates(
        self, species: Sequence[int], weights: Sequence[float], seed: int
    ) -> tuple[str, list[str]]:
        """Particle templates of ``species`` (number fractions ``weights``) and their
        distribution: by mass as LIGGGHTS weighs templates, or, with multisphere species (whose
        mass LIGGGHTS computes), ``particledistribution/discrete/numberbased``."""
        lines, parts = [], []
        by_number = any(index in self.body_types for index in species)
        group = SPHERES if self.body_types else "all"
        for k, (index, weight) in enumerate(zip(species, weights)):
            sp = self.spec.species[index - 1]
            if index in self.body_types:
                parts.append((shape_id(index), weight))
                continue
            for j, (radius, fraction) in enumerate(size_classes(sp.radius)):
                tid = self.new_id("template")
                volume = 4 / 3 * math.pi * radius**3
                lines.append(
                    f"fix {tid} {group} particletemplate/sphere {prime(seed, 10 * k + j + 1)} "
                    f"atom_type {index} density constant {fmt(sp.density)} radius constant {fmt(radius)} "
                    f"volume_limit {fmt(volume / 10)}"
                )
                parts.append((tid, weight * fraction * (1 if by_number else sp.density * radius**3)))
        total = sum(w for _, w in parts)
        did = self.new_id("distribution")
        entries = " ".join(f"{tid} {fmt(w / total)}" for tid, w in parts if w > 0)
        count = sum(1 for _, w in parts if w > 0)
        style = "particledistribution/discrete" + ("/numberbased" if by_number else "")
        lines.append(f"fix {did} all {style} {prime(seed)} {count} {entries}")
        return did, lines

    @staticmethod
    def insert_every(spec: InsertSpec, dt: float | None) -> int | None:
        """Steps between the insertions of ``spec`` (``None``: once, by pack): its ``freq``; by
        rate without it, every :data:`~pygran_core.simulation.insertion.RATE_INTERVAL` as other
        engines."""
        if spec.mechanism == "by_rate" and spec.freq is None:
            if dt is None:
                raise ConfigError("Insertion by rate needs the time step: pass dt=... to DEM before insert()")
            from pygran_core.simulation.insertion import RATE_INTERVAL

            return max(1, round(RATE_INTERVAL / dt))
        return spec.freq

    def insert(self, spec: InsertSpec, dt: float | None) -> tuple[str, list[str]]:
        """``fix insert/pack`` or ``fix insert/rate/region``, inserting every
        :meth:`insert_every` steps from the next step on."""
        every = self.insert_every(spec, dt)
        distribution, lines = self._templates(spec.species, spec.weights, spec.seed)
        rid, region = self.region(spec.region)
        lines += region
        iid = self.new_id("insert")
        vel = spec.velocity
        velocity = " ".join(fmt(v) for v in (*vel.mean, *(vel.spread if vel.kind != "constant" else ())))
        common = (
            f"seed {prime(spec.seed, 99)} distributiontemplate {distribution} "
            f"vel {vel.kind} {velocity} omega constant {' '.join(fmt(w) for w in spec.omega)} "
            f"overlapcheck yes all_in {'yes' if spec.all_in else 'no'}"
        )
        if isinstance(spec.orientation, str):
            common += f" orientation {spec.orientation}"
        elif spec.orientation is not None:
            common += f" orientation constant {' '.join(map(fmt, spec.orientation))}"
        if spec.mechanism == "by_pack":
            amount = int(spec.value) if spec.target == "particles_in_region" else fmt(spec.value)
            lines.append(
                f"fix {iid} all insert/pack {common} insert_every {every or 'once'} {spec.target} {amount} "
                f"region {rid}"
            )
            return iid, lines
        if spec.target == "particlerate":
            total = "INF" if spec.duration is None else str(max(1, round(spec.value * spec.duration)))
            amount = f"nparticles {total} particlerate {fmt(spec.value)}"
        else:
            total = "INF" if spec.duration is None else fmt(spec.value * spec.duration)
            amount = (
                f"{'nparticles INF' if spec.duration is None else f'mass {total}'} massrate {fmt(spec.value)}"
            )
        lines.append(f"fix {iid} all insert/rate/region {common} insert_every {every} {amount} region {rid}")
        return iid, lines

    def wall(self, spec: WallSpec) -> tuple[str, list[str]]:
        """A primitive wall's fix; a mesh wall only gets its id and is checked here (all mesh
        walls share one fix, see :meth:`mesh_walls`)."""
        wid = self.new_id("wall")
        if spec.kind == "mesh":
            if spec.mesh in self.bare_meshes and spec.species != 1:
                raise ConfigError(
                    f"mesh {spec.mesh!r} has no material of its own, so it is made of species 1; "
                    "give it 'material' in mesh={...} to use another one"
                )
            return wid, []
        if spec.kind == "plane":
            peq = given(spec.peq, "a plane wall's peq")
            geometry = f"{spec.plane} {fmt(peq)}"
        else:
            centre = given(spec.centre, "a cylinder wall's centre")
            radius = given(spec.radius, "a cylinder wall's radius")
            geometry = f"{spec.axis}cylinder {fmt(radius)} {fmt(centre[0])} {fmt(centre[1])}"
        return wid, [f"fix {wid} all wall/gran {self.law.granular} primitive type {spec.species} {geometry}"]

    def mesh_walls(self, meshes: Sequence[str]) -> tuple[str, list[str]]:
        """The one ``fix wall/gran`` LIGGGHTS allows for mesh walls, with ``meshes`` (names)."""
        wid = self.new_id("meshwalls")
        ids = " ".join(self.mesh_ids[name] for name in meshes)
        return wid, [f"fix {wid} all wall/gran {self.law.granular} mesh n_meshes {len(meshes)} meshes {ids}"]

    def motion(self, spec: MotionSpec) -> tuple[str, list[str]]:
        mid = self.new_id("move")
        mesh = self.mesh_ids[spec.mesh]
        if spec.kind == "linear":
            how = "linear " + " ".join(fmt(v) for v in given(spec.velocity, "a linear motion's velocity"))
        elif spec.kind == "wiggle":
            amplitude = given(spec.amplitude, "a wiggle motion's amplitude")
            period = given(spec.period, "a wiggle motion's period")
            how = f"wiggle amplitude {' '.join(fmt(a) for a in amplitude)} period {fmt(period)}"
        elif spec.kind in ("viblin", "vibrot"):
            # LIGGGHTS 3.8 reads one period per harmonic (and warns, wrongly, that the periods
            # after the first are ignored)
            axis = " ".join(fmt(a) for a in given(spec.axis, f"a {spec.kind} motion's axis"))
            head = f"viblin axis {axis}"
            if spec.kind == "vibrot":
                head = f"vibrot origin {' '.join(fmt(o) for o in spec.origin)} axis {axis}"
            how = (
                f"{head} order {len(spec.amplitudes)} amplitude {' '.join(map(fmt, spec.amplitudes))} "
                f"phase {' '.join(map(fmt, spec.phases))} period {' '.join(map(fmt, spec.periods))}"
            )
        else:
            omega = given(spec.omega, "a rotation's omega")
            if omega == 0:
                raise ConfigError("moveMesh(rotate=True) with omega=0 does not move the mesh")
            axis = np.sign(omega) * np.asarray(given(spec.axis, "a rotation's axis"))
            how = (
                f"rotate origin {' '.join(fmt(o) for o in spec.origin)} "
                f"axis {' '.join(fmt(a) for a in axis)} period {fmt(2 * math.pi / abs(omega))}"
            )
        return mid, [f"fix {mid} all move/mesh mesh {mesh} {how}"]

    def viscous(self, spec: ViscousSpec) -> tuple[str, list[str]]:
        """``fix viscous`` on every atom, scaled to 0 for the species left out (by type at every
        step: a group would miss particles created or inserted later)."""
        vid = self.new_id("viscous")
        others = "".join(f" scale {s.type} 0" for s in self.spec.species if s.type not in spec.species)
        return vid, [f"fix {vid} all viscous {fmt(spec.gamma * spec.scale)}{others}"]


def shape_id(species: int) -> str:
    """The ``particletemplate/multisphere`` of multisphere species ``species``."""
    return f"pg_shape{species}"


def servo_words(servo: ServoSpec | None) -> str:
    """The servo keywords of a ``mesh/surface/stress/servo`` mesh (``''`` for other meshes)."""
    if servo is None:
        return ""
    words = (
        f" com {' '.join(map(fmt, servo.com))} ctrlPV {servo.control} axis {' '.join(map(fmt, servo.axis))} "
        f"target_val {fmt(servo.target)} vel_max {fmt(servo.vel_max)}"
    )
    if servo.mode == "auto":
        return f"{words} mode auto ratio {fmt(given(servo.ratio, 'the ratio of a servo in mode auto'))}"
    return f"{words} kp {fmt(servo.kp)} ki {fmt(servo.ki)} kd {fmt(servo.kd)}"


def native_particles(spec: SimulationSpec) -> bool:
    """Whether LIGGGHTS writes the particle trajectory itself (a ``.dump`` file)."""
    return spec.traj.pfile is not None and spec.traj.pfile.suffix == ".dump"


def native_meshes(spec: SimulationSpec) -> bool:
    """Whether LIGGGHTS writes mesh frames itself (``.vtk``; the only mesh format it has here)."""
    return bool(spec.meshes) and spec.traj.mfile is not None
