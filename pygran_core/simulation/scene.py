"""What the engine base knows of a simulation's contents, for its checks and for placing new
particles: the walls set up (their specs), the insertions under way, the meshes ``moveMesh``
moves, the faces particles are expected to leave through, the fastest speed the script gave
particles, and the particles present, read from the engine anew only after a call or a run
may have changed them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.calls import CreateSpec, InsertSpec, WallSpec
from pygran_core.simulation.diagnostics import (
    LostParticles,
    Present,
    TimeStepLimits,
    check_clear,
    lost_report,
    species_present,
)
from pygran_core.simulation.insertion import Obstacles, wall_obstacles
from pygran_core.simulation.specs import SimulationSpec, given
from pygran_core.simulation.timestep import Assessment


class Scene:
    """The contents of the simulation of ``spec`` (``extract``: the engine's per-particle
    quantities), by handle id where a call made them. A ``fresh`` simulation holds no
    particle, so its first ``createParticles`` does not wait for the solver to start."""

    def __init__(self, spec: SimulationSpec, extract: Callable[[str], np.ndarray], fresh: bool) -> None:
        self.spec = spec
        self._extract = extract
        self.walls: dict[int, WallSpec] = {}  # the walls new particles clear, contacts meet
        self.inserts: dict[int, InsertSpec] = {}  # the species that may appear
        self.moving: dict[int, str] = {}  # the mesh each moveMesh moves
        self.speed = 0.0  # the largest speed the script gave particles
        self.outflow: frozenset[str] = frozenset()  # the faces particles are expected to leave through
        self.broken: set[int] = set()  # ids of non-finite particles counted by a LostWatch
        self.time_step = TimeStepLimits(spec)
        #: (species, smallest radius, more than one) of the particles present; None: read anew
        self._present: Present | None = None
        #: Positions and radii of the particles present, kept between runs for createParticles
        self._placed: tuple[np.ndarray, np.ndarray] | None = (
            (np.empty((0, 3)), np.empty(0)) if fresh else None
        )

    def gave(self, speed: float) -> None:
        """The script gave particles ``speed``."""
        self.speed = max(self.speed, speed)

    def forget(self, moved_only: bool = False) -> None:
        """Read the particles present anew when next needed: a call or run may have changed
        them (``moved_only``: a run moved them, the species and sizes present are the same)."""
        self._placed = None
        if not moved_only:
            self._present = None

    def removed(self, handle: int) -> None:
        for known in (self.walls, self.inserts, self.moving):
            known.pop(handle, None)

    def present(self) -> Present:
        """The species present, their smallest radius and whether there are several."""
        if self._present is None:
            self._present = species_present(self.spec, self._extract("type"), self._extract("radius"))
        return self._present

    def coming(self) -> set[int]:
        """The species the insertions under way add."""
        return {k for insert in self.inserts.values() for k in insert.species}

    def judge_time_step(self, dt: float, check_dt: bool) -> tuple[Assessment | None, str | None, str | None]:
        """``dt`` against the contacts that can happen now, between the species present or
        being inserted and with the walls (see :meth:`.TimeStepLimits.judge`)."""
        return self.time_step.judge(dt, self.present(), self.coming(), self.walls.values(), check_dt)

    def lost_report(
        self,
        engine: str,
        lost: LostParticles,
        estimated: bool,
        run: tuple[int, int],
        total: int,
        check: Assessment | None,
    ) -> tuple[str | None, str | None]:
        """What to log and warn of the particles ``lost`` in ``run`` (see :func:`.lost_report`)."""
        speeds = np.linalg.norm(self._extract("v").reshape(-1, 3), axis=1)
        return lost_report(
            engine, self.spec, lost, estimated, run, self.outflow, total, check, self.speed, speeds
        )

    def check_clear(self, request: CreateSpec) -> None:
        """Refuse the ``single`` positions or lattice sites of ``request`` that overlap each
        other or the particles present (see :func:`.diagnostics.check_clear`)."""
        if self._placed is None:
            x, r = self._extract("x").reshape(-1, 3), self._extract("radius")
            finite = np.isfinite(x).all(axis=1)
            self._placed = (x[finite], r[finite])
        check_clear(self.spec, request, *self._placed)

    def created(self, request: CreateSpec) -> None:
        """The particles of ``request`` were created: positions given are added to those known."""
        self._present = None
        if request.style == "single" and self._placed is not None:
            radius = request.radius or self.spec.species[request.species - 1].radius.min
            x, r = self._placed
            self._placed = (
                np.vstack([x, request.centres]),
                np.append(r, np.full(len(request.centres), radius)),
            )
        else:
            self._placed = None

    def mesh_walls(self) -> list[str]:
        """The meshes that are walls, in the order they were set up."""
        return [given(w.mesh, "a mesh wall's mesh") for w in self.walls.values() if w.kind == "mesh"]

    def mesh_where(self, name: str, now: np.ndarray | None, engine: str, call: str) -> np.ndarray:
        """The triangles of mesh wall ``name`` for ``call``: ``now``, where the ``engine``'s
        solver has them, or where the mesh file puts them while no ``moveMesh`` moves it."""
        if now is not None:
            return now
        if name in self.moving.values():
            raise UnsupportedFeature(
                f"{call} on the {engine} engine while mesh {name!r} moves: PyGran places these "
                "particles clear of the walls, and where the mesh is now only the solver knows; make "
                "them before moveMesh"
            )
        return next(m for m in self.spec.meshes if m.name == name).triangles()

    def obstacles(self, meshes: list[np.ndarray]) -> Obstacles:
        """The walls new particles must clear, with the mesh walls' triangles ``meshes``."""
        return wall_obstacles(self.walls.values(), meshes)
