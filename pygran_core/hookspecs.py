"""Plugin hooks: what an engine, contact-model or file-format plugin implements.

A plugin is a distribution with one entry point in one of the groups ``pygran.engines``,
``pygran.models`` or ``pygran.readers`` naming a module of :data:`hookimpl` functions.
Each hook returns (or yields) small frozen records defined here. The registry
(:mod:`pygran_core.registry`) loads every plugin, checks the records and answers lookups.

Hook names are shared across groups (pluggy keeps one namespace), so a single module may
implement several hooks, e.g. a reader plugin that is also a writer plugin.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pluggy

from pygran_core.formats.base import Trajectory, TrajectoryWriter

PROJECT = "pygran"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)

#: Capabilities an engine may declare; a request outside an engine's set raises
#: :class:`~pygran_core.errors.UnsupportedFeature` naming the engines that have it.
CAPABILITIES = frozenset(
    {
        "mesh-walls",  # triangle-mesh walls from STL
        "moving-mesh",  # translating / rotating / wiggling mesh walls
        "mesh-vibration",  # moveMesh viblin and vibrot
        "servo-walls",  # mesh/surface/stress/servo meshes
        "primitive-walls",  # analytic planes and cylinders
        "periodic",  # periodic boundaries
        "polydisperse",  # size distributions within a species
        "pair-tables",  # DEM(pairs=...): per-pair material values, read from the material table
        "multisphere",  # clumped spheres
        "spring-dashpot",
        "hertz-mindlin",
        "thornton-ning",
        "cohesion",  # SJKR / JKR adhesion
        "rolling-friction",  # rolling resistance, LIGGGHTS' cdt model
        "rolling-epsd",  # the other rolling-resistance models (ContactModel.configure(rolling=...))
        "rolling-epsd2",
        "rolling-epsd3",
        "limit-force",  # ContactModel.configure(limitForce=True): no attractive visco-elastic force
        "insert-by-rate",
        "mpi",  # runs on several MPI ranks
        "threads",  # shared-memory parallelism within one process
        "restart",  # checkpoint and resume
        "raw-commands",  # pass solver-native commands through
        "monitor-species",  # monitor(var=..., species=...) of some species only
        "liggghts-dump",  # LIGGGHTS' dump settings: dump_modify, traj margs
        "neighbor-styles",  # nns_type other than 'bin' (LIGGGHTS' neighbor nsq, multi)
        "contact-output",  # per-contact records in the trajectory (traj cfile)
    }
)


def _known_capabilities(engine: str, capabilities: Iterable[str]) -> frozenset[str]:
    """``capabilities`` as a frozenset, or a ValueError if one is not in :data:`CAPABILITIES`."""
    unknown = set(capabilities) - CAPABILITIES
    if unknown:
        raise ValueError(
            f"Engine {engine!r} declares unknown capabilities {sorted(unknown)}; "
            f"known: {sorted(CAPABILITIES)}"
        )
    return frozenset(capabilities)


class _Capabilities:
    """The field :attr:`EngineSpec.capabilities`, always read as a frozenset. It is given as a
    set, checked at once, or as a function returning one, called and checked when they are
    first read: for capabilities that cost something to find out (whether a solver's add-on
    loads), which loading the registry must not pay for."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = f"_{name}"

    def __get__(self, spec: EngineSpec | None, owner: type) -> frozenset[str]:
        if spec is None:
            return frozenset()  # the field's default
        value = getattr(spec, self.slot)
        if callable(value):
            value = _known_capabilities(spec.name, value())
            object.__setattr__(spec, self.slot, value)
        return value

    def __set__(self, spec: EngineSpec, value: Iterable[str] | Callable[[], Iterable[str]]) -> None:
        checked = value if callable(value) else _known_capabilities(spec.name, value)
        object.__setattr__(spec, self.slot, checked)


@dataclass(frozen=True)
class EngineSpec:
    """An engine a plugin provides.

    ``factory(spec)`` builds the :class:`~pygran_core.simulation.engine.Engine` from a
    :class:`~pygran_core.simulation.specs.SimulationSpec` (typed loosely: the records are a leaf
    module, below the engine base class, which looks up writers through the registry);
    ``capabilities`` are a set or a function returning one, called once, when first read;
    ``locate_solver()`` returns a one-line description of the solver it will drive (path,
    version, threads) or raises :class:`~pygran_core.errors.EngineError` whose message
    says how to install the missing solver.
    """

    name: str
    factory: Callable[..., Any]
    capabilities: _Capabilities = _Capabilities()
    description: str = ""
    locate_solver: Callable[[], str] | None = None

    def __post_init__(self) -> None:
        _check_name(self.name)


@dataclass(frozen=True)
class ModelSpec:
    """A contact model (a :class:`~pygran_core.simulation.models.ContactModel` subclass)."""

    name: str
    model: type
    description: str = ""

    def __post_init__(self) -> None:
        _check_name(self.name)


@dataclass(frozen=True)
class ReaderSpec:
    """A trajectory or mesh file format that can be read.

    ``open(paths, **options)`` returns a lazy :class:`~pygran_core.io.Trajectory` over one
    file or an ordered sequence of files (one frame each, or many). ``extensions`` are
    matched against the end of the file name, longest first (``".dump.gz"`` before
    ``".gz"``). ``can_open(path)`` may look at the first bytes of a file and say whether
    this reader understands it; it must be cheap and never raise.
    ``kinds`` says what the format holds: ``"particles"``, ``"mesh"``, ``"contacts"`` (the
    records of :mod:`~pygran_core.formats.contacts`), or several.
    """

    name: str
    extensions: tuple[str, ...]
    open: Callable[..., Trajectory]
    can_open: Callable[[Path], bool] | None = None
    kinds: frozenset[str] = frozenset({"particles"})
    description: str = ""

    def __post_init__(self) -> None:
        _check_name(self.name)
        _check_extensions(self.name, self.extensions)
        object.__setattr__(self, "kinds", frozenset(self.kinds))


