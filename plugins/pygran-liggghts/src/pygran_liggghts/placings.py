"""Insertions PyGran makes itself on LIGGGHTS. LIGGGHTS' ``fix insert`` keeps new particles
clear of other particles, not of mesh walls: an insertion into a region that a mesh wall
crosses is made by PyGran instead, as the placing engines make it (at the call, then every
``freq`` steps; by rate, every :meth:`~.Commands.insert_every` steps for its duration), its
particles drawn from the insertion's seed, placed clear of particles, walls and meshes and
created by the :class:`~.creation.Creator`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from pygran_core.errors import ConfigError
from pygran_core.simulation.calls import InsertSpec, Region
from pygran_core.simulation.engine import Engine
from pygran_core.simulation.insertion import insertion_steps
from pygran_core.simulation.specs import given
from pygran_liggghts.commands import Commands
from pygran_liggghts.creation import Creator
from pygran_liggghts.walls import Walls

#: Cells along each edge of the grid :func:`reaches` lays over a triangle.
GRID = 32


def reaches(region: Region, triangles: np.ndarray, reach: float) -> bool:
    """Whether a point of ``triangles`` ``(T, 3, 3)`` may lie in ``region`` grown by ``reach``:
    tested on a grid of :data:`GRID` cells along each edge over each triangle, with the region
    grown by a further cell's longest edge (any point of a triangle lies that close to a grid
    point), so that a triangle in it is always found."""
    a, b = (
        np.array(v, float) / GRID
        for v in zip(*[(i, j) for i in range(GRID + 1) for j in range(GRID + 1 - i)])
    )
    weights = np.column_stack([a, b, 1 - a - b])
    edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max(axis=1)
    for first in range(0, len(triangles), 256):
        points = np.einsum("gk,tkd->tgd", weights, triangles[first : first + 256]).reshape(-1, 3)
        margin = np.repeat(reach + edges[first : first + 256] / GRID, len(weights))
        if region.contains(points, -margin).any():
            return True
    return False


@dataclass
class Placed:
    """One insertion PyGran makes: the request, the mesh walls crossing its region, its random
    stream, the step of its next event, the steps between events (``None``: once), the step
    it ends before (``None``: never) and what is owed (by rate)."""

    spec: InsertSpec
    meshes: list[str]
    rng: np.random.Generator
    next_step: int
    every: int | None
    end: int | None
    owed: float = 0.0

    def due(self, step: int) -> bool:
        """Whether an event is due at ``step``, those before it (a resumed step's) skipped."""
        if self.every is not None and self.next_step < step:
            self.next_step += -(-(step - self.next_step) // self.every) * self.every
        return self.next_step == step

    def schedule(self, step: int) -> bool:
        """Schedule the event after the one at ``step``; whether there is one."""
        following = None if self.every is None else step + self.every
        if following is None or (self.end is not None and following >= self.end):
            return False
        self.next_step = following
        return True


class Placings:
    """The insertions PyGran makes in one simulation on LIGGGHTS, by label. ``engine`` tells
    the step and time step; ``walls`` the mesh walls; ``creator`` makes the particles."""

    def __init__(self, engine: Engine, commands: Commands, walls: Walls, creator: Creator) -> None:
        self._engine = engine
        self._commands = commands
        self._walls = walls
        self._creator = creator
        self._labels: set[str] = set()  # every insertion made here, its events over or not
        self._coming: dict[str, Placed] = {}  # those with events to come

    def reached(self, spec: InsertSpec) -> list[str]:
        """The mesh walls that particles LIGGGHTS inserts for ``spec`` could overlap (its
        ``fix insert`` keeps clear of particles only): those with a triangle in the region,
        grown by the largest radius when only centres must be in it (see :func:`reaches`). A
        mesh whose inside is the region, or a part of its intersection, is not one with
        ``all_in``: LIGGGHTS inserts whole particles into the primitive inscribed in it."""
        species = self._engine.spec.species
        region = spec.region
        parts = region.args if region.kind == "intersect" else (region,)
        insides = [part.args[0].triangles for part in parts if part.kind == "mesh"] if spec.all_in else []
        reach = 0.0 if spec.all_in else max(species[k - 1].radius.max for k in spec.species)
        bounds = region.bounds()
        meshes = {mesh.name: mesh for mesh in self._engine.spec.meshes}
        reached = []
        for name in self._walls.meshes.values():
            triangles = meshes[name].triangles()
            if any(inside.shape == triangles.shape and np.allclose(inside, triangles) for inside in insides):
                continue
            near = np.all(
                (triangles.max(axis=1) >= bounds[:, 0] - reach)
                & (triangles.min(axis=1) <= bounds[:, 1] + reach),
                axis=1,
            )
            if near.any() and reaches(region, triangles[near], reach):
                reached.append(name)
        return reached

    def add(self, spec: InsertSpec, meshes: list[str]) -> str:
        """Insertion ``spec`` into a region that mesh walls ``meshes`` cross, its first event made
        now; its label. LIGGGHTS makes multisphere particles by its own insertion only: those are
        refused here."""
        engine = self._engine
        bodies = sorted(set(spec.species) & set(self._commands.body_types))
        if bodies:
            raise ConfigError(
                f"insert() of multisphere species {bodies} into the region {spec.region}, which mesh wall "
                f"{meshes[0]!r} crosses: LIGGGHTS inserts multisphere particles itself, clear of other "
                "particles only, so they could overlap the mesh. Give a region clear of the mesh (with "
                "all_in, the inside of a mesh built by simulation.geometry, region=('mesh', surface), or "
                "its intersection with your region, is clear of that mesh)"
            )
        label = self._commands.new_id("insert")
        self._labels.add(label)
        every = (
            None
            if spec.mechanism == "by_pack" and not spec.freq
            else self._commands.insert_every(spec, engine.dt)
        )
        end = None
        if spec.duration is not None:
            end = engine.step + round(spec.duration / given(engine.dt, "the time step"))
        self._coming[label] = Placed(spec, meshes, np.random.default_rng(spec.seed), engine.step, every, end)
        self._make_due(label, engine.step)  # due at the call, as on the placing engines
        return label

    def make_due(self, step: int) -> None:
        """Make the events due at ``step`` (as the piece of a run that starts there begins)."""
        for label in list(self._coming):
            self._make_due(label, step)

    def event_steps(self, start: int, end: int) -> set[int]:
        """The steps of the events after ``start`` up to ``end``."""
        steps: set[int] = set()
        for placed in self._coming.values():
            steps.update(insertion_steps(placed.next_step, placed.every, start + 1, end, placed.end))
        return steps

    def crossing(self, mesh: str) -> list[str]:
        """The insertions with events to come into a region that ``mesh`` crosses."""
        return [label for label, placed in self._coming.items() if mesh in placed.meshes]

    def remove(self, label: str) -> bool:
        """Stop insertion ``label``; whether it is one of these."""
        self._coming.pop(label, None)
        if label not in self._labels:
            return False
        self._labels.discard(label)
        return True

    def _make_due(self, label: str, step: int) -> None:
        """Make insertion ``label`` if one of its events is due at ``step`` (none while a resumed
        script is replayed: the restart file holds their particles), and schedule the next."""
        engine = self._engine
        placed = self._coming[label]
        if not placed.due(step):
            return
        if not engine.replaying:
            spec = placed.spec
            place = functools.partial(self._creator.place, label, spec, rng=placed.rng, meshes=placed.meshes)
            if spec.mechanism == "by_pack":
                place(self._creator.lacking(spec))
            else:
                placed.owed += (
                    spec.value * given(placed.every, "an insertion's interval") * given(engine.dt, "dt")
                )
                placed.owed -= place(placed.owed)
        if not placed.schedule(step):
            del self._coming[label]
