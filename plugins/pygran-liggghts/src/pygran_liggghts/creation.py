"""Particles PyGran itself makes in LIGGGHTS: those of ``createParticles``, and the spheres of
an insertion into a region a mesh wall crosses, which PyGran places clear of the mesh (see
:meth:`~.engine.LiggghtsEngine._insert_clear`).

Inside the box, LIGGGHTS numbers created atoms in turn: their ids are counted here, without
a round trip, and their ``set atom`` lines merged into ranges (see :class:`~.channel.Channel`).
:data:`BULK_CREATE` particles or more are read from a dump file instead of one command each.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.calls import CreateSpec, InsertSpec
from pygran_core.simulation.engine import Engine
from pygran_core.simulation.insertion import draw_spheres, place_spheres, report_shortfall, target_shares
from pygran_core.simulation.specs import given
from pygran_liggghts.channel import Channel
from pygran_liggghts.commands import Commands, fmt

#: createParticles with this many positions or more reads them from a dump file it writes in
#: the output folder's :data:`CREATED_DIR` (``read_dump ... add yes``), not one command each.
BULK_CREATE = 64
CREATED_DIR = "created"


def numbered_in_turn(count: int, ranks: int) -> np.ndarray:
    """The order to list ``count`` new atoms in a file for ``read_dump ... add yes`` so that
    LIGGGHTS numbers them as listed before: it deals the file's atoms to the ranks in turn
    (atom f to rank f % ranks) and then numbers the new atoms rank by rank. Entry f is the
    position, in the intended order, of the atom the file lists f-th."""
    listed = np.arange(count)
    per_rank = [(count - rank + ranks - 1) // ranks for rank in range(ranks)]
    first = np.concatenate([[0], np.cumsum(per_rank)[:-1]]).astype(int)
    return first[listed % ranks] + listed // ranks


class Creator:
    """Makes particles in one simulation's LIGGGHTS. ``engine`` gives the spec, step and
    messages; ``channel`` carries the commands; ``ranks``: LIGGGHTS' MPI ranks; ``root``:
    whether this rank writes files; ``allow`` lets LIGGGHTS create atoms (after a restart file
    it must run first). New particles clear the walls the engine knows (``engine.obstacles``)."""

    def __init__(
        self,
        engine: Engine,
        channel: Channel,
        commands: Commands,
        ranks: int,
        root: bool,
        allow: Callable[[], None],
        histories: Callable[[], bool],
    ) -> None:
        self._engine = engine
        self._channel = channel
        self._commands = commands
        self._ranks = ranks
        self._root = root
        self._allow = allow
        self._histories = histories
        self._ungrouped = False  # atoms created since the last run, not yet in the spheres' group
        self._short_warned: set[str] = set()  # placed insertions whose shortfall was warned about

    def regroup(self) -> list[str]:
        """Before a run: the line adding the atoms created since the last one to the group of
        single spheres (with multisphere species; see :meth:`.Commands.regroup`)."""
        lines = [self._commands.regroup()] if self._ungrouped else []
        self._ungrouped = False
        return lines

    def create(self, spec: CreateSpec) -> int:
        """The particles of ``createParticles`` ``spec``; how many were made."""
        species = self._engine.spec.species[spec.species - 1]
        if species.style == "multisphere":
            raise UnsupportedFeature(
                f"LIGGGHTS makes multisphere particles (species {spec.species}) only by insertion: "
                "use insert(), or createParticles for the species of single spheres"
            )
        channel = self._channel
        self._ungrouped = bool(self._commands.body_types)
        self._allow()
        first = channel.max_id + 1
        radii = None  # per particle, when drawn here
        bulk = False  # read from a file with their radii
        if spec.style in ("single", "lattice"):  # lattice: the front end's sites, as on every engine
            centres = spec.centres
            box = np.array(self._engine.spec.domain.box, float)
            inside = bool(np.all((centres > box[:, 0]) & (centres < box[:, 1])))
            bulk = inside and len(centres) >= BULK_CREATE and self._can_read(len(centres))
            if bulk:
                radii = self._bulk(spec, first, centres)
                centres = centres[:0]  # created
            lines = [f"create_atoms {spec.species} single {' '.join(map(fmt, c))} units box" for c in centres]
            if inside:
                # inside the box LIGGGHTS gives them the next ids: no round trip needed
                channel.queue(lines, keep_set_open=True)
                channel.max_id += len(lines)
            else:
                channel.queue(lines)
                channel.flush()
        else:
            centres, radii = self._random(spec)
            channel.queue(
                [f"create_atoms {spec.species} single {' '.join(map(fmt, c))} units box" for c in centres]
            )
            channel.max_id += len(centres)  # all strictly inside the box
        last = channel.max_id
        count = max(0, last - first + 1)
        if count == 0:
            return 0
        values = f"density {fmt(species.density)}"
        if radii is None and spec.radius is None and species.radius.kind != "constant":
            radii = species.radius.sample(count, np.random.default_rng(spec.seed))
        if radii is None or np.all(radii == radii[0]):
            radius = radii[0] if radii is not None else spec.radius or species.radius.values[0]
            values = f"diameter {fmt(2 * radius)} {values}"
        elif not bulk:  # set density then gives each its mass from its own radius
            channel.queue([f"set atom {first + i} diameter {fmt(2 * r)}" for i, r in enumerate(radii)])
        if any(spec.velocity):
            vx, vy, vz = (fmt(v) for v in spec.velocity)
            values += f" vx {vx} vy {vy} vz {vz}"
        channel.set_atoms(first, last, values)  # sent with the next request
        if any(spec.omega):
            channel.set_omega(np.arange(first, last + 1), spec.omega, f"atoms {first}*{last}")
        else:
            channel.stream()  # LIGGGHTS creates these while the script creates the next ones
        return count

    def lacking(self, spec: InsertSpec) -> float:
        """What the region of by-pack insertion ``spec`` lacks of its target (particles, volume
        or mass), counted as the placing engines count it."""
        arrays = self._channel.gather("x", "radius", "mass")
        inside = spec.region.contains(arrays["x"].reshape(-1, 3))
        if spec.target == "particles_in_region":
            return max(spec.value - np.count_nonzero(inside), 0.0)
        if spec.target == "volumefraction_region":
            held = float(np.sum(4 / 3 * np.pi * arrays["radius"][inside] ** 3))
            return max(spec.value * spec.region.volume() - held, 0.0)
        return max(spec.value - float(np.sum(arrays["mass"][inside])), 0.0)

    def place(
        self, label: str, spec: InsertSpec, amount: float, rng: np.random.Generator, meshes: list[str]
    ) -> float:
        """Make an event of insertion ``label`` (``spec``) that PyGran places clear of mesh walls
        ``meshes``: draw up to ``amount`` of its target from ``rng``, place what fits and create
        it. Returns the amount drawn, placed or not (as the placing engines count what is owed)."""
        engine, channel = self._engine, self._channel
        species, radii = draw_spheres(engine.spec, spec, amount, rng)
        velocities = spec.velocity.sample(len(radii), rng)
        existing = channel.gather("x", "radius")
        index, centres = place_spheres(
            spec.region,
            radii,
            rng,
            (existing["x"].reshape(-1, 3), existing["radius"]),
            engine.obstacles("insert()"),
            spec.all_in,
        )
        self._allow()
        first = channel.max_id + 1
        lines = []
        for atom, k, centre in zip(itertools.count(first), index, centres):
            lines.append(f"create_atoms {species[k]} single {' '.join(map(fmt, centre))} units box")
            density = fmt(engine.spec.species[species[k] - 1].density)
            velocity = " ".join(f"v{axis} {fmt(v)}" for axis, v in zip("xyz", velocities[k]))
            lines.append(f"set atom {atom} diameter {fmt(2 * radii[k])} density {density} {velocity}")
        channel.queue(lines)
        channel.max_id += len(index)
        last = channel.max_id
        self._ungrouped = bool(self._commands.body_types)
        if any(spec.omega) and len(index):
            channel.set_omega(np.arange(first, last + 1), spec.omega, f"atoms {first}*{last}")
        channel.flush()
        made, asked = len(index), len(radii)
        engine.log(
            "insert at step %d: %d of %d particles, placed by PyGran clear of mesh %s",
            engine.step,
            made,
            asked,
            ", ".join(meshes),
        )
        if made < asked:
            message = (
                f"insertion at step {engine.step}: {made} of {asked} particles inserted, the region "
                f"{spec.region} is full (no free place for the other {asked - made})"
            )
            report_shortfall(engine.messages, message, label in self._short_warned)
            self._short_warned.add(label)
        return float(target_shares(engine.spec, spec, species, radii).sum())

    def _can_read(self, count: int) -> bool:
        """Whether ``count`` new atoms can be read from a file here. LIGGGHTS 3.8's ``read_dump``
        deals them to the ranks in turn and moves each to its owner without setting their
        contact histories (it calls no fix's ``set_arrays``), and a fix of contact histories
        (the mesh walls', or the pair style's after a run) then crashes on the move. With
        several ranks and such a fix, the atoms are created one by one on their owners
        (``create_atoms``; time quadratic in the number of atoms), and the log says so."""
        if self._ranks == 1 or not self._histories():
            return True
        self._engine.log(
            "createParticles: %d particles created one by one (LIGGGHTS 3.8 crashes reading them "
            "from a file on %d ranks beside contact histories)",
            count,
            self._ranks,
        )
        return False

    def _bulk(self, spec: CreateSpec, first: int, centres: np.ndarray) -> np.ndarray:
        """Queue ``read_dump`` of a dump file of the particles (ids from ``first``, the species'
        type, radii) written to :data:`CREATED_DIR` of the output folder: one command, linear
        in their number (``create_atoms single`` per particle is quadratic). Returns the radii."""
        domain = self._engine.spec.domain
        species = self._engine.spec.species[spec.species - 1]
        count = len(centres)
        if spec.radius is None and species.radius.kind != "constant":
            radii = species.radius.sample(count, np.random.default_rng(spec.seed))
        else:
            radii = np.full(count, spec.radius or species.radius.values[0])
        path = self._engine.output / CREATED_DIR / f"atoms-{first}.dump"
        if self._root:
            path.parent.mkdir(exist_ok=True)
            ids = np.arange(first, first + count)
            rows = np.column_stack([ids, np.full(count, spec.species), centres, radii])
            rows = rows[numbered_in_turn(count, self._ranks)]
            bounds = "\n".join(f"{fmt(lo)} {fmt(hi)}" for lo, hi in domain.box)
            header = (
                f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{count}\nITEM: BOX BOUNDS ff ff ff\n{bounds}\n"
                "ITEM: ATOMS id type x y z radius"
            )
            np.savetxt(path, rows, fmt=["%d", "%d"] + ["%.17g"] * 4, header=header, comments="")
        self._channel.queue([f"read_dump {self._commands.path(path)} 0 x y z radius box no add yes"])
        self._channel.max_id += count
        return radii

    def _random(self, spec: CreateSpec) -> tuple[np.ndarray, np.ndarray]:
        """Centres and radii of ``spec.count`` spheres placed in ``spec.region`` clear of the
        particles and walls, as every placing engine draws them for the same seed; those
        that did not fit, or lie outside the box, are left out."""
        rng = np.random.default_rng(spec.seed)
        species = self._engine.spec.species[spec.species - 1]
        count = given(spec.count, "createParticles 'random''s count")
        if spec.radius is not None:
            radii = np.full(count, spec.radius)
        else:
            radii = species.radius.sample(count, rng)
        existing = self._channel.gather("x", "radius")
        region = given(spec.region, "createParticles 'random''s region")
        index, centres = place_spheres(
            region,
            radii,
            rng,
            (existing["x"], existing["radius"]),
            self._engine.obstacles("createParticles 'random'"),
        )
        box = np.array(self._engine.spec.domain.box, float)
        inside = np.all((centres > box[:, 0]) & (centres < box[:, 1]), axis=1)
        return centres[inside], radii[index][inside]
