"""Conformance tests every DEM engine passes, in the style of MDAnalysis' reader tests.

An engine plugin's tests subclass :class:`EngineConformance` once::

    class TestNative(EngineConformance):
        engine = "native"
        options = {"threads": 1}

The suite runs every front-end call of :class:`~pygran_core.simulation.DEM` (``insert`` by
pack and by rate with schedules, every ``createParticles`` form, ``setupWall`` primitive and
mesh, every ``moveMesh`` style, ``addViscous``, ``monitor``, ``set``, ``run``, ``remove``,
``extract*``, ``close``, a restart round trip), settles a sphere and a stack of two on a
floor for every material of :data:`pygran_core.params.MATERIALS`, and compares impacts of
every contact model with the reference models (:mod:`pygran_core.testing.validation`). Each optional
setting is run with and without: it must change the result (as its closed form says, where
one exists) or raise :class:`~pygran_core.errors.UnsupportedFeature`, never be ignored.

What runs is decided by the engine's declared capabilities (``EngineSpec.capabilities``):
a declared capability is checked in full, an undeclared one must raise
:class:`UnsupportedFeature`. Features of the suite that no capability names
(:data:`SUITE_FEATURES`: ``createParticles`` forms, ``insert``, ``set``, drag, optional
monitor quantities...) are required unless the subclass lists them in
:attr:`EngineConformance.refuses`, and then they must raise :class:`UnsupportedFeature`.

The mesh tests read ``meshes/silo.stl`` from the ``data_dir`` fixture (the repository's
``tests/data``, from the root ``conftest.py``); a subclass may override the fixture. A
subclass whose engine needs installing first overrides the class-scoped ``engine_plugin``
fixture. A missing engine or solver fails under ``CI=true`` and skips elsewhere.
Scenarios use small particle counts and few steps; the set-ups several tests share run once
per class. Requires pytest.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq
from scipy.spatial.distance import pdist

from pygran_core import params, registry
from pygran_core.errors import (
    ConfigError,
    EngineError,
    LostParticlesWarning,
    PluginNotFound,
    TimeStepWarning,
    UnsupportedFeature,
)
from pygran_core.hookspecs import CAPABILITIES
from pygran_core.io import open_trajectory
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.insertion import triangle_distance
from pygran_core.simulation.models import ContactModel, HertzMindlin, SpringDashpot, ThorntonNing
from pygran_core.simulation.timestep import Body, characteristic_speed, limits
from pygran_core.testing import mistakes
from pygran_core.testing.solvers import in_ci, require_solver
from pygran_core.testing.validation import (
    IMPACT_MATERIALS,
    IMPACT_SPEED,
    STEPS_PER_CONTACT,
    Collision,
    check_hertz,
    format_table,
    one_species,
    sphere_mass,
    wall_impact,
)

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
#: The pair values of the pair-table checks (Dosta et al. 2024's M1-M2 pair).
PAIR: Mapping[str, float] = {"coefficientRestitution": 0.45, "coefficientFriction": 0.2}
#: The period of the mesh motions (a quarter of it is the time each is run for, at least).
MOTION_PERIOD = 0.04
#: The settle runs until the slowest vibration about rest has fallen to this fraction.
SETTLE_DECAY = 1e-2


# -- reference values ---------------------------------------------------------------------------


def safe_dt(model: type[ContactModel], materials: Sequence[Mapping[str, float]], radius: float) -> float:
    """The time step the time-step check (:mod:`~pygran_core.simulation.timestep`) takes as safe
    for spheres of ``radius`` of each material meeting each other and walls of each material."""
    bodies = [Body(f"species {k}", m, radius, m["density"]) for k, m in enumerate(materials, start=1)]
    pairs = [(a, b) for a in bodies for b in bodies]
    pairs += [(a, Body(f"wall {k}", m)) for a in bodies for k, m in enumerate(materials, start=1)]
    found = limits(model, pairs, characteristic_speed(materials))
    assert found is not None
    return found.safe_dt


def rest_overlap(model: ContactModel, load: float) -> float:
    """The overlap at which the reference model's elastic force (cohesion included) carries
    ``load``: the force less the load is negative at touch and grows past zero once."""
    top = (load / model.effective_modulus / math.sqrt(model.effective_radius)) ** (2 / 3)
    while float(model.normal_force(top, 0.0)) < load:
        top *= 2
    return brentq(lambda delta: float(model.normal_force(delta, 0.0)) - load, 1e-30, top, xtol=1e-30)


def sink_energy(model: ContactModel, load: float, overlap: float) -> float:
    """The energy a body under ``load`` set down touching has, above its rest at ``overlap``:
    the work ``load - F(delta)`` does from touch to rest (more than ``load * overlap`` with
    cohesion, which pulls the body in)."""
    return quad(lambda delta: load - float(model.normal_force(delta, 0.0)), 0.0, overlap)[0]


def slowest_decay(mass: float, *contacts: tuple[ContactModel, float]) -> float:
    """Decay rate (1/s) of the least damped vertical vibration of a column of spheres of
    ``mass`` about rest, each resting on the one below (the first on the floor) through a
    contact ``(model, rest overlap)``: the smallest ``-Re(lambda)`` of the column's equations
    linearised about rest (the models' tangent stiffness and damping)."""
    n = len(contacts)
    stiffness, damping = np.zeros((n, n)), np.zeros((n, n))
    for i, (model, delta) in enumerate(contacts):
        k = float(model.normal_force(delta * 1.000001, 0.0) - model.normal_force(delta, 0.0)) / (delta * 1e-6)
        c = float(model.normal_force(delta, 1.0) - model.normal_force(delta, 0.0))
        for matrix, value in ((stiffness, k), (damping, c)):  # between spheres i - 1 and i
            matrix[i, i] += value
            if i > 0:
                matrix[i - 1, i - 1] += value
                matrix[i, i - 1] -= value
                matrix[i - 1, i] -= value
    system = np.block([[np.zeros((n, n)), np.eye(n)], [-stiffness / mass, -damping / mass]])
    return float(-np.linalg.eigvals(system).real.max())


def pair_impact(
    engine: str,
    output: Path,
    model: type[ContactModel],
    material: Mapping[str, float],
    radius: float = RADIUS,
    speed: float = IMPACT_SPEED,
    **options: Any,
) -> Collision:
    """Two equal spheres approaching head-on at ``speed`` each, without gravity (no wall needed).

    As in :func:`~pygran_core.testing.validation.wall_impact`: the time step is 1/400 of the reference
    model's contact time, and the contact ends when the free flight after it extrapolates back
    to touching. ``options`` are further ``DEM`` keywords (``threads``, ``nprocs``)."""
    sphere = dict(material, radius=radius)
    dt = model(material=sphere, partner=sphere).contactTime(2 * speed) / STEPS_PER_CONTACT
    box = (-4 * radius, 4 * radius, -2 * radius, 2 * radius, -2 * radius, 2 * radius)
    with one_species(engine, output, material, radius, model=model, box=box, dt=dt, **options) as sim:
        for side in (-1, 1):
            start = side * (radius + 0.5 * speed * dt)  # touching half a step after the start
            sim.createParticles(1, "single", start, 0.0, 0.0, vel=(-side * speed, 0.0, 0.0))
        sim.run(4 * STEPS_PER_CONTACT)
        x, v, end = sim.extractCoords()[:, 0], sim.extractVelocities()[:, 0], sim.time
    gap, separating = x[1] - x[0] - 2 * radius, v[1] - v[0]
    if gap <= 0 or separating <= 0:
        return Collision(math.inf, 0.0)
    return Collision(end - gap / separating - dt / 2, separating / (2 * speed))


def reference_collision(model: ContactModel, speed: float) -> Collision:
    """What :func:`pair_impact` and :func:`~pygran_core.testing.validation.wall_impact` measure, from the
    reference model: restitution, and the time the bodies spend closer than touching (for a
    plastic contact, the contact time plus the flight back over its permanent overlap)."""
    impact = model.displacement(speed)
    overlap, rate = impact.soln[-1]
    return Collision(impact.contact_time + overlap / abs(rate), impact.restitution)


#: The createParticles scenario's (N, 3) array, lattice and random region (see ``created``).
ARRAY = np.array([[x, y, -7e-3] for x in (-3e-3, 0.0, 3e-3) for y in (-3e-3, 0.0, 3e-3)])
LATTICE_SPACING = 2.5 * RADIUS
LATTICE_BOUNDS = tuple(v for n in (3, 2, 2) for v in (0.25 * LATTICE_SPACING, (n + 0.25) * LATTICE_SPACING))
LATTICE_REGION = ("block", *LATTICE_BOUNDS)
RANDOM_REGION = ("block", -9e-3, -1e-3, -9e-3, -1e-3, -5e-3, 5e-3)


def extracted(sim: DEM) -> dict[str, np.ndarray]:
    """Every extract* of ``sim``."""
    return {
        "id": sim.extractIds(),
        "x": sim.extractCoords(),
        "v": sim.extractVelocities(),
        "omega": sim.extractOmegas(),
        "f": sim.extractForces(),
        "radius": sim.extractRadii(),
    }


def create(sim: DEM, positions: Any, **keywords: Any) -> None:
    """Spheres of species 1 at ``positions``, created one by one (the array form has a test of
    its own)."""
    for position in np.asarray(positions, float):
        sim.createParticles(1, "single", *position, **keywords)


# -- the suite ----------------------------------------------------------------------------------


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


class EngineConformance:
    """Base class of an engine's conformance tests; see the module docstring."""

    #: The engine's registered name.
    engine: ClassVar[str]
    #: ``DEM`` keywords added to every simulation of the suite (``threads``, ``nprocs``).
    options: ClassVar[Mapping[str, Any]] = {}
    #: Features of :data:`SUITE_FEATURES` the engine refuses with :class:`UnsupportedFeature`.
    refuses: ClassVar[frozenset[str]] = frozenset()
    #: A solver-native command giving particle 1 (the only one) the velocity (0.5, 0, 0): the
    #: check of ``raw-commands``, required of an engine that declares it.
    raw_command: ClassVar[str | None] = None

    # -- set-up ------------------------------------------------------------------------------

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

    # -- registration, createParticles, extract, close ---------------------------------------------

    @pytest.fixture(scope="class")
    @classmethod
    def created(cls, tmp_path_factory) -> dict[str, Outcome]:
        """One simulation without gravity, each ``createParticles`` form in its own part of the
        box: what each created (or raised), the particles after 200 steps, the engine's name
        and capabilities, and what calls raise once it is closed."""
        suite = cls()
        dt = suite.dt(0.8 * RADIUS)
        output = tmp_path_factory.mktemp("created")
        forms: dict[str, tuple[Any, ...]] = {
            "single": (
                (-6e-3, 6e-3, 8e-3, {"vel": (0.1, -0.2, 0.05), "omega": (1.0, 2.0, 3.0)}),
                (-6e-3, 2e-3, 8e-3, {"radius": 0.8 * RADIUS}),
            ),
            "array": (ARRAY, {"vel": (0.0, 0.0, 0.1)}),
            "lattice": (LATTICE_SPACING, {"region": LATTICE_REGION}),
            "random": (20, {"region": RANDOM_REGION}),
        }

        def run(sim: DEM) -> tuple[Any, int, float]:
            """The particles after 200 steps, the step and the time."""
            sim.run(200)
            return extracted(sim), sim.step, sim.time

        def make(sim: DEM, form: str) -> tuple[Any, np.ndarray]:
            """What ``createParticles`` returned, and the ids of the particles it made."""
            before = sim.extractIds()
            made: int | list[int]
            if form == "single":
                made = [sim.createParticles(1, "single", *xyz, **kw) for *xyz, kw in forms[form]]
            else:
                first, keywords = forms[form]
                made = sim.createParticles(1, "single" if form == "array" else form, first, **keywords)
            return made, np.setdiff1d(sim.extractIds(), before)

        try:
            sim = suite.dem(output, dt=dt)
        except Exception as exc:  # noqa: BLE001 - every test of the scenario reads it
            return {key: Outcome(error=exc) for key in ("engine", *forms, "start", "run", "closed")}
        results = {"engine": Outcome((sim.engine.name, sim.engine.capabilities))}
        with sim:
            for form in forms:
                results[form] = attempt(partial(make, sim, form))
            results["start"] = attempt(partial(extracted, sim))
            results["run"] = attempt(partial(run, sim))
        closed = {}
        for name, call in (("close", sim.close), ("extract", sim.extractCoords), ("run", lambda: sim.run(1))):
            closed[name] = attempt(call).error
        results["closed"] = Outcome((closed, (output / "pygran.log").read_text()))
        return results

    def test_declarations(self, created):
        """Known capabilities; refusals are suite features, not capabilities; the engine
        object declares what its plugin registered."""
        assert self.capabilities <= CAPABILITIES, self.capabilities - CAPABILITIES
        assert self.refuses <= set(SUITE_FEATURES), self.refuses - set(SUITE_FEATURES)
        if "raw-commands" in self.capabilities:
            assert self.raw_command, "an engine declaring raw-commands gives raw_command for its check"
        assert created["engine"].get() == (self.engine, self.capabilities)

    def created_by(self, created: dict[str, Outcome], form: str) -> np.ndarray:
        """The ids of the particles ``form`` created, once its count is checked."""
        made, ids = created[form].get()
        counts: dict[str, int | list[int]] = {"single": [1, 1], "array": 9, "lattice": 12, "random": 20}
        count = counts[form]
        assert made == count and len(ids) == np.sum(count), (made, ids)
        return ids

    def test_create_single_and_extract(self, created):
        """Two spheres created one by one, with velocity and spin or a radius of their own,
        are where they were put and move freely (no gravity); every extract* gives them in
        id order."""
        ids = self.created_by(created, "single")
        start = created["start"].get()
        (end, step, time), dt = created["run"].get(), self.dt(0.8 * RADIUS)
        x0 = np.array([[-6e-3, 6e-3, 8e-3], [-6e-3, 2e-3, 8e-3]])
        v0 = np.array([[0.1, -0.2, 0.05], [0.0, 0.0, 0.0]])
        w0 = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
        assert len(ids) == 2 and ids[0] < ids[1]
        first = np.isin(start["id"], ids)
        np.testing.assert_allclose(start["x"][first], x0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(start["v"][first], v0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(start["omega"][first], w0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(start["radius"][first], [RADIUS, 0.8 * RADIUS], rtol=1e-12)
        assert step == 200 and time == pytest.approx(200 * dt, rel=1e-12)
        np.testing.assert_array_equal(end["id"], start["id"])
        np.testing.assert_allclose(end["x"][first], x0 + v0 * time, rtol=0, atol=1e-12)
        np.testing.assert_allclose(end["v"][first], v0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(end["omega"][first], w0, rtol=0, atol=1e-9)
        np.testing.assert_allclose(end["f"], 0.0, rtol=0, atol=1e-15)

    def test_create_array(self, created):
        """An (N, 3) array of positions gives one sphere at each row, in the order of the rows."""
        if not self.supports("create-array"):
            with pytest.raises(UnsupportedFeature):
                created["array"].get()
            return
        ids = self.created_by(created, "array")
        start = created["start"].get()
        chosen = np.isin(start["id"], ids)
        np.testing.assert_allclose(start["x"][chosen], ARRAY, rtol=0, atol=1e-15)
        np.testing.assert_allclose(start["v"][chosen], [[0.0, 0.0, 0.1]] * len(ARRAY), rtol=0, atol=1e-15)

    def test_create_lattice(self, created):
        """A simple cubic lattice of spacing ``a`` filling a block a quarter spacing off the
        lattice: 3 x 2 x 2 sites, spaced ``a`` along each axis, inside the block."""
        if not self.supports("create-lattice"):
            with pytest.raises(UnsupportedFeature):
                created["lattice"].get()
            return
        ids = self.created_by(created, "lattice")
        start = created["start"].get()
        x, a = start["x"][np.isin(start["id"], ids)], LATTICE_SPACING
        bounds = np.reshape(LATTICE_BOUNDS, (3, 2))
        for axis, n in enumerate((3, 2, 2)):
            levels = np.unique(np.round(x[:, axis] / a, 6))
            assert len(levels) == n, (axis, levels)
            np.testing.assert_allclose(np.diff(levels), 1.0, rtol=1e-9)
            assert np.all((bounds[axis, 0] <= x[:, axis]) & (x[:, axis] <= bounds[axis, 1]))

    def test_create_random(self, created):
        """20 spheres placed at random in a block: all whole inside it, none overlapping."""
        if not self.supports("create-random"):
            with pytest.raises(UnsupportedFeature):
                created["random"].get()
            return
        ids = self.created_by(created, "random")
        start = created["start"].get()
        chosen = np.isin(start["id"], ids)
        x, r = start["x"][chosen], start["radius"][chosen]
        bounds = np.reshape(RANDOM_REGION[1:], (3, 2))
        assert np.all((x - r[:, None] >= bounds[:, 0] - 1e-12) & (x + r[:, None] <= bounds[:, 1] + 1e-12))
        assert pdist(x).min() >= 2 * RADIUS * (1 - 1e-9)

    def test_close(self, created):
        """A closed simulation refuses calls with EngineError; closing twice is harmless."""
        closed, log = created["closed"].get()
        assert closed["close"] is None
        assert isinstance(closed["extract"], EngineError) and isinstance(closed["run"], EngineError)
        assert "engine closed at step 200" in log

    # -- insert ---------------------------------------------------------------------------------

    def test_insert_by_pack(self, tmp_path):
        """Once by pack (no gravity): 30 spheres of two species in number fractions 1:3 with
        velocities uniform within +-0.1 m/s and a given spin, then 5 more on top of them in
        the same region; a volume fraction of 0.1 in another region, to within one sphere."""
        low = ("block", -9e-3, 9e-3, -9e-3, 9e-3, -9e-3, 0.0)
        high = ("block", -5e-3, 5e-3, -5e-3, 5e-3, 4e-3, 8e-3)
        species = ({"material": dict(MATERIAL), "radius": RADIUS},) * 2
        first = dict(species=(1, 2), weights=(0.25, 0.75), value=30, region=low)
        spread = dict(vel_type="uniform", vel=(0, 0, 0, 0.1, 0.1, 0.1), omega=("constant", 0, 0, 5))
        with self.dem(tmp_path, dt=self.dt(), species=species) as sim:
            if not self.supports("insert"):
                with pytest.raises(UnsupportedFeature):
                    sim.insert(**first)
                    sim.run(1)
                return
            sim.insert(**first, **spread)
            sim.run(1)
            types, v, w = sim.engine.extract("type"), sim.extractVelocities(), sim.extractOmegas()
            sim.insert(species=1, value=5, region=low)
            sim.run(1)
            assert len(sim.extractIds()) == 35
            sim.insert(species=1, mech="volumefraction_region", value=0.1, region=high)
            sim.run(1)
            x, r = sim.extractCoords(), sim.extractRadii()
        assert len(types) == 30 and abs(np.count_nonzero(types == 2) - 22.5) <= 8, np.bincount(types)
        assert np.abs(v).max() <= 0.1 + 1e-9 and np.all(v.std(axis=0) > 0.03), v
        np.testing.assert_allclose(w, [[0.0, 0.0, 5.0]] * 30, rtol=1e-12)
        upper = x[:, 2] > 2e-3
        assert np.count_nonzero(~upper) == 35
        assert np.all((x[~upper, 2] >= -9e-3 + r[~upper] - 1e-5) & (x[~upper, 2] <= -r[~upper] + 1e-5))
        sphere, volume = 4 / 3 * math.pi * RADIUS**3, 1e-2 * 1e-2 * 4e-3
        assert abs(np.count_nonzero(upper) * sphere - 0.1 * volume) <= sphere, np.count_nonzero(upper)

    def test_insert_by_pack_every_freq(self, tmp_path):
        """By pack every 500 steps: spheres thrown down (1 m/s) leave the region between
        insertions, so each refills it with 8; removing the insertion stops it."""
        box = (-6e-3, 6e-3, -6e-3, 6e-3, -0.04, 0.01)
        region = ("block", -5e-3, 5e-3, -5e-3, 5e-3, 5e-3, 9e-3)
        with self.dem(tmp_path, dt=self.dt(), box=box, gravity=GRAVITY) as sim:
            if not self.supports("insert"):
                with pytest.raises(UnsupportedFeature):
                    sim.insert(species=1, value=8, region=region, freq=500)
                    sim.run(1)
                return
            handle = sim.insert(species=1, value=8, region=region, freq=500, vel=(0.0, 0.0, -1.0))
            counts = []
            for steps in (1, 500, 500):
                sim.run(steps)
                counts.append(len(sim.extractIds()))
            sim.remove(handle)
            sim.run(1000)
            counts.append(len(sim.extractIds()))
        assert counts == [8, 16, 24, 24]

    def test_insert_by_rate(self, tmp_path):
        """By rate, PyGran 1.x's form (``mech='nparticles'``, ``value`` in all, ``rate`` per
        second): 24 spheres at 8 per insertion every 500 steps, then no more."""
        dt = self.dt()
        box = (-6e-3, 6e-3, -6e-3, 6e-3, -0.04, 0.01)
        region = ("block", -5e-3, 5e-3, -5e-3, 5e-3, 5e-3, 9e-3)
        request = dict(
            species=1,
            insert="by_rate",
            mech="nparticles",
            value=24,
            rate=8 / (500 * dt),
            freq=500,
            region=region,
            vel=(0.0, 0.0, -1.0),
        )
        with self.dem(tmp_path, dt=dt, box=box, gravity=GRAVITY) as sim:
            if not self.supports("insert-by-rate"):
                with pytest.raises(UnsupportedFeature):
                    sim.insert(**request)
                return
            sim.insert(**request)
            counts = []
            for steps in (1, 500, 500, 1000):
                sim.run(steps)
                counts.append(len(sim.extractIds()))
        assert counts == [8, 16, 24, 24]

    # -- walls --------------------------------------------------------------------------------

    def test_primitive_walls(self, tmp_path):
        """Spheres (no gravity) bounce off a z plane, an x plane and a z cylinder around them;
        with the z plane removed, a fourth passes where it would have bounced."""
        v = 0.1
        starts = np.array([[0.0, 0.0, -3e-3], [3e-3, 0.0, 3e-3], [-6e-3, 0.0, 3e-3], [0.0, 4e-3, -2e-3]])
        velocities = np.array([[0.0, 0.0, -v], [v, 0.0, 0.0], [-v, 0.0, 0.0], [0.0, 0.0, -v]])
        dt = self.dt()
        with self.dem(tmp_path, dt=dt) as sim:
            if not self.supports("primitive-walls"):
                with pytest.raises(UnsupportedFeature):
                    sim.setupWall(species=1, plane="zplane", peq=-5e-3)
                return
            floor = sim.setupWall(species=1, plane="zplane", peq=-5e-3)
            sim.setupWall(species=1, plane="xplane", peq=5e-3)
            sim.setupWall(species=1, axis="z", centre=(0.0, 0.0), radius=8e-3)
            for x, u in zip(starts, velocities):
                sim.createParticles(1, "single", *x, vel=tuple(u))
            sim.run(round(0.015 / dt))  # 1 mm to each wall at 0.1 m/s: 10 ms
            after = sim.extractVelocities()
            sim.remove(floor)  # the fourth sphere, 2 mm from it, has not reached it
            sim.run(round(0.02 / dt))
            z, end = sim.extractCoords()[3, 2], sim.time
        bounced = [after[0, 2], -after[1, 0], after[2, 0]]
        assert all(0.5 * v < b <= v * (1 + 1e-9) for b in bounced), after
        assert z == pytest.approx(-2e-3 - v * end, rel=1e-6) and z < -5e-3

    def silo(self, data_dir: Path) -> dict[str, Any]:
        """``silo.stl`` (a conical hopper, in mm) as the mesh ``silo``, not a wall yet."""
        file = data_dir / "meshes" / "silo.stl"
        return {"silo": {"file": str(file), "args": ("scale 1e-3",), "import": False}}

    @staticmethod
    def seat(sim: DEM, radius: float) -> float:
        """The height on the silo's axis where a sphere of ``radius`` touches its facets."""
        triangles = sim.spec.meshes[0].triangles()
        return brentq(
            lambda z: float(triangle_distance(np.array([[0.0, 0.0, z]]), triangles)[0]) - radius,
            0.0,
            3e-3,
            xtol=1e-12,
        )

    def test_mesh_wall(self, tmp_path, data_dir):
        """A sphere (r = 0.5 mm) set on the axis of the silo (outlet radius 0.3 mm), where it
        touches the facets, stays there; removing the mesh's wall by name, it falls freely."""
        radius = 5e-4
        box = (-1.5e-3, 1.5e-3, -1.5e-3, 1.5e-3, -4e-3, 4e-3)
        keywords = dict(box=box, mesh=self.silo(data_dir), gravity=GRAVITY, dt=self.dt(radius))
        if not self.supports("mesh-walls"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, radius, **keywords).close()
            return
        with self.dem(tmp_path, radius, **keywords) as sim:
            sim.setupWall(wtype="mesh", mesh="silo")
            seat = self.seat(sim, radius)
            sim.createParticles(1, "single", 0.0, 0.0, seat)
            sim.run(2000)
            held, speed, start = sim.extractCoords()[0], sim.extractVelocities()[0, 2], sim.time
            sim.remove("silo")
            sim.run(1000)
            fallen, duration = sim.extractCoords()[0], sim.time - start
        assert seat - 0.02 * radius < held[2] <= seat + 1e-9 and np.hypot(*held[:2]) < 1e-3 * radius, held
        assert fallen[2] - held[2] == pytest.approx(speed * duration - 0.5 * G * duration**2, rel=1e-3)

    @pytest.fixture(scope="class")
    @classmethod
    def mesh_motions(cls, tmp_path_factory, data_dir) -> dict[str, Outcome]:
        """A sphere seated in the silo, then each ``moveMesh`` style in turn (each motion
        removed before the next): what each did to the sphere, or what it raised."""
        suite = cls()
        radius, period = 5e-4, MOTION_PERIOD
        box = (-1.5e-3, 1.5e-3, -1.5e-3, 1.5e-3, -4e-3, 4e-3)
        dt = suite.dt(radius)
        quarter = round(period / 4 / dt)
        results: dict[str, Outcome] = {}

        def rotate(sim: DEM) -> tuple[float, float, float]:
            before = float(sim.extractOmegas()[0, 2])
            sim.run(quarter)
            return before, float(sim.extractOmegas()[0, 2]), 2 * math.pi / period

        def linear(sim: DEM) -> tuple[float, float]:
            z, t = sim.extractCoords()[0, 2], sim.time
            sim.run(2 * quarter)
            return float(sim.extractCoords()[0, 2] - z), 2e-3 * (sim.time - t)

        def wiggle(sim: DEM) -> tuple[float, float]:
            z = sim.extractCoords()[0, 2]
            sim.run(quarter)
            up = sim.extractCoords()[0, 2] - z
            sim.run(quarter)
            return float(up), float(sim.extractCoords()[0, 2] - z)

        def viblin(sim: DEM) -> float:
            z = sim.extractCoords()[0, 2]
            sim.run(2 * quarter)
            return float(sim.extractCoords()[0, 2] - z)

        def vibrot(sim: DEM) -> float:
            sim.run(quarter)
            return float(sim.extractOmegas()[0, 2])

        amplitude = 2e-5
        phases: dict[str, tuple[dict[str, Any], Callable[[DEM], Any]]] = {
            "rotate": ({"rotate": ("origin", 0.0, 0.0, 0.0), "axis": (0, 0, 1), "period": period}, rotate),
            "linear": ({"linear": (0.0, 0.0, 2e-3)}, linear),
            "wiggle": ({"wiggle": ("amplitude", 0.0, 0.0, amplitude), "period": period}, wiggle),
            "viblin": (
                {"viblin": ("axis", 0, 0, 1), "order": 1, "amplitude": (amplitude,), "phase": (0.0,)}
                | {"period": (period,)},
                viblin,
            ),
            "vibrot": (
                {"vibrot": ("origin", 0, 0, 0), "axis": (0, 0, 1), "order": 1, "amplitude": (0.5,)}
                | {"phase": (0.0,), "period": (period,)},
                vibrot,
            ),
        }
        try:
            sim = suite.dem(
                tmp_path_factory.mktemp("motions"),
                radius,
                box=box,
                mesh=suite.silo(data_dir),
                gravity=GRAVITY,
                dt=dt,
            )
        except Exception as exc:  # noqa: BLE001 - every style's test reads it
            return {style: Outcome(error=exc) for style in phases}
        with sim:
            outcome = attempt(lambda: sim.setupWall(wtype="mesh", mesh="silo"))
            if outcome.error is not None:
                return {style: outcome for style in phases}
            sim.createParticles(1, "single", 0.0, 0.0, suite.seat(sim, radius))
            sim.run(quarter)
            for style, (kwargs, measure) in phases.items():
                try:
                    handle = sim.moveMesh("silo", **kwargs)
                except Exception as exc:  # noqa: BLE001 - read by the style's test
                    results[style] = Outcome(error=exc)
                    continue
                results[style] = attempt(partial(measure, sim))
                removed = attempt(partial(sim.remove, handle))
                if removed.error is not None:  # the next styles would not start from rest
                    return results | {s: removed for s in phases if s not in results}
        return results

    def motion(self, mesh_motions: dict[str, Outcome], style: str, *needs: str) -> Any:
        """The style's measurement, or ``None`` once its UnsupportedFeature is asserted."""
        if all(self.supports(need) for need in ("mesh-walls", "moving-mesh", *needs)):
            return mesh_motions[style].get()
        with pytest.raises(UnsupportedFeature):
            mesh_motions[style].get()
        return None

    def test_move_mesh_rotate(self, mesh_motions):
        """The silo turning about its axis spins the sphere seated in it (at rest before) up to
        its own rate."""
        measured = self.motion(mesh_motions, "rotate")
        if measured is not None:
            before, spin, omega = measured
            assert abs(before) < 1e-3 * omega and spin == pytest.approx(omega, rel=0.02), measured

    def test_move_mesh_linear(self, mesh_motions):
        """The silo moving up at 2 mm/s lifts the sphere with it."""
        measured = self.motion(mesh_motions, "linear")
        if measured is not None:
            lift, expected = measured
            assert lift == pytest.approx(expected, rel=0.03), measured

    def test_move_mesh_wiggle(self, mesh_motions):
        """A slow vertical wiggle of 20 um lifts the sphere by it after a quarter period and
        brings it back after half."""
        measured = self.motion(mesh_motions, "wiggle")
        if measured is not None:
            up, back = measured
            assert up == pytest.approx(2e-5, rel=0.05) and abs(back) < 1e-6, measured

    def test_move_mesh_viblin(self, mesh_motions):
        """A vertical viblin of one harmonic (amplitude 20 um, phase 0) lowers the sphere by
        twice its amplitude after half a period."""
        measured = self.motion(mesh_motions, "viblin", "mesh-vibration")
        if measured is not None:
            assert measured == pytest.approx(-4e-5, rel=0.05)

    def test_move_mesh_vibrot(self, mesh_motions):
        """A vibrot about the axis (0.5 rad, phase 0) spins the sphere at -0.5 w after a quarter period."""
        measured = self.motion(mesh_motions, "vibrot", "mesh-vibration")
        if measured is not None:
            assert measured == pytest.approx(-0.5 * 2 * math.pi / MOTION_PERIOD, rel=0.02)

    # -- forces, gravity, set ---------------------------------------------------------------------

    def test_viscous_drag(self, tmp_path):
        """A drag on species 2 only slows its sphere as ``exp(-gamma scale t / m)``; the sphere
        of species 1 keeps its speed; removed, the drag stops."""
        dt, v = self.dt(), 0.1
        species = ({"material": dict(MATERIAL), "radius": RADIUS},) * 2
        mass = sphere_mass(MATERIAL, RADIUS)
        steps = 1000
        gamma, scale = 0.25 * mass / (steps * dt), 2.0
        with self.dem(tmp_path, dt=dt, species=species) as sim:
            sim.createParticles(1, "single", 0.0, -3e-3, 0.0, vel=(v, 0.0, 0.0))
            sim.createParticles(2, "single", 0.0, 3e-3, 0.0, vel=(v, 0.0, 0.0))
            if not self.supports("viscous"):
                with pytest.raises(UnsupportedFeature):
                    sim.addViscous(gamma=gamma, species=2, scale=scale)
                    sim.run(1)
                return
            drag = sim.addViscous(gamma=gamma, species=2, scale=scale)
            sim.run(steps)
            slowed = sim.extractVelocities()[:, 0]
            sim.remove(drag)
            sim.run(steps)
            after = sim.extractVelocities()[:, 0]
        assert slowed[0] == pytest.approx(v, rel=1e-12)
        assert slowed[1] == pytest.approx(v * math.exp(-0.5), rel=1e-3)
        np.testing.assert_allclose(after, slowed, rtol=1e-3)  # the drag (40 % over a run) stopped

    def test_gravity_and_monitor(self, tmp_path):
        """Free fall along (0.6, 0, -0.8) over two runs of different time steps follows the
        closed form; a monitor samples n, time and ke = m (g t)^2 / 2 at its frequency into
        memory and its file, PyGran 1.x's averaged monitor averages them, and a removed
        monitor samples no more.

        Positions within 1e-3 of the closed form: velocity Verlet gives it exactly, a leapfrog
        taking the initial velocity at -dt/2 is off by dt/t.
        """
        dt = self.dt()
        direction = np.array([0.6, 0.0, -0.8])
        mass = sphere_mass(MATERIAL, RADIUS)
        with self.dem(tmp_path, dt=dt, gravity=(G, *direction)) as sim:
            sim.createParticles(1, "single", -5e-3, 0.0, 5e-3)
            monitor = sim.monitor(quantities=("ke", "n", "time"), freq=250, file="fall.txt")
            averaged = sim.monitor(var="ke", name="keavg", nevery=10, nrepeat=5, nfreq=250)
            sim.run(2000)
            sim.run(1000, dt=dt / 2)
            x, v, t = sim.extractCoords()[0], sim.extractVelocities()[0], sim.time
            sim.remove(monitor)
            sim.run(250)
            samples, means = monitor.values, averaged.values
        assert sim.step == 3250 and t == pytest.approx(2500 * dt, rel=1e-12)
        np.testing.assert_allclose(v, G * t * direction, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(x - [-5e-3, 0.0, 5e-3], 0.5 * G * t**2 * direction, rtol=1e-3, atol=1e-12)
        steps = np.arange(0, 3001, 250)
        np.testing.assert_array_equal(samples["step"], steps)
        times = np.where(steps <= 2000, steps * dt, 2000 * dt + (steps - 2000) * dt / 2)
        np.testing.assert_allclose(samples["time"], times, rtol=1e-12)
        np.testing.assert_array_equal(samples["n"], 1)
        np.testing.assert_allclose(samples["ke"], 0.5 * mass * (G * times) ** 2, rtol=1e-9, atol=1e-30)
        lines = (tmp_path / "fall.txt").read_text().splitlines()
        assert len(lines) == 1 + len(steps) and lines[0].startswith("#")
        window = np.arange(-40, 1, 10)
        expected = [np.mean(0.5 * mass * (G * (k + window) * dt) ** 2) for k in range(250, 2001, 250)]
        np.testing.assert_allclose(means["ke"][:8], expected, rtol=1e-9)
        assert (tmp_path / "keavg.dat").read_text().count("\n") == 2 + len(means["ke"])

    def probe_monitor(self, sim: DEM, quantity: str) -> Any:
        """A monitor of ``quantity`` every step, or ``None`` once its refusal is asserted (at
        the call or at the first sample)."""
        if self.supports(f"monitor-{quantity}"):
            return sim.monitor(quantities=(quantity,), freq=1, file=f"{quantity}.txt")
        with pytest.raises(UnsupportedFeature):
            refused = sim.monitor(quantities=(quantity,), freq=1, file=f"{quantity}.txt")
            try:
                sim.run(1)
            finally:
                sim.remove(refused)
        return None

    def test_optional_monitors(self, tmp_path):
        """ke_rot of a spinning sphere is I w^2 / 2; contacts counts two pairs of spheres (no
        other contact) while they collide head-on, none before or after; wall_force of a
        sphere settling on a floor (added only where wall_force is supported: a floor holds a
        contact of its own) averages its weight. A quantity the engine refuses raises
        UnsupportedFeature, at the call or at its first sample."""
        dt, mass = self.dt(), sphere_mass(MATERIAL, RADIUS)
        sphere = dict(MATERIAL, radius=RADIUS)
        contact_time = self.model(material=sphere, partner=sphere).contactTime(0.2)
        floor = self.supports("monitor-wall_force")
        with self.dem(tmp_path, dt=dt, gravity=GRAVITY if floor else None) as sim:
            if floor:
                sim.setupWall(species=1, plane="zplane", peq=-0.01)
                sim.createParticles(1, "single", 7e-3, 7e-3, -0.01 + RADIUS)
            sim.createParticles(1, "single", -7e-3, -7e-3, 7e-3, omega=(0.0, 0.0, 30.0))
            for y in (-4e-3, 4e-3):
                for side in (-1, 1):
                    sim.createParticles(1, "single", side * 1.25e-3, y, 0.0, vel=(-side * 0.1, 0.0, 0.0))
            monitors = {q: self.probe_monitor(sim, q) for q in ("ke_rot", "contacts", "wall_force")}
            sim.run(round(2 * (0.5e-3 / 0.2 + contact_time) / dt))
        spin, contacts, force = (monitors[q] for q in ("ke_rot", "contacts", "wall_force"))
        if spin is not None:
            inertia = 0.4 * mass * RADIUS**2
            np.testing.assert_allclose(spin.values["ke_rot"], 0.5 * inertia * 30.0**2, rtol=1e-6)
        if contacts is not None:
            counts = contacts.values["contacts"] - (1 if floor else 0)
            assert counts[0] == counts[-1] == 0 and set(counts) == {0, 2}, np.unique(counts)
            assert np.count_nonzero(counts == 2) * dt == pytest.approx(contact_time, rel=0.1)
        if force is not None:
            assert np.mean(force.values["wall_force"]) == pytest.approx(mass * G, rel=0.05)

    def test_set(self, tmp_path):
        """set() assigns velocities to all, to ids, and spins to a region's particles, returning
        how many it changed; set(radius=...) changes the radius and with it the mass."""
        x0 = np.array([[-6e-3, 0, 0], [-2e-3, 0, 0], [2e-3, 0, 0], [6e-3, 0, 0]], float)
        with self.dem(tmp_path, dt=self.dt(0.5 * RADIUS)) as sim:
            sim.createParticles(1, "single", x0[0, 0], 0.0, 0.0)
            for x in x0[1:]:
                sim.createParticles(1, "single", *x)
            if not self.supports("set"):
                with pytest.raises(UnsupportedFeature):
                    sim.set(vel=(0.0, 0.0, 0.1))
                return
            ids = sim.extractIds()
            assert sim.set(vel=(0.0, 0.0, 0.1)) == 4
            assert sim.velocity(vel=(0.0, 0.1, 0.0), ids=[int(ids[1])]) == 1
            assert sim.set(omega=(0.0, 0.0, 5.0), region=("block", 0, 0.01, -0.01, 0.01, -0.01, 0.01)) == 2
            if self.supports("set-radius"):
                assert sim.set(radius=0.5 * RADIUS, ids=[int(ids[3])]) == 1
            else:
                with pytest.raises(UnsupportedFeature):
                    sim.set(radius=0.5 * RADIUS, ids=[int(ids[3])])
            v, w, r = sim.extractVelocities(), sim.extractOmegas(), sim.extractRadii()
            mass = sim.engine.extract("mass")
            sim.run(100)
            x = sim.extractCoords()
        np.testing.assert_allclose(v, [[0, 0, 0.1], [0, 0.1, 0], [0, 0, 0.1], [0, 0, 0.1]], atol=1e-15)
        np.testing.assert_allclose(w, [[0, 0, 0], [0, 0, 0], [0, 0, 5], [0, 0, 5]], atol=1e-12)
        np.testing.assert_allclose(x, x0 + v * sim.time, rtol=0, atol=1e-12)
        if self.supports("set-radius"):
            np.testing.assert_allclose(r, [RADIUS] * 3 + [0.5 * RADIUS], rtol=1e-12)
            np.testing.assert_allclose(mass[3], sphere_mass(MATERIAL, 0.5 * RADIUS), rtol=1e-9)

    # -- run, lost particles, output, close -----------------------------------------------------------

    def test_time_step_check(self, tmp_path):
        """Before a run, a time step too long for the contacts that can happen is refused and
        one that resolves them poorly warned about; a safe one is neither."""
        dt = self.dt()
        with self.dem(tmp_path, dt=dt) as sim:
            create(sim, [[-2e-3, 0, 0], [2e-3, 0, 0]])
            with pytest.raises(ConfigError, match="fewer than 3 steps"):
                sim.run(10, dt=1000 * dt)
            assert sim.step == 0
            with pytest.warns(TimeStepWarning):
                sim.run(10, dt=3 * dt)
            with warnings.catch_warnings():
                warnings.simplefilter("error", TimeStepWarning)
                sim.run(10, dt=dt)
            assert sim.step == 20

    def test_lost_particles(self, tmp_path):
        """A sphere leaving the box through its top is reported lost through z+."""
        dt = self.dt()
        with self.dem(tmp_path, dt=dt) as sim:
            create(sim, [[0, 0, 8e-3], [0, 0, -5e-3]], vel=(0.0, 0.0, 1.0))
            with pytest.warns(LostParticlesWarning, match="z\\+"):
                sim.run(round(0.005 / dt))
            assert len(sim.extractIds()) == 1 and sim.engine.lost == 1
            assert dict(sim.engine.last_lost.where) == {"z+": 1}

    def test_trajectory(self, tmp_path):
        """The trajectory file holds a frame every ``freq`` steps with the particles then."""
        traj = {"pfile": "traj.dump", "freq": 100}
        with self.dem(tmp_path, dt=self.dt(), traj=traj, gravity=GRAVITY) as sim:
            create(sim, [[0, 0, 0], [3e-3, 0, 0]], vel=(0.0, 0.1, 0.0))
            sim.run(200)
            ids, x = sim.extractIds(), sim.extractCoords()
        with open_trajectory(tmp_path / "traj.dump") as frames:
            assert [f.timestep for f in frames] == [0, 100, 200]
            last = frames[-1].arrays
        order = np.argsort(last["id"])
        np.testing.assert_array_equal(last["id"][order], ids)
        np.testing.assert_allclose(np.column_stack([last[k][order] for k in "xyz"]), x, rtol=1e-5, atol=1e-12)

    # -- options and capabilities --------------------------------------------------------------------

    def columns(self, output: Path, **options: Any) -> np.ndarray:
        """Four columns of two spheres falling 0.2 mm onto a floor: positions and velocities
        after 1500 steps, with ``options`` (threads, nprocs) in place of the class's."""
        x = np.array([[i, j, k] for i in (-3e-3, 3e-3) for j in (-3e-3, 3e-3) for k in (1.2e-3, 3.4e-3)])
        box = (-6e-3, 6e-3, -6e-3, 6e-3, 0.0, 6e-3)
        with self.dem(output, dt=self.dt(), gravity=GRAVITY, box=box, **options) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            create(sim, x)
            sim.run(1500)
            return np.hstack([sim.extractCoords(), sim.extractVelocities()])

    def test_threads(self, tmp_path):
        """Two threads give what one does."""
        if not self.supports("threads"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, threads=2).close()
            return
        one = self.columns(tmp_path / "one", threads=1)
        np.testing.assert_allclose(self.columns(tmp_path / "two", threads=2), one, rtol=0, atol=1e-12)

    def test_mpi(self, tmp_path):
        """Two MPI ranks give what one does."""
        if not self.supports("mpi"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, nprocs=2).close()
            return
        one = self.columns(tmp_path / "one", nprocs=1)
        np.testing.assert_allclose(self.columns(tmp_path / "two", nprocs=2), one, rtol=0, atol=1e-12)

    def test_periodic(self, tmp_path):
        """Periodic in x: a sphere leaving through x+ comes back through x-, and two spheres
        meet across the boundary and bounce apart."""
        dt = self.dt()
        keywords: dict[str, Any] = {"dt": dt, "boundary": ("p", "f", "f")}
        if not self.supports("periodic"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, **keywords).close()
            return
        with self.dem(tmp_path, **keywords) as sim:
            sim.createParticles(1, "single", 8e-3, -5e-3, 0.0, vel=(0.1, 0.0, 0.0))
            sim.createParticles(1, "single", -8e-3, 5e-3, 0.0, vel=(-0.1, 0.0, 0.0))
            sim.createParticles(1, "single", 8e-3, 5e-3, 0.0, vel=(0.1, 0.0, 0.0))
            sim.run(round(0.03 / dt))
            x, v, t = sim.extractCoords(), sim.extractVelocities(), sim.time
        assert x[0, 0] == pytest.approx((8e-3 + 0.1 * t + 0.01) % 0.02 - 0.01, abs=1e-9)
        assert v[1, 0] > 0.05 and v[2, 0] < -0.05, v

    def test_polydisperse(self, tmp_path):
        """A normal size distribution (mean 1 mm, sd 0.1 mm, cut at 3 sd) gives each sphere its
        own radius within the cut, and the mass of that radius."""
        species = ({"material": dict(MATERIAL), "radius": ("normal", RADIUS, 0.1 * RADIUS)},)
        across = np.arange(-7.5e-3, 8e-3, 3e-3)
        x = np.stack(np.meshgrid(across, across, [0.0], indexing="ij"), -1).reshape(-1, 3)
        if not self.supports("polydisperse"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, species=species).close()
            return
        with self.dem(tmp_path, species=species, dt=self.dt(0.7 * RADIUS)) as sim:
            create(sim, x)
            r, mass = sim.extractRadii(), sim.engine.extract("mass")
        assert len(r) == len(x) and np.all((r >= 0.7 * RADIUS) & (r <= 1.3 * RADIUS))
        assert 0.05 * RADIUS < np.std(r) < 0.15 * RADIUS and abs(np.mean(r) / RADIUS - 1) < 0.06
        np.testing.assert_allclose(mass, 4 / 3 * math.pi * r**3 * MATERIAL["density"], rtol=1e-9)

    def test_multisphere(self, tmp_path):
        """A tablet of two touching spheres, inserted in a region (LIGGGHTS makes multisphere
        particles by insertion only), falls as one rigid body. Extracts give each of its
        spheres a row (the original PyGran's convention), each carrying the body's mass, here
        the two spheres' (they do not overlap; LIGGGHTS integrates it by Monte Carlo, to
        0.2 %). The drop after the step of its insertion is ``v1 T - g T^2 / 2`` to within the
        integrator's order (a leapfrog's velocity lags half a step: 1/1000 of the drop)."""
        species = (
            {"style": "multisphere/tablet", "material": dict(MATERIAL), "nspheres": 2}
            | {"radius": RADIUS, "length": 4 * RADIUS},
        )
        if not self.supports("multisphere"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, species=species).close()
            return
        dt, steps = self.dt(), 1000
        region = ("block", -3e-3, 3e-3, -3e-3, 3e-3, -3e-3, 3e-3)
        with self.dem(tmp_path, species=species, dt=dt, gravity=GRAVITY) as sim:
            sim.insert(species=1, value=1, region=region)
            sim.run(1)
            x1, v1 = sim.extractCoords(), sim.extractVelocities()
            sim.run(steps)
            x, mass = sim.extractCoords(), sim.engine.extract("mass")
        assert len(x) == len(x1) == 2, x
        assert np.linalg.norm(x[1] - x[0]) == pytest.approx(2 * RADIUS, rel=1e-12)
        g, duration = G * np.array(GRAVITY[1:]), steps * dt
        np.testing.assert_allclose(x - x1, v1 * duration + g * duration**2 / 2, rtol=2e-3, atol=1e-12)
        assert mass[0] == mass[1] == pytest.approx(2 * sphere_mass(MATERIAL, RADIUS), rel=2e-3), mass

    def test_raw_commands(self, tmp_path):
        """The engine's native command (:attr:`raw_command`) reaches the solver."""
        with self.dem(tmp_path, dt=self.dt()) as sim:
            sim.createParticles(1, "single", 0.0, 0.0, 0.0)
            if not self.supports("raw-commands"):
                with pytest.raises(UnsupportedFeature):
                    sim.command("run 0")
                return
            assert self.raw_command is not None, "an engine declaring raw-commands gives raw_command"
            sim.command(self.raw_command)
            sim.run(10)
            v = sim.extractVelocities()[0]
        np.testing.assert_allclose(v, [0.5, 0.0, 0.0], rtol=1e-12)

    def restart_script(self, output: Path, resume: bool = False, lastfile: str | None = None) -> dict:
        """A sphere sliding on a floor (friction history), one bouncing, one falling onto it;
        checkpoints every 250 steps; its final state and monitor."""
        restart = (250, "restart", "restart.*.h5", resume, lastfile)
        x = np.array([[-4e-3, 0.0, RADIUS], [4e-3, 0.0, 1.1e-3], [4e-3, 0.0, 3.3e-3]])
        keywords: dict[str, Any] = {
            "dt": self.dt(),
            "gravity": GRAVITY,
            "box": (-6e-3, 6e-3, -6e-3, 6e-3, 0.0, 8e-3),
        }
        with self.dem(output, restart=restart, **keywords) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            sim.createParticles(1, "single", *x[0], vel=(0.05, 0.0, 0.0))
            create(sim, x[1:])
            ke = sim.monitor(quantities=("ke",), freq=50, file="ke.txt")
            sim.run(500)
            sim.run(500)
            return {
                "x": sim.extractCoords(),
                "v": sim.extractVelocities(),
                "omega": sim.extractOmegas(),
                "ke": ke.values["ke"],
                "step": sim.step,
            }

    def test_restart_round_trip(self, tmp_path):
        """Resumed from its checkpoint at step 750, the script ends where it ended uninterrupted."""
        if not self.supports("restart"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, restart=(250, "restart", "restart.h5")).close()
            return
        straight = self.restart_script(tmp_path)
        assert (tmp_path / "restart" / "restart.750.h5").is_file()
        again = self.restart_script(tmp_path, resume=True, lastfile="restart.750.h5")
        assert again["step"] == straight["step"] == 1000
        assert "resumed from" in (tmp_path / "pygran.log").read_text()
        for key in ("x", "v", "omega", "ke"):
            np.testing.assert_allclose(again[key], straight[key], rtol=1e-9, atol=1e-15, err_msg=key)

    # -- contact models and materials -----------------------------------------------------------------

    def pair_scene(self, output: Path, material: Mapping[str, float], **keywords: Any) -> DEM:
        """Species 1 and 2 of ``material`` (species 1 with friction 0.5, 2 with none, so that
        mixing gives none) and a floor of species 2 at z = 0; pair (1, 2) from :data:`PAIR`."""
        species = (
            {"material": dict(material, coefficientFriction=0.5), "radius": RADIUS},
            {"material": dict(material), "radius": RADIUS},
        )
        sim = self.dem(output, species=species, pairs={(2, 1): dict(PAIR)}, **keywords)
        try:
            sim.setupWall(species=2, plane="zplane", peq=0.0)
        except BaseException:
            sim.close()
            raise
        return sim

    def test_pair_table_bounce(self, tmp_path):
        """A sphere of species 1 hitting a floor of species 2 rebounds with the pair's
        restitution (0.45, not the species' 0.9 mixed): the reference model's, within 2 %."""
        material = dict(MATERIAL, coefficientRestitution=0.9)
        reference = self.model(material=dict(material, radius=RADIUS, coefficientRestitution=0.45))
        dt = reference.contactTime(IMPACT_SPEED) / STEPS_PER_CONTACT
        if not self.supports("primitive-walls"):
            with pytest.raises(UnsupportedFeature):
                self.pair_scene(tmp_path, material, dt=dt)
            return
        with self.pair_scene(tmp_path, material, dt=dt) as sim:
            sim.createParticles(
                1, "single", 0.0, 0.0, RADIUS + 0.5 * IMPACT_SPEED * dt, vel=(0, 0, -IMPACT_SPEED)
            )
            sim.run(4 * STEPS_PER_CONTACT)
            rebound = sim.extractVelocities()[0, 2] / IMPACT_SPEED
            assert "species 1 - species 2*" in (tmp_path / "pygran.log").read_text()  # the table, logged
        want = reference_collision(reference, IMPACT_SPEED).restitution
        assert rebound == pytest.approx(want, rel=0.02)
        assert rebound < 0.6  # the species' own 0.9 would rebound near 0.9

    def test_pair_table_slide(self, tmp_path):
        """A sphere of species 1 sliding on a floor of species 2 decelerates at mu_pair g
        (0.2 g; the mixed value is 0) until it rolls; with a material of only its model's
        required keys (friction from the defaults table: 0) it keeps its speed."""
        speed, late = 0.1, 0.006  # rolling starts at 2 v / (7 mu g) = 0.0146 s
        if not self.supports("primitive-walls"):
            with pytest.raises(UnsupportedFeature):
                self.pair_scene(tmp_path, dict(MATERIAL))
            return
        measured = {}
        required = {k: MATERIAL[k] for k in (*self.model.required, "density") if k != "radius"}
        for name, material, pairs in (("pair", dict(MATERIAL), True), ("bare", required, False)):
            species = (
                {"material": material, "radius": RADIUS},
                {"material": dict(material), "radius": RADIUS},
            )
            extra: dict[str, Any] = {"pairs": {(1, 2): {"coefficientFriction": 0.2}}} if pairs else {}
            dt = self.dt()
            with self.dem(tmp_path / name, species=species, gravity=GRAVITY, dt=dt, **extra) as sim:
                sim.setupWall(species=2, plane="zplane", peq=0.0)
                sim.createParticles(1, "single", 0.0, -8e-3, RADIUS, vel=(0.0, speed, 0.0))
                sim.run(round(0.001 / dt))  # settled on the floor
                early = sim.time, sim.extractVelocities()[0, 1]
                sim.run(round((late - early[0]) / dt))
                measured[name] = (early[1] - sim.extractVelocities()[0, 1]) / (sim.time - early[0])
        assert measured["pair"] == pytest.approx(0.2 * G, rel=0.01)
        assert measured["bare"] == pytest.approx(0.0, abs=1e-6)

    @pytest.mark.parametrize("model", MODELS, ids=[m.__name__ for m in MODELS])
    def test_impacts(self, tmp_path, model):
        """A sphere-wall and a sphere-sphere impact: restitution and contact time within 2 % of
        the reference model; for Hertz-Mindlin, also the closed-form Hertz contact time and
        largest overlap of an elastic impact (``pygran validate``'s rows, within 1 %)."""
        material = IMPACT_MATERIALS[model]
        if model.kernel not in self.capabilities:
            with pytest.raises(UnsupportedFeature):
                pair_impact(self.engine, tmp_path, model, material, **self.options)
            return
        sphere = dict(material, radius=RADIUS)
        measured = [pair_impact(self.engine, tmp_path / "pair", model, material, **self.options)]
        expected = [reference_collision(model(material=sphere, partner=sphere), 2 * IMPACT_SPEED)]
        if self.supports("primitive-walls"):
            measured.append(wall_impact(self.engine, tmp_path / "wall", model, material))
            expected.append(reference_collision(model(material=sphere), IMPACT_SPEED))
        for got, want in zip(measured, expected):
            assert got.restitution == pytest.approx(want.restitution, rel=0.02), (got, want)
            assert got.contact_time == pytest.approx(want.contact_time, rel=0.02), (got, want)
        if model is HertzMindlin and self.supports("primitive-walls"):
            rows = check_hertz(self.engine, tmp_path / "hertz")
            assert all(row.passed for row in rows), format_table(rows)

    def test_a_user_subclass_runs_with_its_parents_kernel(self, tmp_path):
        """A subclass of a model (a user's helper methods, a plugin's renamed model) runs the
        parent's kernel: the same impact to the last bit; a model that declares no kernel is
        refused by name."""
        parent = self.model

        class Renamed(parent):  # type: ignore[valid-type,misc]
            """A user's model: the parent's law with a helper of its own."""

            def stiffness_note(self) -> str:
                return f"{type(self).__name__} is {parent.__name__}"

        class NoKernel(parent):  # type: ignore[valid-type,misc]
            """A force law no engine has."""

            kernel = None

        material = IMPACT_MATERIALS[parent]
        mine = pair_impact(self.engine, tmp_path / "renamed", Renamed, material, **self.options)
        theirs = pair_impact(self.engine, tmp_path / "parent", parent, material, **self.options)
        assert (mine.restitution, mine.contact_time) == (theirs.restitution, theirs.contact_time)
        with pytest.raises(UnsupportedFeature, match="NoKernel declares no kernel"):
            pair_impact(self.engine, tmp_path / "none", NoKernel, material, **self.options)

    @pytest.fixture(scope="class")
    @classmethod
    def settled(cls, tmp_path_factory) -> dict[str, Outcome]:
        """Every material's settle (see :meth:`settle`), run when first asked for."""
        return _Lazy(lambda name: attempt(lambda: cls().settle(tmp_path_factory.mktemp(name), name)))

    def settle(self, output: Path, name: str) -> dict[str, Any]:
        """A sphere on a floor and a stack of two, all of material ``name``, set down touching
        at rest (Hertz-Mindlin where declared), run until their slowest vibration has decayed
        to :data:`SETTLE_DECAY`, with the time step the time-step check takes as safe."""
        material = params.MATERIALS[name]
        model = HertzMindlin if self.supports("hertz-mindlin") else self.model
        sphere = dict(material, radius=RADIUS)
        on_wall, on_sphere = model(material=sphere), model(material=sphere, partner=sphere)
        mass = sphere_mass(material, RADIUS)
        lone, bottom = rest_overlap(on_wall, mass * G), rest_overlap(on_wall, 2 * mass * G)
        top = rest_overlap(on_sphere, mass * G)
        dt = safe_dt(model, (material,), RADIUS)
        decay = slowest_decay(mass, (on_wall, bottom), (on_sphere, top))
        steps = math.ceil(math.log(1 / SETTLE_DECAY) / decay / dt)
        box = (-4 * RADIUS, 4 * RADIUS, -2 * RADIUS, 2 * RADIUS, -RADIUS, 6 * RADIUS)
        keywords: dict[str, Any] = {"box": box, "dt": dt, "gravity": GRAVITY, "model": model}
        species = ({"material": dict(material), "radius": RADIUS},)
        with self.dem(output, species=species, **keywords) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            create(sim, [[-2 * RADIUS, 0, RADIUS], [2 * RADIUS, 0, RADIUS]])
            sim.createParticles(1, "single", 2 * RADIUS, 0.0, 3 * RADIUS)
            with warnings.catch_warnings():
                warnings.simplefilter("error", TimeStepWarning)
                warnings.simplefilter("error", LostParticlesWarning)
                sim.run(steps)
            return {
                "x": sim.extractCoords(),
                "v": sim.extractVelocities(),
                "lost": sim.engine.lost,
                "expected": (lone, bottom, top),
                "energy": sink_energy(on_wall, mass * G, lone)
                + sink_energy(on_wall, 2 * mass * G, bottom)
                + sink_energy(on_sphere, mass * G, top),
                "mass": mass,
            }

    @pytest.mark.parametrize("name", sorted(params.MATERIALS))
    def test_material_settles(self, settled, name):
        """Every stock material: nothing lost, all finite, each sphere at rest where the
        reference model's force carries its load (within 2 %, plus delta / R between the
        spheres, the order to which the reference's SJKR area is LIGGGHTS' lens area), and
        moving no faster than the decayed vibration allows."""
        material = params.MATERIALS[name]
        needs = ["primitive-walls"]
        needs += ["cohesion"] if material.get("cohesionEnergyDensity", 0) > 0 else []
        needs += ["rolling-friction"] if material.get("coefficientRollingFriction", 0) > 0 else []
        if not all(self.supports(need) for need in needs):
            with pytest.raises(UnsupportedFeature):
                settled[name].get()
            return
        result = settled[name].get()
        x, v = result["x"], result["v"]
        lone, bottom, top = result["expected"]
        assert result["lost"] == 0 and len(x) == 3
        assert np.isfinite(x).all() and np.isfinite(v).all()
        assert RADIUS - x[0, 2] == pytest.approx(lone, rel=0.02)
        assert RADIUS - x[1, 2] == pytest.approx(bottom, rel=0.02)
        assert 2 * RADIUS - (x[2, 2] - x[1, 2]) == pytest.approx(top, rel=0.02 + top / RADIUS)
        # the vibration has decayed to SETTLE_DECAY: its energy to SETTLE_DECAY^2 of what the
        # spheres had above rest when set down, at most
        assert np.abs(v).max() < SETTLE_DECAY * math.sqrt(2 * result["energy"] / result["mass"])

    def test_cohesion(self, settled):
        """``cohesive`` is ``organic`` with cohesion: it rests about a hundred times deeper,
        as the reference model says; without the capability it is refused."""
        assert {k: v for k, v in MATERIAL.items() if k != "cohesionEnergyDensity"} == {
            k: v for k, v in params.MATERIALS["cohesive"].items() if k != "cohesionEnergyDensity"
        }
        if not self.supports("primitive-walls") or not self.supports("cohesion"):
            with pytest.raises(UnsupportedFeature):
                settled["cohesive"].get()
            return
        plain, sticky = settled["organic"].get(), settled["cohesive"].get()
        ratio = (RADIUS - sticky["x"][0, 2]) / (RADIUS - plain["x"][0, 2])
        assert ratio > 10
        assert ratio == pytest.approx(sticky["expected"][0] / plain["expected"][0], rel=0.03)

    def rolling(self, output: Path, friction: float) -> np.ndarray:
        """A sphere rolling on a floor at 5 cm/s: its position every 5 ms for 50 ms."""
        material = dict(MATERIAL, coefficientRollingFriction=friction)
        box = (-5e-3, 8e-3, -2e-3, 2e-3, -1e-3, 3e-3)
        v, species = 0.05, ({"material": material, "radius": RADIUS},)
        dt = self.dt()
        with self.dem(output, box=box, dt=dt, gravity=GRAVITY, species=species) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            spin = (0.0, v / RADIUS, 0.0)  # rolling without sliding
            sim.createParticles(1, "single", -4e-3, 0.0, RADIUS, vel=(v, 0.0, 0.0), omega=spin)
            track = [(0.0, -4e-3)]
            for _ in range(10):
                sim.run(round(0.005 / dt))
                track.append((sim.time, sim.extractCoords()[0, 0]))
        return np.array(track)

    def test_rolling_friction(self, tmp_path):
        """With rolling friction mu_r, a rolling sphere decelerates at 5/7 mu_r g (the cdt
        torque mu_r R |F_n| against its spin); without, it keeps rolling."""
        if not self.supports("rolling-friction"):
            with pytest.raises(UnsupportedFeature):
                self.rolling(tmp_path, 0.05)
            return
        decelerations = []
        for friction in (0.05, 0.0):
            t, x = self.rolling(tmp_path / f"mu{friction:g}", friction).T
            decelerations.append(-2 * np.polyfit(t, x, 2)[0])
        assert decelerations[0] == pytest.approx(5 / 7 * 0.05 * G, rel=0.05)
        assert abs(decelerations[1]) < 0.01 * decelerations[0]

    # -- user mistakes (pygran_core.testing.mistakes) ----------------------------------------------------

    @pytest.mark.parametrize(
        ("change", "error", "named"), [pytest.param(*r[1:], id=r[0]) for r in mistakes.SETUP]
    )
    def test_setup_mistake(self, tmp_path, change, error, named):
        """A mistake in ``DEM(**params)``: the same error class on every engine, naming the key."""
        with pytest.raises(error) as info:
            DEM(**change(mistakes.valid(tmp_path / "out", self.engine, self.model) | dict(self.options)))
        assert named in str(info.value)

    @pytest.mark.parametrize(
        ("row", "change", "capability", "named"), [pytest.param(*r, id=r[0]) for r in mistakes.UNSUPPORTED]
    )
    def test_setting_honoured_or_refused(self, tmp_path, row, change, capability, named):
        """A setting the engine declares is taken; any other is refused, naming the setting and
        the capability (or, first, the capability its simulation needs besides)."""
        settings = change(mistakes.valid(tmp_path / "out", self.engine, self.model) | dict(self.options))
        needed = mistakes.NEEDS.get(row)
        if needed is not None and not self.supports(needed):
            with pytest.raises(UnsupportedFeature, match=f"capability {needed!r}"):
                DEM(**settings)
            return
        if self.supports(capability):
            DEM(**settings).close()
            return
        with pytest.raises(UnsupportedFeature) as info:
            DEM(**settings)
        assert named in str(info.value) and f"capability {capability!r}" in str(info.value)

    @pytest.fixture(scope="class")
    @classmethod
    def mistaken(cls, tmp_path_factory) -> Iterator[DEM]:
        """The simulation of :func:`mistakes.running` on this engine."""
        suite = cls()
        output = tmp_path_factory.mktemp("mistakes") / "out"
        floor = suite.supports("primitive-walls")
        sim = mistakes.running(output, cls.engine, suite.model, floor, **cls.options)
        yield sim
        sim.close()

    @pytest.mark.parametrize(
        ("call", "error", "named"), [pytest.param(*r[1:], id=r[0]) for r in mistakes.CALL]
    )
    def test_call_mistake(self, mistaken, call, error, named):
        """A mistake in a call on a running simulation: the same error class on every engine,
        naming the key, and refused before it changes anything."""
        sim = mistaken
        before = (sim.step, sim.engine.dt, len(sim.engine.handles), len(sim.extractIds()))
        with pytest.raises(error) as info:
            call(sim)
        assert named in str(info.value)
        assert (sim.step, sim.engine.dt, len(sim.engine.handles), len(sim.extractIds())) == before


class _Lazy(dict):
    """A dict whose missing entries are made by ``make(key)`` when first read."""

    def __init__(self, make: Callable[[str], Any]) -> None:
        super().__init__()
        self.make = make

    def __missing__(self, key: str) -> Any:
        self[key] = value = self.make(key)
        return value
