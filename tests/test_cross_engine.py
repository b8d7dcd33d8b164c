"""Engines agree: the same ``simulation.DEM`` scripts run on every engine and are compared.

Scenarios: a sphere-wall impact for each contact model and a head-on two-sphere collision
(contact time and restitution within 2 % of the reference model and across engines), the
settle benchmark at 1000 spheres (bulk packing fraction within 2 %, coordination number
within 10 % across engines) and a hopper discharge through ``silo.stl`` (discharge rate
within 15 % across engines). Each scenario runs once per engine; per-engine tests compare
with the reference, per-pair tests compare engines with each other.

The engines are every installed one plus the first-party ones: with ``CI=true`` an engine
whose plugin or solver is missing, or that does not declare what the comparison needs,
fails; elsewhere it is skipped with the reason. A model an engine does not declare must
raise :class:`UnsupportedFeature`: that is asserted.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from pygran_core import registry
from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation import models
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.solvers import in_ci, require_solver
from pygran_core.testing.validation import (
    IMPACT_MATERIALS,
    IMPACT_SPEED,
    RADIUS,
    Bed,
    Collision,
    one_species,
    settle,
    wall_impact,
)

ENGINES = sorted(set(registry.available("engine")) | {"native", "liggghts", "yade"})
#: What every compared engine must declare: Hertz-Mindlin, plane and mesh walls, periodic boxes.
NEEDED = frozenset({"hertz-mindlin", "primitive-walls", "mesh-walls", "periodic"})
SILO = Path(__file__).resolve().parent / "data" / "meshes" / "silo.stl"
#: The hopper's material (LIGGGHTS' softest without soft_particles) and sphere radius.
HOPPER_MATERIAL = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.3,
    "coefficientRestitution": 0.5,
    "coefficientFriction": 0.5,
    "density": 1000.0,
}
HOPPER_RADIUS = 5e-5
HOPPER_SPHERES = 300


def _declares(engine: str, capability: str) -> bool:
    installed = registry.available("engine")
    return engine in installed and capability in installed[engine].spec.capabilities


def require_engine(engine: str) -> None:
    """Unless ``engine`` is installed, finds its solver and declares :data:`NEEDED`: fail
    with ``CI=true``, else skip."""
    installed = registry.available("engine")
    if engine in installed and installed[engine].spec.locate_solver is not None:
        require_solver(installed[engine].spec.locate_solver)
    if engine not in installed:
        problem = f"the {engine} engine is not installed. {registry.install_hint(engine)}"
    else:
        missing = NEEDED - installed[engine].spec.capabilities
        if not missing:
            return
        needed = ", ".join(sorted(missing))
        problem = f"the {engine} engine does not declare {needed}, needed to compare engines"
    if in_ci():
        pytest.fail(f"CI=true and {problem}", pytrace=False)
    pytest.skip(problem)


class Runs:
    """Each scenario's result per engine, run once for the module (exceptions are kept and re-raised)."""

    def __init__(self, base: Path) -> None:
        self.base = base
        self.done: dict[tuple[str, ...], object] = {}

    def get(self, scenario, engine: str, *args):
        key = (scenario.__name__, engine, *map(str, args))
        if key not in self.done:
            require_engine(engine)
            try:
                self.done[key] = scenario(engine, self.base.joinpath(*key), *args)
            except Exception as exc:  # noqa: BLE001 - kept to re-raise in every test that needs it
                self.done[key] = exc
        result = self.done[key]
        if isinstance(result, Exception):
            raise result
        return result


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Runs:
    return Runs(tmp_path_factory.mktemp("engines"))


def close(a: float, b: float, tolerance: float) -> bool:
    return abs(a / b - 1) <= tolerance


# -- scenarios -----------------------------------------------------------------------------------


def impact(engine: str, output: Path, model_name: str) -> Collision:
    """Sphere-wall impact of ``model_name`` at 0.1 m/s (see validation.wall_impact)."""
    model = MODELS[model_name]
    return wall_impact(engine, output, model, IMPACT_MATERIALS[model])


