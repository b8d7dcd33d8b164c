"""What every area of the engine suite shares: its constants and features, the reference time
step, and :class:`EngineSuite`, the set-up each area's checks build their scenarios with."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from pygran_core import params, registry
from pygran_core.errors import PluginNotFound
from pygran_core.hookspecs import CAPABILITIES
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.models import ContactModel, HertzMindlin, SpringDashpot, ThorntonNing
from pygran_core.simulation.timestep import Body, characteristic_speed, limits
from pygran_core.testing.solvers import in_ci, require_solver

#: The suite's features that no capability names, which an engine may refuse (with
#: :class:`UnsupportedFeature`) if its test class lists them in ``refuses``.
SUITE_FEATURES: Mapping[str, str] = {
    "insert": "insert() by pack",
    "create-array": "createParticles(species, 'single', positions) with an (N, 3) array",
    "create-lattice": "createParticles(species, 'lattice', spacing, region=...)",
    "create-random": "createParticles(species, 'random', count, region=...)",
    "set": "set(vel=..., omega=...) and velocity()",
    "set-radius": "set(radius=...)",
    "viscous": "addViscous()",
    "monitor-ke_rot": "the monitor quantity 'ke_rot'",
    "monitor-contacts": "the monitor quantity 'contacts'",
    "monitor-wall_force": "the monitor quantity 'wall_force'",
}
#: The contact models, in the order a scenario picks the first one an engine declares.
MODELS: tuple[type[ContactModel], ...] = (HertzMindlin, SpringDashpot, ThorntonNing)
RADIUS = 1e-3
#: The material of the scenarios that need no other: the original PyGran's ``organic``.
MATERIAL: Mapping[str, float] = params.MATERIALS["organic"]
G = 9.81
GRAVITY = (G, 0.0, 0.0, -1.0)
BOX = (-0.01, 0.01, -0.01, 0.01, -0.01, 0.01)


def safe_dt(model: type[ContactModel], materials: Sequence[Mapping[str, float]], radius: float) -> float:
    """The time step the time-step check (:mod:`~pygran_core.simulation.timestep`) takes as safe
    for spheres of ``radius`` of each material meeting each other and walls of each material."""
    bodies = [Body(f"species {k}", m, radius, m["density"]) for k, m in enumerate(materials, start=1)]
    pairs = [(a, b) for a in bodies for b in bodies]
    pairs += [(a, Body(f"wall {k}", m)) for a in bodies for k, m in enumerate(materials, start=1)]
    found = limits(model, pairs, characteristic_speed(materials))
    assert found is not None
    return found.safe_dt


def create(sim: DEM, positions: Any, **keywords: Any) -> None:
    """Spheres of species 1 at ``positions``, created one by one (the array form has a test of
    its own)."""
    for position in np.asarray(positions, float):
        sim.createParticles(1, "single", *position, **keywords)


@dataclass
class Outcome:
    """A scenario's result, or the exception it raised (kept to be raised where it is read)."""

    value: Any = None
    error: BaseException | None = None

    def get(self) -> Any:
        if self.error is not None:
            raise self.error
        return self.value


def attempt(scenario: Callable[[], Any]) -> Outcome:
    """Run ``scenario`` and keep its result or its exception."""
    try:
        return Outcome(scenario())
    except Exception as exc:  # noqa: BLE001 - kept and raised in each test that reads it
        return Outcome(error=exc)


class Lazy(dict):
    """A dict whose missing entries are made by ``make(key)`` when first read."""

    def __init__(self, make: Callable[[str], Any]) -> None:
        super().__init__()
        self.make = make

    def __missing__(self, key: str) -> Any:
        self[key] = value = self.make(key)
        return value


class EngineSuite:
    """The set-up of the engine suite's checks: what the engine is and declares, and a
    simulation on it (see :mod:`pygran_core.testing.engines`)."""

    #: The engine's registered name.
    engine: ClassVar[str]
    #: ``DEM`` keywords added to every simulation of the suite (``threads``, ``nprocs``).
    options: ClassVar[Mapping[str, Any]] = {}
    #: Features of :data:`SUITE_FEATURES` the engine refuses with :class:`UnsupportedFeature`.
    refuses: ClassVar[frozenset[str]] = frozenset()
    #: A solver-native command giving particle 1 (the only one) the velocity (0.5, 0, 0): the
    #: check of ``raw-commands``, required of an engine that declares it.
    raw_command: ClassVar[str | None] = None

    @pytest.fixture(scope="class")
    @classmethod
    def engine_plugin(cls) -> Iterator[None]:
        """Make the engine's plugin importable (override to install one for the tests)."""
        yield

    @pytest.fixture(scope="class", autouse=True)
    @classmethod
    def engine_ready(cls, engine_plugin: None) -> None:
        """The engine is registered and finds its solver: else a failure under CI, a skip elsewhere."""
        try:
            spec = registry.get_engine(cls.engine)
        except PluginNotFound as exc:
            if in_ci():
                pytest.fail(f"CI=true and the {cls.engine} engine is missing: {exc}", pytrace=False)
            pytest.skip(str(exc))
        if spec.locate_solver is not None:
            require_solver(spec.locate_solver)

    @property
    def capabilities(self) -> frozenset[str]:
        return registry.get_engine(self.engine).capabilities

    def supports(self, feature: str) -> bool:
        """A capability the engine declares, or a suite feature it does not refuse."""
        if feature in CAPABILITIES:
            return feature in self.capabilities
        assert feature in SUITE_FEATURES, f"unknown feature {feature!r}"
        return feature not in self.refuses

    @property
    def model(self) -> type[ContactModel]:
        """The first of :data:`MODELS` the engine declares."""
        declared = [m for m in MODELS if m.kernel in self.capabilities]
        assert declared, f"the {self.engine} engine declares no contact model"
        return declared[0]

    def dt(self, radius: float = RADIUS) -> float:
        """The safe time step (:func:`safe_dt`) for spheres of :data:`MATERIAL` of ``radius``."""
        return safe_dt(self.model, (MATERIAL,), radius)

    def dem(self, output: Path, radius: float = RADIUS, **keywords: Any) -> DEM:
        """A simulation on this engine writing to ``output``: one species of :data:`MATERIAL`
        unless ``species`` is given, no trajectory, no progress bar, the class's options."""
        settings: dict[str, Any] = {
            "engine": self.engine,
            "model": self.model,
            "output": str(output),
            "progress": False,
            "traj": {"pfile": None},
            "species": ({"material": dict(MATERIAL), "radius": radius},),
            "box": BOX,
            **self.options,
        }
        return DEM(**settings | keywords)
