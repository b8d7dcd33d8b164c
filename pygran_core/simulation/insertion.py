"""Placing new particles without overlaps: engine-neutral, reproducible from a seed.

Engines whose solver inserts particles (LIGGGHTS) use it only where theirs cannot keep clear
of the walls (a mesh wall crossing the region); the others (native, YADE) hold an
:class:`Inserter`, so that the same request gives the same particles on every engine. What new
particles must clear of the walls comes from the walls' specs (:func:`wall_obstacles`).
Candidates are drawn in batches and checked with k-d trees, never one Python iteration per
particle. Spheres are placed by :func:`place_spheres`; clumps of
multisphere species by :func:`place_clumps`, which checks their own spheres, each clump turned
its own way, as LIGGGHTS does.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from pygran_core.errors import ConfigError, InsertionWarning, ReadError, UnsupportedFeature
from pygran_core.simulation import clumps
from pygran_core.simulation.calls import CreateSpec, InsertSpec, Region, WallSpec
from pygran_core.simulation.checkpoint import encode_text, state_entry, state_json
from pygran_core.simulation.geometry import triangle_distance
from pygran_core.simulation.specs import SimulationSpec, given

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

    from pygran_core.simulation.log import EngineLog


@dataclass(frozen=True)
class Obstacles:
    """What new spheres must not overlap besides other spheres: planes through ``points``
    with unit ``normals`` (acting on both sides, as primitive walls do) and triangles
    (``(T, 3, 3)`` corner coordinates)."""

    plane_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    plane_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    #: Primitive cylinder walls (acting on both sides): ``(axis, (c1, c2), radius)``, the centre
    #: in the two other axes' order, as :class:`~pygran_core.simulation.calls.WallSpec` has it.
    cylinders: tuple[tuple[str, tuple[float, float], float], ...] = ()

    def clear(self, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Which spheres overlap no plane, no cylinder and no triangle."""
        ok = np.ones(len(centres), bool)
        for point, normal in zip(self.plane_points, self.plane_normals):
            ok &= np.abs((centres - point) @ normal) >= radii
        for axis, (c1, c2), radius in self.cylinders:
            across = [i for i in range(3) if "xyz"[i] != axis]
            distance = np.hypot(centres[:, across[0]] - c1, centres[:, across[1]] - c2)
            ok &= np.abs(distance - radius) >= radii
        if len(self.triangles) and len(centres):
            reach = float(radii.max())
            lo, hi = centres.min(axis=0) - reach, centres.max(axis=0) + reach
            near = np.all((self.triangles.max(axis=1) >= lo) & (self.triangles.min(axis=1) <= hi), axis=1)
            if near.any():  # the others are farther than any radius from every sphere
                ok &= triangle_distance(centres, self.triangles[near]) >= radii
        return ok


def report_shortfall(messages: EngineLog, message: str, again: bool) -> None:
    """Report an insertion that made fewer particles than asked (``message``): as an
    :class:`InsertionWarning` the first time, in ``pygran.log`` only ``again``."""
    if again:
        messages.to_file(logging.WARNING, message)
    else:
        messages.warn(
            f"{message}: give a larger region or fewer particles. Further shortfalls of this "
            "insertion are logged in pygran.log only.",
            InsertionWarning,
        )