def two_spheres(engine: str, output: Path) -> Collision:
    """Two equal Hertz-Mindlin spheres (e = 0.5) approaching head-on at 0.1 m/s each, no gravity.

    As for the wall impact, the contact ends when the free flight after it extrapolates
    back to touching: ``T - gap_T / u_T``, with ``u`` the separation speed."""
    material, speed = IMPACT_MATERIALS[HertzMindlin], IMPACT_SPEED
    sphere = dict(material, radius=RADIUS)
    dt = HertzMindlin(material=sphere, partner=sphere).contactTime(2 * speed) / 400
    box = (-4 * RADIUS, 4 * RADIUS, -2 * RADIUS, 2 * RADIUS, -2 * RADIUS, 2 * RADIUS)
    with one_species(engine, output, material, RADIUS, model=HertzMindlin, box=box, dt=dt) as sim:
        for side in (-1, 1):
            start = side * (RADIUS + 0.5 * speed * dt)
            sim.createParticles(1, "single", start, 0.0, 0.0, vel=(-side * speed, 0.0, 0.0))
        sim.run(1600)
        x, v, end = sim.extractCoords()[:, 0], sim.extractVelocities()[:, 0], sim.time
    gap, separating = x[1] - x[0] - 2 * RADIUS, v[1] - v[0]
    assert gap > 0 and separating > 0, f"the spheres are still in contact: gap {gap}, speed {separating}"
    return Collision(end - gap / separating - dt / 2, separating / (2 * speed))


def settled(engine: str, output: Path) -> Bed:
    """The settle benchmark with 10 x 10 x 10 spheres (360 leave differences of up to 3 %
    between runs of one engine from different random displacements)."""
    return settle(engine, output, shape=(10, 10, 10))


def hopper_positions(seed: int = 5) -> np.ndarray:
    """The lowest ``HOPPER_SPHERES`` sites of a lattice (spacing 2.2 r) that fit in the conical
    hopper (radius 0.3 mm at z = 0 to 1 mm at z = 3 mm, 16 facets), jittered by up to 0.09 r."""
    spacing = 2.2 * HOPPER_RADIUS
    across = np.arange(-1e-3 + spacing / 2, 1e-3, spacing)
    up = np.arange(spacing / 2, 3e-3, spacing)
    sites = np.stack(np.meshgrid(across, across, up, indexing="ij"), axis=-1).reshape(-1, 3)
    facet = (3e-4 + sites[:, 2] * 7e-4 / 3e-3) * math.cos(math.pi / 16)  # inscribed radius of the 16-gon
    sites = sites[np.hypot(sites[:, 0], sites[:, 1]) < facet - 1.3 * HOPPER_RADIUS]
    sites = sites[np.argsort(sites[:, 2], kind="stable")][:HOPPER_SPHERES]
    return sites + np.random.default_rng(seed).uniform(-1, 1, sites.shape) * 0.09 * HOPPER_RADIUS


def hopper(engine: str, output: Path) -> tuple[float, np.ndarray]:
    """Spheres settle for 5 ms on a stopper at the outlet of ``silo.stl`` (scale 1e-3), then
    discharge for 20 ms; returns the discharge rate (spheres/s: the least-squares slope of
    the count above the outlet while it falls from 90 % to 30 %) and the counts."""
    mesh = {"hopper": {"file": str(SILO), "mtype": "mesh/surface", "args": ("scale 1e-3",)}}
    box = (-1e-3, 1e-3, -1e-3, 1e-3, -1e-3, 4e-3)
    counts, times = [], []
    with one_species(
        engine,
        output,
        HOPPER_MATERIAL,
        HOPPER_RADIUS,
        model=HertzMindlin,
        box=box,
        mesh=mesh,
        dt=5e-7,
        gravity=(9.81, 0, 0, -1),
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="hopper")
        stopper = sim.setupWall(plane="zplane", peq=0.0)
        for position in hopper_positions():
            sim.createParticles(1, "single", *position)
        sim.run(10_000)
        assert len(sim.extractIds()) == HOPPER_SPHERES and sim.extractCoords()[:, 2].min() > 0
        sim.remove(stopper)
        sim.expect_outflow("z-")  # the outlet opens onto the bottom of the box
        for _ in range(40):
            sim.run(1000)
            counts.append(np.count_nonzero(sim.extractCoords()[:, 2] > 0))
            times.append(sim.time)
    counts, times = np.array(counts), np.array(times)
    steady = (counts <= 0.9 * HOPPER_SPHERES) & (counts >= 0.3 * HOPPER_SPHERES)
    assert steady.sum() >= 5, f"too few samples of steady discharge: {counts.tolist()}"
    return -np.polyfit(times[steady], counts[steady], 1)[0], counts


# -- parameters -------------------------------------------------------------------------------------


def unsupported(engine: str, model: str | None = None) -> str | None:
    """What ``engine`` must raise UnsupportedFeature about for ``model``, if anything."""
    if model is not None and not _declares(engine, getattr(models, model).kernel):
        return model
    return None