@dataclass(frozen=True)
class WriterSpec:
    """A file format that can be written, one frame at a time.

    ``open(path, **options)`` returns a :class:`~pygran_core.io.TrajectoryWriter`.
    """

    name: str
    extensions: tuple[str, ...]
    open: Callable[..., TrajectoryWriter]
    kinds: frozenset[str] = frozenset({"particles"})
    description: str = ""
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_name(self.name)
        _check_extensions(self.name, self.extensions)
        object.__setattr__(self, "kinds", frozenset(self.kinds))


def _check_name(name: str) -> None:
    if not name or not name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"Plugin item name {name!r} must be a non-empty identifier-like string")


def _check_extensions(name: str, extensions: tuple[str, ...]) -> None:
    bad = [ext for ext in extensions if not ext.startswith(".")]
    if bad:
        raise ValueError(f"Format {name!r}: extensions must start with '.', got {bad}")


@hookspec
def pygran_engines() -> Iterable[EngineSpec]:
    """Return the engines this plugin provides.

    A complete engine plugin (``pyproject.toml`` then ``pygran_toy/plugin.py``)::

        [project.entry-points."pygran.engines"]
        toy = "pygran_toy.plugin"

        import numpy as np
        from pygran_core import Engine, hookimpl
        from pygran_core.hookspecs import EngineSpec

        class ToyEngine(Engine):
            # Particles that fly in straight lines, without contacts: it runs no model's
            # kernel, so it declares none (tests/plugins/pygran-toy is an engine with
            # spring-dashpot contacts that declares "spring-dashpot").

            name = "toy"
            capabilities = frozenset({"periodic"})

            def __init__(self, spec):  # spec: pygran_core.simulation.specs.SimulationSpec
                super().__init__(spec)
                self.x, self.v = np.zeros((0, 3)), np.zeros((0, 3))

            def _create(self, request):  # createParticles(1, 'single', x, y, z, vel=...)
                self.x = np.vstack([self.x, request.position])
                self.v = np.vstack([self.v, request.velocity])
                return 1

            def _advance(self, nsteps):
                self.x = self.x + nsteps * self.dt * self.v

            def _extract(self, quantity):
                return {"x": self.x, "v": self.v}[quantity]

        @hookimpl
        def pygran_engines():
            yield EngineSpec(name="toy", factory=ToyEngine, capabilities=ToyEngine.capabilities)
    """


@hookspec
def pygran_models() -> Iterable[ModelSpec]:
    """Return the contact models this plugin provides.

    A complete model plugin::

        [project.entry-points."pygran.models"]
        stiff = "pygran_stiff.plugin"

        from pygran_core import hookimpl
        from pygran_core.hookspecs import ModelSpec
        from pygran_core.simulation.models import SpringDashpot

        class StiffSpring(SpringDashpot):
            '''A spring-dashpot with ten times the stiffness: a reference model for
            contactTime() and displacement(); it overrides normal_force, so it has no
            kernel and engines refuse it (see ContactModel.kernel).'''

            def normal_force(self, overlap, overlap_rate):
                return 10 * super().normal_force(overlap, overlap_rate)

        @hookimpl
        def pygran_models():
            yield ModelSpec(name="StiffSpring", model=StiffSpring)
    """


@hookspec
def pygran_readers() -> Iterable[ReaderSpec]:
    """Return the file formats this plugin reads.

    A complete reader plugin for a CSV format with one frame per file::

        [project.entry-points."pygran.readers"]
        csv = "pygran_csv.plugin"

        import numpy as np
        from pygran_core import hookimpl
        from pygran_core.hookspecs import ReaderSpec
        from pygran_core.io import Frame, Trajectory

        class CSVTrajectory(Trajectory):
            def __init__(self, paths, **options):
                self.paths = list(paths)

            @property
            def n_frames(self):
                return len(self.paths)

            def _read_frame(self, index):
                table = np.genfromtxt(self.paths[index], delimiter=",", names=True)
                return Frame({name: table[name] for name in table.dtype.names})

        @hookimpl
        def pygran_readers():
            yield ReaderSpec(name="csv", extensions=(".csv",), open=CSVTrajectory)
    """


@hookspec
def pygran_writers() -> Iterable[WriterSpec]:
    """Return the file formats this plugin writes.

    A complete writer plugin (in the same module as its reader, or its own)::

        import numpy as np
        from pygran_core import hookimpl
        from pygran_core.hookspecs import WriterSpec
        from pygran_core.io import TrajectoryWriter

        class CSVWriter(TrajectoryWriter):
            def __init__(self, path, **options):
                self.path = path

            def write_frame(self, frame):
                names = list(frame.arrays)
                table = np.column_stack([frame.arrays[n] for n in names])
                np.savetxt(self.path, table, delimiter=",", header=",".join(names), comments="")

        @hookimpl
        def pygran_writers():
            yield WriterSpec(name="csv", extensions=(".csv",), open=CSVWriter)
    """