def insertion_steps(first: int, freq: int | None, start: int, stop: int, end: int | None = None) -> list[int]:
    """The steps in ``[start, stop)`` at which insertions are due: ``first``, then every
    ``freq`` steps (``None``: only ``first``), before ``end`` (``None``: no end).

    The rule every engine follows (LIGGGHTS' ``fix insert``): an insertion due at step ``s``
    is made as the simulation advances from ``s`` to ``s + 1``. A run from step ``a`` to
    ``b`` therefore makes the insertions due in ``[a, b)``: the first as it starts, none at
    its last step; one due at ``b`` is made as the next run starts. (The insertion due at
    the step of the ``insert`` call itself is made at the call by the engines that place
    particles, at the next run's start by LIGGGHTS: no time passes in between.)
    """
    if freq is None:
        steps = [first] if start <= first < stop else []
    else:
        k = max(0, -(-(start - first) // freq))
        steps = list(range(first + k * freq, stop, freq))
    return [s for s in steps if end is None or s < end]


#: :func:`place_spheres` and :func:`place_clumps` give up after this many batches in a row
#: placed nothing: the region is jammed.
JAMMED = 5


def place_spheres(
    region: Region,
    radii: np.ndarray,
    rng: np.random.Generator,
    existing: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 3)), np.zeros(0)),
    obstacles: Obstacles | None = None,
    all_in: bool = True,
    attempts: int = 50,
) -> tuple[np.ndarray, np.ndarray]:
    """Place spheres of ``radii`` in ``region`` overlapping neither each other, the
    ``existing`` (positions, radii) spheres nor the ``obstacles``.

    Random sequential addition in batches, largest spheres first: candidates uniform in
    the region (whole spheres inside it when ``all_in``) are kept when they clear all
    placed spheres and every earlier candidate of their batch. Returns ``(index, centres)``:
    the centres of ``radii[index]``, for as many as fit within ``attempts`` batches or until
    :data:`JAMMED` batches in a row place none (the caller compares the count with what it
    asked for).
    """
    radii = np.asarray(radii, float)
    bounds = region.bounds()
    pending = np.argsort(-radii, kind="stable")
    placed_index: list[np.ndarray] = []
    centres_placed, radii_placed = existing[0].reshape(-1, 3), existing[1].reshape(-1)
    n_existing = len(centres_placed)
    empty = 0  # batches in a row that placed nothing
    for _ in range(attempts):
        if len(pending) == 0 or empty == JAMMED:
            break
        slots = np.resize(np.arange(len(pending)), max(4 * len(pending), 64))
        r = radii[pending[slots]]
        centres = rng.uniform(bounds[:, 0], bounds[:, 1], (len(slots), 3))
        ok = region.contains(centres, r if all_in else 0.0)
        ok[ok] &= ~_clashes(centres[ok], r[ok], centres_placed, radii_placed)
        if obstacles is not None:
            ok[ok] &= obstacles.clear(centres[ok], r[ok])
        keep = np.flatnonzero(ok)
        keep = keep[_clear_of_earlier(centres[keep], r[keep])]
        _, first = np.unique(slots[keep], return_index=True)
        keep = keep[np.sort(first)]
        centres_placed = np.vstack([centres_placed, centres[keep]])
        radii_placed = np.append(radii_placed, r[keep])
        placed_index.append(pending[slots[keep]])
        pending = np.delete(pending, slots[keep])
        empty = 0 if len(keep) else empty + 1
    index = np.concatenate(placed_index) if placed_index else np.zeros(0, int)
    return index, centres_placed[n_existing:]