def measure(runs: Runs, scenario, engine: str, model: str | None = None):
    """The scenario's result, or ``None`` once the engine's expected UnsupportedFeature is asserted."""
    args = () if model is None else (model,)
    reason = unsupported(engine, model)
    if reason is None:
        return runs.get(scenario, engine, *args)
    require_engine(engine)
    with pytest.raises(UnsupportedFeature, match=reason):
        runs.get(scenario, engine, *args)
    return None


def pairs(model: str | None = None) -> list[tuple[str, str]]:
    """Pairs of engines that both run ``model`` (every pair without one)."""
    return list(itertools.combinations([e for e in ENGINES if unsupported(e, model) is None], 2))


MODELS = {model.__name__: model for model in IMPACT_MATERIALS}

# -- one engine against the reference -------------------------------------------------------------


@pytest.mark.parametrize(
    ("engine", "model"),
    [pytest.param(e, m, id=f"{e}-{m}") for e in ENGINES for m in MODELS],
)
def test_wall_impact_matches_the_reference_model(runs, engine, model):
    measured = measure(runs, impact, engine, model)
    if measured is None:
        return
    cls = MODELS[model]
    reference = cls(material=dict(IMPACT_MATERIALS[cls], radius=RADIUS)).displacement(IMPACT_SPEED)
    # the measured time is the time within R of the wall: a plastic contact (Thornton-Ning)
    # ends earlier, at its permanent overlap, from which the sphere flies off freely
    (overlap, speed) = reference.soln[-1]
    within = reference.contact_time + overlap / abs(speed)
    assert close(measured.contact_time, within, 0.02), (measured, within)
    assert close(measured.restitution, reference.restitution, 0.02), (measured, reference.restitution)


@pytest.mark.parametrize("engine", ENGINES)
def test_two_sphere_collision_matches_the_reference_model(runs, engine):
    measured = measure(runs, two_spheres, engine)
    if measured is None:
        return
    material = dict(IMPACT_MATERIALS[HertzMindlin], radius=RADIUS)
    reference = HertzMindlin(material=material, partner=material).displacement(2 * IMPACT_SPEED)
    assert close(measured.contact_time, reference.contact_time, 0.02), (measured, reference.contact_time)
    assert close(measured.restitution, reference.restitution, 0.02), (measured, reference.restitution)


@pytest.mark.parametrize("engine", ENGINES)
def test_settled_bed_is_a_random_packing(runs, engine):
    bed = measure(runs, settled, engine)
    if bed is None:
        return
    assert 0.55 <= bed.packing_fraction <= 0.62, bed
    assert 4.0 <= bed.coordination <= 6.5 and bed.count > 400, bed


@pytest.mark.parametrize("engine", ENGINES)
def test_hopper_discharges(runs, engine):
    discharge = measure(runs, hopper, engine)
    if discharge is None:
        return
    rate, counts = discharge
    assert counts[0] == HOPPER_SPHERES and counts[-1] < 0.3 * HOPPER_SPHERES, counts
    assert rate > 0


# -- engines against each other ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("a", "b", "model"),
    [pytest.param(a, b, m, id=f"{a}-{b}-{m}") for m in MODELS for a, b in pairs(m)],
)
def test_engines_agree_on_wall_impacts(runs, a, b, model):
    first, second = (runs.get(impact, e, model) for e in (a, b))
    assert close(first.contact_time, second.contact_time, 0.02), (first, second)
    assert close(first.restitution, second.restitution, 0.02), (first, second)


@pytest.mark.parametrize(("a", "b"), pairs())
def test_engines_agree_on_two_sphere_collisions(runs, a, b):
    first, second = (runs.get(two_spheres, e) for e in (a, b))
    assert close(first.contact_time, second.contact_time, 0.02), (first, second)
    assert close(first.restitution, second.restitution, 0.02), (first, second)


@pytest.mark.parametrize(("a", "b"), pairs())
def test_engines_agree_on_the_settled_bed(runs, a, b):
    first, second = (runs.get(settled, e) for e in (a, b))
    assert close(first.packing_fraction, second.packing_fraction, 0.02), (first, second)
    assert close(first.coordination, second.coordination, 0.10), (first, second)


@pytest.mark.parametrize(("a", "b"), pairs())
def test_engines_agree_on_hopper_discharge(runs, a, b):
    (first, _), (second, _) = (runs.get(hopper, e) for e in (a, b))
    assert close(first, second, 0.15), (first, second)
