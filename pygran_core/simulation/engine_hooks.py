"""What an engine is to the core: its name, its capabilities and its hooks, the methods the
:class:`~pygran_core.simulation.engine.Engine` base class calls and a plugin engine implements.

Every hook is declared here, with the capability it serves (:data:`HOOKS`); a hook that has a
default here may be left out. A plugin engine overrides hooks and nothing else of the base
class (``tests/test_architecture.py`` refuses any other name): the base's run loop, checks,
output, journal and checkpoints are the same for every engine.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np

from pygran_core.errors import UnsupportedFeature
from pygran_core.io import Frame
from pygran_core.registry import engines_with
from pygran_core.simulation.calls import CreateSpec, InsertSpec, MotionSpec, SetSpec, ViscousSpec, WallSpec
from pygran_core.simulation.diagnostics import LostParticles, check_spec
from pygran_core.simulation.insertion import Inserter
from pygran_core.simulation.output import NativeTrajectory, contacts_frame
from pygran_core.simulation.specs import SimulationSpec

#: Every hook by name: the capability it serves (``None``: engines of any capability).
HOOKS: dict[str, str | None] = {"name": None, "capabilities": None, "max_run_chunks": None, "inserter": None}

Method = TypeVar("Method", bound=Callable[..., Any])


@dataclass(frozen=True)
class Handle:
    """What an engine call such as ``insert`` or ``setupWall`` returns; pass it to ``remove``."""

    kind: str
    id: int
    label: str
    engine_id: int


def hook(capability: str | None = None) -> Callable[[Method], Method]:
    """Declare the decorated method a hook (of engines with ``capability``), in :data:`HOOKS`."""

    def declare(method: Method) -> Method:
        HOOKS[method.__name__] = capability
        return method

    return declare


def require_capability(engine: str, capabilities: frozenset[str], capability: str, what: str | None) -> None:
    """Raise :class:`UnsupportedFeature`, naming the installed engines that can, unless the
    engine ``engine`` has ``capability`` among its ``capabilities``."""
    if capability in capabilities:
        return
    able = [name for name in engines_with(capability) if name != engine]
    alternative = f"Engines that can: {', '.join(able)}." if able else "No installed engine can."
    raise UnsupportedFeature(
        f"The {engine} engine does not support {what or capability} "
        f"(capability {capability!r}). {alternative}"
    )


class EngineHooks(abc.ABC):
    """An engine's name, :attr:`capabilities` and hooks. Hooks receive validated specs; those
    of calls return the solver's label for what they created. A hook of a call the engine
    does not support raises :class:`UnsupportedFeature` (:meth:`_unsupported`)."""

    name: ClassVar[str] = "engine"
    capabilities: ClassVar[frozenset[str]] = frozenset()
    #: Upper bound on the progress updates (and Python round trips) per ``run`` between events.
    max_run_chunks: ClassVar[int] = 100
    #: The engine's :class:`~pygran_core.simulation.insertion.Inserter`, which places the
    #: particles of ``insert`` and ``createParticles`` when its solver cannot.
    inserter: Inserter | None = None

    #: Set by the base class; hooks read them.
    spec: SimulationSpec
    step: int
    time: float
    dt: float | None

    def require(self, capability: str, what: str | None = None) -> None:
        """Raise :class:`UnsupportedFeature` unless this engine has ``capability``."""
        try:
            require_capability(self.name, self.capabilities, capability, what)
        except UnsupportedFeature as exc:
            reason = self._why_missing(capability)
            if not reason:
                raise
            raise UnsupportedFeature(f"{exc} {reason}") from None

    def _unsupported(self, what: str) -> UnsupportedFeature:
        return UnsupportedFeature(f"The {self.name} engine does not implement {what}")

    # -- the solver ---------------------------------------------------------------------------

    @hook()
    @abc.abstractmethod
    def _advance(self, nsteps: int) -> None:
        """Integrate ``nsteps`` steps of :attr:`dt` in the solver."""

    @hook()
    @abc.abstractmethod
    def _extract(self, quantity: str) -> np.ndarray:
        """A per-particle quantity ordered by id: (N, 3) for vectors, (N,) for scalars."""

    @hook()
    def _check_spec(self, spec: SimulationSpec) -> None:
        """Refuse, before the solver starts, whatever of ``spec`` this engine cannot do (the
        capabilities it needs, :func:`.diagnostics.check_spec`; an engine adds its own limits)."""
        check_spec(spec, self.require)

    @hook()
    def _why_missing(self, capability: str) -> str:
        """Why this engine lacks ``capability``, added to its refusal (LIGGGHTS: its add-on did
        not load); empty: no more to say."""
        return ""

    @hook()
    def _default_dt(self) -> float | None:
        """The time step of a run when neither ``DEM(dt=...)`` nor ``run`` gives one (YADE: a
        fraction of its p-wave estimate); ``None``: the run is refused."""
        return None

    @hook()
    def _writes_output(self) -> bool:
        """Whether this process writes the simulation's files and messages: of the MPI ranks
        that share one simulation (LIGGGHTS under ``mpirun``), the first only."""
        return True

    @hook()
    def _lost_since_last(self) -> LostParticles | None:
        """Particles the solver lost (left a fixed boundary, became non-finite, were deleted)
        since the last call. ``None``: this engine does not count them, and ``run`` finds them
        by comparing the particles from one piece of the run to the next."""
        return None

    @hook()
    def _event_steps(self, start: int, end: int) -> set[int]:
        """Steps in ``(start, end]`` at which the engine must be back in Python: those of its
        :attr:`inserter`'s insertions, and of insertions the engine makes itself."""
        return set() if self.inserter is None else self.inserter.due_steps(start, end)

    @hook()
    def _close(self) -> None:
        """Release solver resources; engines holding any override."""

    # -- calls --------------------------------------------------------------------------------

    @hook()
    def _insert(self, spec: InsertSpec) -> str:
        if self.inserter is None:
            raise self._unsupported("insert")
        return self.inserter.insert(spec)

    @hook()
    def _create(self, spec: CreateSpec) -> int:
        if self.inserter is None:
            raise self._unsupported("createParticles")
        return self.inserter.create(spec)

    @hook()
    def _assign(self, ids: np.ndarray, spec: SetSpec) -> None:
        """Give the particles with these ids the spec's velocity, omega and/or radius."""
        raise self._unsupported("set/velocity")

    @hook()
    def _wall(self, spec: WallSpec) -> str:
        raise self._unsupported("setupWall")

    @hook("moving-mesh")
    def _move_mesh(self, spec: MotionSpec) -> str:
        raise self._unsupported("moveMesh")

    @hook()
    def _viscous(self, spec: ViscousSpec) -> str:
        raise self._unsupported("addViscous")

    @hook("raw-commands")
    def _command(self, text: str) -> None:
        raise self._unsupported("raw commands")

    @hook()
    def _remove(self, handle: Handle) -> None:
        """Delete the solver object behind ``handle`` (a wall, a motion, a force; the
        :attr:`inserter` removes its insertions)."""
        raise UnsupportedFeature(f"The {self.name} engine cannot remove a {handle.kind}")

    # -- what the solver holds -------------------------------------------------------------------

    @hook()
    def _scalar(self, quantity: str) -> float:
        """A monitored scalar (see :data:`~pygran_core.simulation.calls.MONITOR_QUANTITIES`)."""
        if quantity == "n":
            return float(len(self._extract("id")))
        if quantity == "time":
            return self.time
        if quantity == "ke":
            v = self._extract("v")
            return float(0.5 * np.sum(self._extract("mass") * np.einsum("ij,ij->i", v, v)))
        raise self._unsupported(f"the monitor quantity {quantity!r}")

    @hook("monitor-species")
    def _species_scalar(self, quantity: str, species: tuple[int, ...]) -> float:
        """A monitored scalar of the particles of ``species`` only: ``n``, ``time``, ``ke`` and,
        for spheres, ``ke_rot``."""
        if quantity == "time":
            return self.time
        chosen = np.isin(self._extract("type"), species)
        if quantity == "n":
            return float(np.count_nonzero(chosen))
        if quantity in ("ke", "ke_rot"):
            mass = self._extract("mass")[chosen]
            if quantity == "ke":
                speed = self._extract("v")[chosen]
                return float(0.5 * np.sum(mass * np.einsum("ij,ij->i", speed, speed)))
            if any(s.style == "multisphere" for s in self.spec.species if s.type in species):
                raise self._unsupported("a ke_rot monitor of multisphere species")
            spin = self._extract("omega")[chosen]
            inertia = 0.4 * mass * self._extract("radius")[chosen] ** 2
            return float(0.5 * np.sum(inertia * np.einsum("ij,ij->i", spin, spin)))
        raise self._unsupported(f"the monitor quantity {quantity!r} of some species")

    @hook("multisphere")
    def bodies(self) -> np.ndarray:
        """The body of each sphere, ordered by id as ``extract``: a positive id for the spheres
        of a multisphere particle (those of one in its template's order), -1 for single spheres."""
        raise self._unsupported("multisphere bodies")

    @hook("mesh-walls")
    def _mesh_triangles(self, name: str) -> np.ndarray | None:
        """The corners ``(T, 3, 3)`` of mesh wall ``name``'s triangles where they are now;
        ``None``: where the mesh file puts them, unless ``moveMesh`` moved the mesh (then the
        solver alone knows, and what needs them is refused)."""
        return None

    @hook("servo-walls")
    def mesh_force(self, name: str) -> np.ndarray:
        """The force (N, x y z) the particles exert on mesh ``name`` at the last step (``mtype``
        ``mesh/surface/stress`` or ``mesh/surface/stress/servo``), as on LIGGGHTS."""
        raise self._unsupported("forces on meshes")

    # -- output ---------------------------------------------------------------------------------

    @hook("contact-output")
    def _contacts(self) -> dict[str, np.ndarray]:
        """Every contact now, as the columns of :data:`pygran_core.formats.contacts.COLUMNS`:
        pairs once each, walls with ``id2 = -(k + 1)`` for the k-th wall set up."""
        raise self._unsupported("contact output")

    @hook("contact-output")
    def _contact_frames(self) -> list[Frame]:
        """The contacts frames due now: one of :meth:`_contacts`; an engine whose solver writes
        them (LIGGGHTS) gives those written since the last call."""
        records = self._contacts()
        return [
            contacts_frame(
                self.spec, records, f"the {self.name} engine's contact records", self.step, self.time
            )
        ]

    @hook()
    def _native_trajectories(self) -> Mapping[str, NativeTrajectory]:
        """The trajectories (``particles``, ``meshes``) the engine's solver writes itself, with
        how each is cut back on resume: PyGran writes none of their frames."""
        return {}

    # -- checkpoints ------------------------------------------------------------------------------

    @hook("restart")
    def _state(self) -> dict[str, np.ndarray]:
        """The solver's state for a checkpoint, as named arrays (names may contain ``/``)."""
        return {}

    @hook("restart")
    def _restore_state(self, state: dict[str, np.ndarray]) -> None:
        """Put back a :meth:`_state` result; the script's calls up to it have been replayed."""

    @hook("restart")
    def _facts(self) -> dict[str, Any]:
        """What must be the same on resume for a bitwise continuation (e.g. thread count)."""
        return {}

    @hook("restart")
    def _checkpoint_files(self) -> list[Path]:
        """The files beside the checkpoint being written that it needs (LIGGGHTS' restart
        file); those of a checkpoint the next one replaces are deleted."""
        return []