def place_clumps(
    region: Region,
    shapes: Sequence[np.ndarray],
    kinds: np.ndarray,
    radii: np.ndarray,
    rng: np.random.Generator,
    existing: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 3)), np.zeros(0)),
    obstacles: Obstacles | None = None,
    all_in: bool = True,
    attempts: int = 50,
    orientation: str | Sequence[float] = "random",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Place particles in ``region``: particle ``i`` a clump of the spheres ``shapes[kinds[i]]``
    (rows ``x, y, z, r`` about the centre of their bounding sphere), or a single sphere of
    ``radii[i]`` where ``kinds[i] < 0``; no sphere of one overlapping a sphere of another, the
    ``existing`` (positions, radii) spheres or the ``obstacles``.

    As :func:`place_spheres`, largest first and in batches: a candidate is a bounding sphere's
    centre uniform in the region (the whole bounding sphere inside it when ``all_in``, as
    LIGGGHTS' ``all_in``), turned as ``orientation`` says (see :func:`.clumps.orientations`;
    ``'random'``: each candidate its own turn), and is kept when its spheres clear what is
    placed and the spheres of the candidates kept before it in its batch (see
    :func:`_first_come`). Returns ``(index, centres, orientations)``: where the bounding
    spheres' centres of ``index`` are and how they are turned, for as many as fit within
    ``attempts`` batches or until :data:`JAMMED` batches in a row place none (a batch of clumps
    turned other ways may still find room after one that found none).
    """
    kinds = np.asarray(kinds)
    reach = np.array(radii, float)
    for kind, shape in enumerate(shapes):
        reach[kinds == kind] = np.max(np.linalg.norm(shape[:, :3], axis=1) + shape[:, 3])
    bounds = region.bounds()
    pending = np.argsort(-reach, kind="stable")
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    spheres, spheres_radii = existing[0].reshape(-1, 3), existing[1].reshape(-1)
    idle = 0  # batches in a row that placed nothing
    for _ in range(attempts):
        if len(pending) == 0:
            break
        slots = np.resize(np.arange(len(pending)), max(4 * len(pending), 64))
        items = pending[slots]
        centres = rng.uniform(bounds[:, 0], bounds[:, 1], (len(slots), 3))
        turns = clumps.orientations(orientation, len(slots), rng)
        candidates = np.flatnonzero(region.contains(centres, reach[items] if all_in else 0.0))
        x, r, owner = _members(
            shapes, kinds[items[candidates]], reach[items[candidates]], centres[candidates], turns[candidates]
        )
        bad = _clashes(x, r, spheres, spheres_radii)
        if obstacles is not None:
            bad[~bad] = ~obstacles.clear(x[~bad], r[~bad])
        clear = np.bincount(owner, weights=bad, minlength=len(candidates)) == 0
        kept = _first_come(x, r, owner, slots[candidates], clear)
        keep = candidates[kept]
        placed = np.isin(owner, kept)
        spheres, spheres_radii = np.vstack([spheres, x[placed]]), np.append(spheres_radii, r[placed])
        found.append((items[keep], centres[keep], turns[keep]))
        pending = np.delete(pending, slots[keep])
        idle = 0 if len(keep) else idle + 1
        if idle == JAMMED:
            break  # batches of four candidates per particle found no free place
    if not found:
        return np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 4))
    index, centres, turns = (np.concatenate(parts) for parts in zip(*found))
    return index, centres, turns


def _members(
    shapes: Sequence[np.ndarray], kinds: np.ndarray, radii: np.ndarray, centres: np.ndarray, turns: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The spheres of particles (see :func:`place_clumps`) at ``centres`` turned by ``turns``:
    their centres, radii and particle (index into ``kinds``), particle by particle."""
    parts = [(centres[kinds < 0], radii[kinds < 0], np.flatnonzero(kinds < 0))]
    for kind, shape in enumerate(shapes):
        chosen = np.flatnonzero(kinds == kind)
        offsets = np.einsum("nij,kj->nki", clumps.rotation_matrix(turns[chosen]), shape[:, :3])
        parts.append(
            (
                (centres[chosen, None, :] + offsets).reshape(-1, 3),
                np.tile(shape[:, 3], len(chosen)),
                np.repeat(chosen, len(shape)),
            )
        )
    x, r, owner = (np.concatenate(column) for column in zip(*parts))
    order = np.argsort(owner, kind="stable")
    return x[order], r[order], owner[order]


def _tree(points: np.ndarray) -> cKDTree:
    """A k-d tree of ``points`` (scipy.spatial loads on first use: engines import this module)."""
    from scipy.spatial import cKDTree

    return cKDTree(points)


def _first_come(
    centres: np.ndarray, radii: np.ndarray, owner: np.ndarray, slots: np.ndarray, clear: np.ndarray
) -> np.ndarray:
    """The candidates kept when taken in order: each one ``clear`` of what is placed is kept
    unless one of its spheres (``centres``, ``radii``, candidate ``owner``, ascending) overlaps
    a sphere of a candidate kept before it, or a candidate before it for the same particle
    (``slots``) is kept. Decided in rounds, each deciding every candidate whose earlier rivals
    are decided. Returns the kept candidates, ascending."""
    state = np.where(clear, 0, -1)  # 0: undecided, 1: kept, -1: dropped
    pairs = np.zeros((0, 2), int)  # overlapping candidates, the earlier first
    if len(centres):
        near = _tree(centres).query_pairs(2 * float(radii.max()), output_type="ndarray")
        gap = np.linalg.norm(centres[near[:, 0]] - centres[near[:, 1]], axis=1)
        near = near[gap < radii[near[:, 0]] + radii[near[:, 1]]]
        pairs = np.column_stack([owner[near[:, 0]], owner[near[:, 1]]])
        pairs = pairs[(pairs[:, 0] != pairs[:, 1]) & (state[pairs[:, 0]] == 0) & (state[pairs[:, 1]] == 0)]
    while np.any(state == 0):
        state[pairs[state[pairs[:, 0]] == 1, 1]] = -1  # overlaps one kept before it
        taken = np.zeros(slots.max() + 1, bool)
        taken[slots[state == 1]] = True
        state[(state == 0) & taken[slots]] = -1  # its particle is placed
        undecided = np.flatnonzero(state == 0)
        waiting = np.zeros(len(state), bool)
        waiting[pairs[state[pairs[:, 0]] == 0, 1]] = True
        _, first = np.unique(slots[undecided], return_index=True)
        ready = undecided[first]  # the first undecided candidate of its particle
        state[ready[~waiting[ready]]] = 1
    return np.flatnonzero(state == 1)


def _clashes(
    centres: np.ndarray, radii: np.ndarray, others: np.ndarray, others_radii: np.ndarray
) -> np.ndarray:
    """Which candidate spheres overlap any of the ``others``."""
    clash = np.zeros(len(centres), bool)
    if len(centres) == 0 or len(others) == 0:
        return clash
    reach = float(radii.max() + others_radii.max())
    pairs = _tree(centres).sparse_distance_matrix(_tree(others), reach, output_type="ndarray")
    bad = pairs["v"] < radii[pairs["i"]] + others_radii[pairs["j"]]
    clash[pairs["i"][bad]] = True
    return clash


def _clear_of_earlier(centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Indices of the candidates that overlap no earlier candidate of the same batch."""
    if len(centres) == 0:
        return np.zeros(0, int)
    pairs = _tree(centres).query_pairs(2 * float(radii.max()), output_type="ndarray")
    dropped = np.zeros(len(centres), bool)
    if len(pairs):
        gap = np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1)
        dropped[pairs[:, 1][gap < radii[pairs[:, 0]] + radii[pairs[:, 1]]]] = True
    return np.flatnonzero(~dropped)


def sample_radii(spec: SimulationSpec, species: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A radius for each sphere of ``species`` (1-based), drawn species by species."""
    radii = np.empty(len(species))
    for s in np.unique(species):
        chosen = species == s
        radii[chosen] = spec.species[int(s) - 1].radius.sample(int(chosen.sum()), rng)
    return radii


def target_shares(
    spec: SimulationSpec, request: InsertSpec, species: np.ndarray, radii: np.ndarray
) -> np.ndarray:
    """Each sphere's share of the request's target: 1, its volume or its mass."""
    if request.target in ("particles_in_region", "particlerate"):
        return np.ones(len(radii))
    volume = 4 / 3 * math.pi * radii**3
    if request.target in ("volumefraction_region",):
        return volume
    return volume * np.array([spec.species[int(s) - 1].density for s in species])


def draw_spheres(
    spec: SimulationSpec, request: InsertSpec, amount: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Species and radii of spheres making up at most ``amount`` of the request's target."""
    if request.target in ("particles_in_region", "particlerate"):
        count = int(amount)
    else:
        typical = target_shares(
            spec,
            request,
            np.array(request.species),
            np.array([spec.species[s - 1].radius.mean for s in request.species]),
        )
        count = int(1.2 * amount / float(np.dot(request.weights, typical))) + 2
    species = rng.choice(np.array(request.species), size=count, p=np.array(request.weights))
    radii = sample_radii(spec, species, rng)
    if request.target not in ("particles_in_region", "particlerate"):
        shares = target_shares(spec, request, species, radii)
        keep = int(np.searchsorted(np.cumsum(shares), amount, side="right"))
        species, radii = species[:keep], radii[:keep]
    return species, radii


def wall_obstacles(walls: Iterable[WallSpec], triangles: Sequence[np.ndarray]) -> Obstacles:
    """What new spheres must clear of the ``walls``: their planes and primitive cylinders (from
    the specs), and the ``triangles`` of the mesh walls (``(T, 3, 3)`` each, where they are now)."""
    points, normals = [], []
    cylinders: list[tuple[str, tuple[float, float], float]] = []
    for wall in walls:
        if wall.kind == "plane":
            axis = "xyz".index(given(wall.plane, "a plane wall's plane")[0])
            points.append(np.eye(3)[axis] * given(wall.peq, "a plane wall's peq"))
            normals.append(np.eye(3)[axis])
        elif wall.kind == "cylinder" and wall.axis and wall.centre and wall.radius:
            cylinders.append((wall.axis, wall.centre, wall.radius))
    return Obstacles(
        np.reshape(points, (-1, 3)),
        np.reshape(normals, (-1, 3)),
        np.concatenate(triangles) if len(triangles) else np.zeros((0, 3, 3)),
        tuple(cylinders),
    )


def multisphere_templates(spec: SimulationSpec) -> dict[int, np.ndarray]:
    """Multisphere species -> their template spheres ``(k, 4)``: ``x, y, z, r`` each."""
    return {s.type: np.array(s.spheres, float) for s in spec.species if s.style == "multisphere"}


class Placing(Protocol):
    """What an :class:`Inserter` asks of the engine that holds it: the simulation, its clock,
    its messages, the particles present and where walls stand, and adding particles to its solver."""

    spec: SimulationSpec
    step: int
    dt: float | None

    @property
    def name(self) -> str: ...

    @property
    def replaying(self) -> bool: ...

    @property
    def messages(self) -> EngineLog: ...

    def log(self, message: str, *args: Any, level: int = ...) -> None: ...

    def _unsupported(self, what: str) -> UnsupportedFeature: ...

    def _extract(self, quantity: str) -> np.ndarray: ...

    def obstacles(self, call: str) -> Obstacles: ...

    def bodies(self) -> np.ndarray: ...

    def _add_spheres(
        self,
        species: np.ndarray,
        centres: np.ndarray,
        radii: np.ndarray,
        velocities: np.ndarray,
        omega: Sequence[float],
    ) -> None:
        """Add spheres of the given species (1-based, none multisphere) to the solver."""

    def _add_clumps(
        self,
        species: int,
        origins: np.ndarray,
        orientations: np.ndarray,
        velocities: np.ndarray,
        omega: Sequence[float],
    ) -> None:
        """Add clumps of multisphere species ``species`` (1-based) to the solver: its template's
        origin at each of ``origins``, turned by ``orientations`` (unit quaternions ``w, x, y,
        z``), moving at ``velocities`` (of the centre of mass) and spinning at ``omega``."""


#: Simulated seconds between insertions by rate when ``freq`` is not given.
RATE_INTERVAL = 1e-2


class Inserter:
    """Adds the particles of ``insert`` and ``createParticles`` for an engine whose solver
    cannot place them itself (native, YADE), so that every such engine inserts and creates the
    same particles for the same request and seed.

    It makes ``insert`` (by pack, once or every ``freq`` steps; by rate, every ``freq`` steps or
    every :data:`RATE_INTERVAL` seconds) at the steps :func:`insertion_steps` gives (the engine
    base splits a run there and calls :meth:`make_due`), and ``createParticles`` (single,
    lattice, random), clear of the particles and of the walls (the engine's ``obstacles``).
    Its schedules are part of every checkpoint (:meth:`state`, :meth:`restore`).

    Multisphere species (engines with the ``multisphere`` capability) are clumps, one per
    particle. They are inserted by number only, turned as the insertion's ``orientation`` says
    (by default at random, as on LIGGGHTS: each clump its own turn from the insertion's
    generator), placed by :func:`place_clumps`, and counted in a region once, when the centre of
    their bounding sphere is in it (as LIGGGHTS counts them); ``createParticles`` keeps their
    template's orientation and puts a ``'single'`` or ``'lattice'`` clump's template origin at
    the point.
    """

    def __init__(self, engine: Placing) -> None:
        if not engine.spec.species:
            raise ConfigError(
                f"The {engine.name} engine needs at least one species: "
                "species=({'material': ..., 'radius': ...},)"
            )
        self.engine = engine
        self.schedules: dict[str, _Schedule] = {}
        self._insertions = 0
        self.templates = multisphere_templates(engine.spec)

    # -- counting ------------------------------------------------------------------------

    def _held(self, request: InsertSpec) -> float:
        """How much of a by-pack target the region holds: particles, volume or mass; a clump
        counts once (with its mass and volume) when the centre of its bounding sphere is in it."""
        extract = self.engine._extract
        if self.templates:
            return self._held_with_clumps(request)
        inside = request.region.contains(extract("x"))
        if request.target == "particles_in_region":
            return float(np.count_nonzero(inside))
        if request.target == "volumefraction_region":
            return float((4 / 3 * math.pi * extract("radius")[inside] ** 3).sum())
        return float(extract("mass")[inside].sum())

    def _held_with_clumps(self, request: InsertSpec) -> float:
        """:meth:`_held` with multisphere species, whose spheres each carry the clump's mass."""
        extract, spec = self.engine._extract, self.engine.spec
        x, bodies, types = extract("x"), self.engine.bodies(), extract("type")
        first, centres = clumps.bounding_centres(x, bodies, types, self.templates)
        single = bodies < 0
        inside = request.region.contains(np.vstack([x[single], centres]))
        if request.target == "particles_in_region":
            return float(np.count_nonzero(inside))
        mass = extract("mass")
        if request.target == "volumefraction_region":
            density = np.array([spec.species[int(t) - 1].density for t in types[first]])
            radius = extract("radius")[single]
            volume = np.append(4 / 3 * math.pi * radius**3, mass[first] / density.reshape(-1))
            return float(volume[inside].sum())
        return float(np.append(mass[single], mass[first])[inside].sum())

    def _lacking(self, schedule: _Schedule) -> float:
        """How much the region lacks of a by-pack target."""
        request = schedule.request
        target = schedule.target * (
            request.region.volume() if request.target == "volumefraction_region" else 1
        )
        return max(target - self._held(request), 0.0)

    # -- placing -----------------------------------------------------------------------

    def _place(
        self,
        call: str,
        region: Region,
        species: np.ndarray,
        radii: np.ndarray,
        rng: np.random.Generator,
        velocities: np.ndarray,
        omega: Sequence[float],
        all_in: bool = True,
        orientation: str | Sequence[float] = "template",
    ) -> int:
        """Add the particles of ``call`` that fit at free places in ``region`` (clumps turned as
        ``orientation`` says, see :func:`.clumps.orientations`); returns how many did."""
        engine = self.engine
        existing = (engine._extract("x"), engine._extract("radius"))
        kinds = sorted(self.templates)
        obstacles = engine.obstacles(call)
        if not np.isin(species, kinds).any():
            index, centres = place_spheres(region, radii, rng, existing, obstacles, all_in)
            if len(index):
                engine._add_spheres(species[index], centres, radii[index], velocities[index], omega)
            return len(index)
        shapes = [self.templates[kind] for kind in kinds]
        offsets = [clumps.bounding_sphere(shape)[0] for shape in shapes]
        shapes = [np.column_stack([shape[:, :3] - off, shape[:, 3]]) for shape, off in zip(shapes, offsets)]
        kind = np.array([kinds.index(s) if s in self.templates else -1 for s in species.tolist()])
        index, centres, turns = place_clumps(
            region, shapes, kind, radii, rng, existing, obstacles, all_in, orientation=orientation
        )
        # the template's origin is its bounding sphere's centre less the turned offset
        for k, off in enumerate(offsets):
            chosen = kind[index] == k
            centres[chosen] -= clumps.rotation_matrix(turns[chosen]) @ off
        self._add_particles(species[index], centres, radii[index], velocities[index], omega, turns)
        return len(index)

    def _add_particles(
        self,
        species: np.ndarray,
        centres: np.ndarray,
        radii: np.ndarray,
        velocities: np.ndarray,
        omega: Sequence[float],
        orientations: np.ndarray,
    ) -> None:
        """Add spheres at ``centres`` and clumps with their template's origin there, turned by
        ``orientations``, species by species."""
        for kind in np.unique(species):
            chosen = species == kind
            if int(kind) in self.templates:
                self.engine._add_clumps(
                    int(kind), centres[chosen], orientations[chosen], velocities[chosen], omega
                )
            else:
                self.engine._add_spheres(
                    species[chosen], centres[chosen], radii[chosen], velocities[chosen], omega
                )

    def _insert_now(self, schedule: _Schedule, amount: float) -> float:
        """Insert up to ``amount`` of the target; returns the amount drawn, placed or not."""
        engine = self.engine
        if engine.replaying:
            return 0.0  # the checkpoint being resumed holds the particles
        request = schedule.request
        species, radii = draw_spheres(engine.spec, request, amount, schedule.rng)
        velocities = request.velocity.sample(len(radii), schedule.rng)
        made = self._place(
            "insert()",
            request.region,
            species,
            radii,
            schedule.rng,
            velocities,
            request.omega,
            request.all_in,
            request.orientation or "random",  # LIGGGHTS' default
        )
        engine.log("insert at step %d: %d of %d particles", engine.step, made, len(radii))
        if made < len(radii):
            message = (
                f"insertion at step {engine.step}: {made} of {len(radii)} particles inserted, the region "
                f"{request.region} is full (no free place for the other "
                f"{len(radii) - made})"
            )
            report_shortfall(engine.messages, message, schedule.warned)
            schedule.warned = True
        if request.target == "volumefraction_region":
            engine.log(
                "volume fraction in the region: %.3g of the %.3g asked for",
                self._held(request) / request.region.volume(),
                request.value,
            )
        return float(target_shares(engine.spec, request, species, radii).sum())

    # -- the calls -----------------------------------------------------------------------

    def insert(self, request: InsertSpec) -> str:
        """Schedule the insertion ``request`` and make its first if due now; returns its label."""
        engine = self.engine
        bodies = [k for k in request.species if k in self.templates]
        if bodies and request.target not in ("particles_in_region", "particlerate"):
            raise engine._unsupported(
                f"inserting multisphere species {bodies} by {request.target} (the {engine.name} engine "
                "inserts clumps by number: particles_in_region or particlerate)"
            )
        if self.templates and request.mechanism == "by_pack" and request.target == "particles_in_region":
            # the front end added the spheres whose centres are in the region; count clumps once
            present = int(self._held(request))
            engine.log(
                "insert: %g particles on top of the %d in the region, counted as LIGGGHTS counts them: "
                "a single sphere when its centre is in it, a multisphere particle once when the centre "
                "of its bounding sphere is (sphere centres in it: %d)",
                request.requested or 0,
                present,
                request.value - (request.requested or 0),
            )
            request = replace(request, value=(request.requested or 0) + present)
        self._insertions += 1
        label = f"insert{self._insertions}"
        rng = np.random.default_rng(request.seed)
        if request.mechanism == "by_pack":
            freq, end = request.freq, None
        else:
            if engine.dt is None:
                raise ConfigError("Insertion by rate needs the time step: pass dt=... to DEM before insert()")
            freq = request.freq or max(1, round(RATE_INTERVAL / engine.dt))
            end = None if request.duration is None else engine.step + round(request.duration / engine.dt)
        schedule = _Schedule(request, freq, engine.step, end, rng, target=request.value)
        self.schedules[label] = schedule
        self._insert_due(label, schedule)  # due now: made at the call (see insertion_steps)
        return label

    def _insert_due(self, label: str, schedule: _Schedule) -> None:
        """Make the insertion due at this step (by rate: for the next ``freq`` steps of the time
        step) and schedule the next, or end the schedule."""
        request = schedule.request
        if request.mechanism == "by_pack":
            self._insert_now(schedule, self._lacking(schedule))
        else:
            interval = given(schedule.freq, "an insertion by rate's freq") * given(self.engine.dt, "dt")
            schedule.owed += request.value * interval
            schedule.owed -= self._insert_now(schedule, schedule.owed)
        following = None if schedule.freq is None else schedule.next_step + schedule.freq
        if following is None or (schedule.end_step is not None and following >= schedule.end_step):
            del self.schedules[label]
        else:
            schedule.next_step = following

    def create(self, request: CreateSpec) -> int:
        """Create the particles of ``request`` now; returns how many."""
        spec = self.engine.spec
        species = spec.species[request.species - 1]
        if request.radius and request.species in self.templates:
            raise ConfigError(
                f"createParticles: species {request.species} is multisphere, its spheres' radii come from "
                "its template; leave radius out"
            )
        rng = np.random.default_rng(request.seed)
        if request.style == "single":
            centres = request.centres
            radii = (
                np.full(len(centres), request.radius)
                if request.radius
                else species.radius.sample(len(centres), rng)
            )
        elif request.style == "lattice":
            centres = request.centres
            radii = np.full(len(centres), request.radius or species.radius.mean)
        else:
            count = given(request.count, "createParticles('random')'s count")
            radii = np.full(count, request.radius) if request.radius else species.radius.sample(count, rng)
            return self._place(
                "createParticles 'random'",
                given(request.region, "createParticles('random')'s region"),
                np.full(count, request.species),
                radii,
                rng,
                np.tile(np.asarray(request.velocity, float), (count, 1)),
                request.omega,
            )
        if len(radii):
            self._add_particles(
                np.full(len(radii), request.species),
                np.asarray(centres, float).reshape(-1, 3),
                radii,
                np.tile(np.asarray(request.velocity, float), (len(radii), 1)),
                request.omega,
                clumps.orientations("template", len(radii), rng),
            )
        return len(radii)

    def remove(self, label: str) -> None:
        """End the insertion ``label``."""
        self.schedules.pop(label, None)

    # -- the engine's schedule ------------------------------------------------------------

    def due_steps(self, start: int, end: int) -> set[int]:
        """The steps in ``(start, end)`` at which insertions are due."""
        steps: set[int] = set()
        for schedule in self.schedules.values():
            steps.update(
                insertion_steps(schedule.next_step, schedule.freq, start + 1, end, schedule.end_step)
            )
        return steps

    def make_due(self, end: int) -> None:
        """Make the insertions due at this step, when a step follows before ``end`` (in a run,
        not at its end); none while the script is replayed up to a checkpoint, which holds
        their outcome."""
        step = self.engine.step
        if step >= end or self.engine.replaying:
            return
        for label, schedule in list(self.schedules.items()):
            if step == schedule.next_step:
                self._insert_due(label, schedule)

    def state(self) -> dict[str, np.ndarray]:
        """The schedules for a checkpoint: when each is due next, until when, what it owes and
        targets, and its random generator's state."""
        state = {}
        for label, schedule in self.schedules.items():
            end = -1 if schedule.end_step is None else schedule.end_step
            state[f"schedules/{label}/clock"] = np.array([schedule.next_step, end], np.int64)
            state[f"schedules/{label}/owed"] = np.array(schedule.owed)
            state[f"schedules/{label}/target"] = np.array(schedule.target)
            state[f"schedules/{label}/rng"] = encode_text(json.dumps(schedule.rng.bit_generator.state))
        return state

    def restore(self, state: dict[str, np.ndarray], path: Path) -> None:
        """The insertion schedules of the checkpoint ``path``, each entry checked (a
        :class:`ReadError` naming the file and the key) before any schedule is changed."""
        saved = sorted({name.split("/")[1] for name in state if name.startswith("schedules/")})
        restored = []
        for label in saved:
            key = f"schedules/{label}"
            if label not in self.schedules:
                raise ReadError(
                    f"{path}: the checkpoint's state entry {key!r} is an insertion the script does not "
                    f"make (its insertions still due: {sorted(self.schedules) or 'none'})"
                )
            next_step, end = (int(v) for v in state_entry(path, state, f"{key}/clock", "iu", (2,)))
            owed = float(state_entry(path, state, f"{key}/owed", "biuf", ()))
            target = float(state_entry(path, state, f"{key}/target", "biuf", ()))
            if next_step < 0 or not (math.isfinite(owed) and math.isfinite(target)):
                raise ReadError(
                    f"{path}: the checkpoint's insertion {key!r} is due at step {next_step}, owes {owed} "
                    f"and targets {target}"
                )
            rng = np.random.default_rng()
            try:
                rng.bit_generator.state = state_json(path, state, f"{key}/rng", dict)
            except (KeyError, TypeError, ValueError) as exc:
                raise ReadError(
                    f"{path}: the checkpoint's state entry '{key}/rng' is not a random generator's state "
                    f"({type(exc).__name__}: {exc})"
                ) from None
            restored.append((label, next_step, None if end < 0 else end, owed, target, rng))
        for label in set(self.schedules) - set(saved):
            del self.schedules[label]
        for label, next_step, end_step, owed, target, rng in restored:
            schedule = self.schedules[label]
            schedule.next_step, schedule.end_step = next_step, end_step
            schedule.owed, schedule.target, schedule.rng = owed, target, rng


@dataclass
class _Schedule:
    """An insertion: what, how often (``None``: once), the step the next is due, until when,
    how much is still owed (by rate), the region's target (by pack: ``request.value`` as
    made at the call, kept in checkpoints) and whether a full region was warned about."""

    request: InsertSpec
    freq: int | None
    next_step: int
    end_step: int | None
    rng: np.random.Generator
    owed: float = 0.0
    target: float = 0.0
    warned: bool = False
