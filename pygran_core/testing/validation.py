"""Physics checks of a DEM engine against closed forms: what ``pygran validate`` runs.

Every check runs real simulations through :class:`~pygran_core.simulation.DEM` with soft
spheres (radius 1 mm, E = 5 MPa as in ``benchmarks/settle.md``, so time steps are large
and runs short) and compares numbers with their known values:

===========  ======================================================================  =========
check        expected                                                                tolerance
===========  ======================================================================  =========
hertz        undamped head-on sphere-wall impact at 0.1 m/s: Hertz contact time      1 %
             ``2.868 (m*^2 / (R* E*^2 v))^(1/5)`` and maximum overlap
             ``(15 m* v^2 / (16 E* R*^(1/2)))^(2/5)``
restitution  realised restitution of a wall impact: ``e`` for SpringDashpot and      1 %
             HertzMindlin; Thornton's (1997) closed form for ThorntonNing
rolling      a sphere sliding on a floor without spin ends rolling at 5/7 of its     1 %
             speed, whatever the friction coefficient (0.2 and 0.8)
energy       27 spheres in a walled box, ``e = 1``, no friction, no gravity:         1e-4
             kinetic plus Hertz elastic energy stays within 1e-4 of its start
             over 1e4 steps
packing      the settle benchmark with 6 x 6 x 10 spheres: bulk packing fraction     0.55-0.62
===========  ======================================================================  =========

The check ``thornton-ning`` runs ThorntonNing wall impacts: the restitution at each yield-to-impact
speed ratio of Thornton's (1997) table (1, 0.5, 0.2, 0.1, 0.05, 0.01; e = 1, 0.931, 0.773,
0.659, 0.557, 0.374) against his closed form and the JKR pull-off force ``3 pi Gamma R*``, each
within 1 %; on an engine other than native, also an adhesive plastic impact's force at every
step against native's, within 1e-6 of the peak force.

A model or feature the engine lacks makes its rows ``unsupported`` (the engine raised
:class:`~pygran_core.errors.UnsupportedFeature`), which is not a failure unless no row could
run at all; any other PyGran error in a simulation is a failed row whose notes say what
happened.

Use :func:`run_validation`, then :func:`format_table`, :func:`summary` and :func:`exit_status`. The scenario
functions (:func:`wall_impact`, :func:`rolling_speed_ratio`, :func:`energy_drift`,
:func:`settle`) return the measured numbers and are shared with the cross-engine tests.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import PyGranError, UnsupportedFeature, unknown_key
from pygran_core.simulation.dem import DEM, resolve_engine
from pygran_core.simulation.models import ContactModel, HertzMindlin, SpringDashpot, ThorntonNing

#: The settle benchmark's material (benchmarks/settle.md).
SOFT: Mapping[str, float] = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.45,
    "coefficientRestitution": 0.3,
    "coefficientFriction": 0.5,
    "density": 2500.0,
}
RADIUS = 1e-3
#: Impact speed of the wall impacts (m/s), also the SpringDashpot characteristic velocity.
IMPACT_SPEED = 0.1
#: Time steps per reference contact time in the impacts.
STEPS_PER_CONTACT = 400
GRAVITY = (9.81, 0.0, 0.0, -1.0)


@dataclass(frozen=True)
class CheckResult:
    """One row of the validation table.

    ``obtained`` is ``None`` when the simulation could not run: ``unsupported`` (the engine
    lacks the model or feature; not a failure) or an error (a failure), explained in ``notes``.
    The check passes when ``|obtained - expected| <= tolerance``, the tolerance being a
    fraction of ``|expected|`` if ``relative``, else absolute.
    """

    name: str
    expected: float
    obtained: float | None
    tolerance: float
    relative: bool = True
    units: str = ""
    notes: str = ""
    unsupported: bool = False

    @property
    def passed(self) -> bool | None:
        """True or False; ``None`` for an unsupported check."""
        if self.unsupported:
            return None
        if self.obtained is None or not math.isfinite(self.obtained):
            return False
        allowed = self.tolerance * (abs(self.expected) if self.relative else 1.0)
        return abs(self.obtained - self.expected) <= allowed

    @property
    def status(self) -> str:
        return {True: "pass", False: "FAIL", None: "unsupported"}[self.passed]


@dataclass(frozen=True)
class Collision:
    """A measured impact: contact time (s), restitution and, when sampled, the largest overlap (m)."""

    contact_time: float
    restitution: float
    max_overlap: float | None = None


@dataclass(frozen=True)
class Bed:
    """A settled bed: bulk packing fraction and mean coordination number of the bulk spheres."""

    packing_fraction: float
    coordination: float
    count: int  #: spheres centred in the bulk


# -- closed forms -------------------------------------------------------------------------------


def contact_modulus(material: Mapping[str, float]) -> float:
    """``E*`` of two bodies (or a body and a wall) of ``material``: ``E / (2 (1 - nu^2))``."""
    return material["youngsModulus"] / (2 * (1 - material["poissonsRatio"] ** 2))


def sphere_mass(material: Mapping[str, float], radius: float) -> float:
    return 4 / 3 * math.pi * radius**3 * material["density"]


def hertz_max_overlap(mass: float, radius: float, modulus: float, speed: float) -> float:
    """Largest overlap of an undamped Hertz impact: ``(15 m* v^2 / (16 E* R*^(1/2)))^(2/5)``."""
    return (15 * mass * speed**2 / (16 * modulus * math.sqrt(radius))) ** 0.4


def hertz_contact_time(mass: float, radius: float, modulus: float, speed: float) -> float:
    """Undamped Hertz contact time, ``2.868 (m*^2 / (R* E*^2 v))^(1/5)``.

    Exactly ``2 (delta_max / v) * (2/5) B(2/5, 1/2)``, i.e. 2.8682 with 2.868's rounding removed.
    """
    integral = 0.4 * math.gamma(0.4) * math.gamma(0.5) / math.gamma(0.9)
    return 2 * integral * hertz_max_overlap(mass, radius, modulus, speed) / speed


def thornton_restitution(material: Mapping[str, float], radius: float, speed: float) -> float:
    """Restitution of an elastic-perfectly-plastic sphere-wall impact (Thornton 1997, eq. 40).

    ``V_y = (pi^4 / 40)^(1/2) (p_y^5 / (E*^4 rho))^(1/2)`` (Thornton's 1.56) is the speed
    at which yield begins; slower impacts are elastic (``e = 1``).
    """
    modulus = contact_modulus(material)
    yield_speed = math.sqrt(
        math.pi**4 / 40 * material["yieldPress"] ** 5 / (modulus**4 * material["density"])
    )
    if speed <= yield_speed:
        return 1.0
    r = yield_speed / speed
    return (
        math.sqrt(6 * math.sqrt(3) / 5)
        * math.sqrt(1 - r**2 / 6)
        * (r / (r + 2 * math.sqrt(6 / 5 - r**2 / 5))) ** 0.25
    )


# -- scenarios --------------------------------------------------------------------------------------


def union_properties(
    spheres: Sequence[Sequence[float]], density: float, samples: int = 2_000_000, seed: int = 7
) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre and inertia tensor of the union of ``spheres`` (rows ``x, y, z, r``), by
    plain Monte Carlo in their bounding box: a reference for clumps independent of
    :func:`pygran_core.simulation.clumps.mass_properties`, which engines use."""
    array = np.array(spheres, float)
    lo = (array[:, :3] - array[:, 3:]).min(axis=0)
    hi = (array[:, :3] + array[:, 3:]).max(axis=0)
    points = np.random.default_rng(seed).uniform(lo, hi, (samples, 3))
    inside = np.zeros(samples, bool)
    for *centre, r in array:
        inside |= np.sum((points - centre) ** 2, axis=1) < r**2
    mass = float(density * np.prod(hi - lo) * inside.mean())
    points = points[inside]
    centre = points.mean(axis=0)
    d = points - centre
    inertia = mass * (np.eye(3) * np.mean(np.sum(d * d, axis=1)) - d.T @ d / len(d))
    return mass, centre, inertia


def one_species(
    engine: str, output: Path, material: Mapping[str, float], radius: float, **params: Any
) -> DEM:
    """A :class:`DEM` of one species, one thread, no progress bar and no trajectory file."""
    settings = {
        "engine": engine,
        "output": str(output),
        "progress": False,
        "threads": 1,
        "traj": {"pfile": None},
        "species": ({"material": dict(material), "radius": radius},),
    }
    return DEM(**settings | params)


def wall_impact(
    engine: str,
    output: Path,
    model: type[ContactModel],
    material: Mapping[str, float],
    radius: float = RADIUS,
    speed: float = IMPACT_SPEED,
    samples: int = 0,
) -> Collision:
    """A sphere hitting a plane wall head-on at ``speed``, without gravity.

    The time step is 1/400 of the reference model's contact time. The contact starts at
    ``(z0 - R) / v`` and ends at ``T - (z_T - R) / v_T``, extrapolated back from the free
    flight after it, so no sampling limits the contact time. (It is the time the sphere
    spends within R of the wall: a plastic contact ends earlier, at its permanent overlap.)
    With ``samples > 0`` the overlap is also sampled that many times during 1.5 reference
    contact times for its maximum.
    A sphere that has not left the wall after 4 contact times gives ``contact_time = inf``.
    """
    reference = model(material=dict(material, radius=radius)).contactTime(speed)
    dt = reference / STEPS_PER_CONTACT
    total = 4 * STEPS_PER_CONTACT
    every = math.ceil(1.5 * STEPS_PER_CONTACT / samples) if samples else 0
    start = radius + 0.5 * speed * dt
    box = (-2 * radius, 2 * radius, -2 * radius, 2 * radius, -radius, 4 * radius)
    overlaps = []
    with one_species(engine, output, material, radius, model=model, box=box, dt=dt) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, start, vel=(0.0, 0.0, -speed))
        for _ in range(samples):
            sim.run(every)
            overlaps.append(radius - sim.extractCoords()[0, 2])
        sim.run(total - every * samples)
        z, vz, end = sim.extractCoords()[0, 2], sim.extractVelocities()[0, 2], sim.time
    max_overlap = max(overlaps) if overlaps else None
    if vz <= 0 or z <= radius:
        return Collision(math.inf, 0.0, max_overlap)
    contact_time = end - (z - radius) / vz - (start - radius) / speed
    return Collision(contact_time, vz / speed, max_overlap)


def rolling_speed_ratio(
    engine: str, output: Path, material: Mapping[str, float], radius: float = RADIUS, speed: float = 0.1
) -> float:
    """A sphere set on a floor sliding at ``speed`` without spin: its mean speed from 20 to
    40 ms later over ``speed``.

    The mean speed comes from the distance travelled over those 20 ms, which averages out
    the tangential spring's vibration once the sphere rolls.
    """
    box = (-2 * radius, 10 * radius, -2 * radius, 2 * radius, -radius, 3 * radius)
    with one_species(
        engine, output, material, radius, model=HertzMindlin, box=box, dt=1e-5, gravity=GRAVITY
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, radius, vel=(speed, 0.0, 0.0))
        sim.run(2000)
        x1, t1 = sim.extractCoords()[0, 0], sim.time
        sim.run(2000)
        x2, t2 = sim.extractCoords()[0, 0], sim.time
    return (x2 - x1) / (t2 - t1) / speed


def energy_drift(
    engine: str, output: Path, material: Mapping[str, float], steps: int = 10_000, every: int = 100
) -> float:
    """Largest relative change of the total energy of 27 spheres colliding in a walled box.

    Spheres of radius 1 mm on a 3 x 3 x 3 lattice of spacing 2.5 mm fill a cube with six
    plane walls; their seeded random velocities are up to 0.2 m/s; no gravity. The total
    energy, sampled every ``every`` steps, is the translational and rotational kinetic
    energy plus the Hertz elastic energy ``8/15 E* R*^(1/2) delta^(5/2)`` of every
    sphere-sphere and sphere-wall overlap. The time step is 1/200 of the Hertz contact
    time at the largest possible approach speed.
    """
    from scipy.spatial import cKDTree

    radius, spacing, n = RADIUS, 2.5e-3, 3
    side = n * spacing
    rng = np.random.default_rng(27)
    centres = (_lattice((n, n, n)) + 0.5) * spacing
    velocities = rng.uniform(-1, 1, centres.shape) * 0.2 / math.sqrt(3)
    mass, modulus = sphere_mass(material, radius), contact_modulus(material)
    dt = hertz_contact_time(mass / 2, radius / 2, modulus, 0.4) / 200

    def total_energy(x: np.ndarray, v: np.ndarray, w: np.ndarray) -> float:
        kinetic = 0.5 * mass * np.sum(v**2) + 0.5 * 0.4 * mass * radius**2 * np.sum(w**2)
        pairs = cKDTree(x).query_pairs(2 * radius, output_type="ndarray")
        pair_overlap = 2 * radius - np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
        wall_overlap = np.clip(radius - np.concatenate([x, side - x]).ravel(), 0.0, None)
        pair_elastic = math.sqrt(radius / 2) * np.sum(np.clip(pair_overlap, 0.0, None) ** 2.5)
        wall_elastic = math.sqrt(radius) * np.sum(wall_overlap**2.5)
        return float(kinetic + 8 / 15 * modulus * (pair_elastic + wall_elastic))

    box = (0.0, side, 0.0, side, 0.0, side)
    energies: list[float] = []
    with one_species(engine, output, material, radius, model=HertzMindlin, box=box, dt=dt) as sim:
        for plane in ("xplane", "yplane", "zplane"):
            sim.setupWall(species=1, plane=plane, peq=0.0)
            sim.setupWall(species=1, plane=plane, peq=side)
        for centre, velocity in zip(centres, velocities):
            sim.createParticles(1, "single", *centre, vel=tuple(velocity))
        for _ in range(steps // every + 1):
            if energies:
                sim.run(every)
            energies.append(total_energy(sim.extractCoords(), sim.extractVelocities(), sim.extractOmegas()))
    return float(np.max(np.abs(np.array(energies) / energies[0] - 1)))


def _lattice(shape: tuple[int, int, int]) -> np.ndarray:
    """Integer coordinates (n, 3) of the cells of a ``shape`` lattice, x slowest."""
    return np.stack(np.meshgrid(*(np.arange(k) for k in shape), indexing="ij"), axis=-1).reshape(-1, 3)


#: Lattice spacing of the settle scenario: 1.1 particle diameters.
SETTLE_SPACING = 1.1 * 2 * RADIUS


def settle_positions(shape: tuple[int, int, int], seed: int = 12345) -> np.ndarray:
    """The settle scenario's start: cell centres ``(i + 0.5) a`` of an ``NX x NY x NZ`` lattice
    (x slowest), each displaced uniformly by up to ``0.45 (a - 2r)`` per axis."""
    cells = _lattice(shape)
    jitter = np.random.default_rng(seed).uniform(-1, 1, cells.shape) * 0.45 * (SETTLE_SPACING - 2 * RADIUS)
    return (cells + 0.5) * SETTLE_SPACING + jitter


def settle_setup(
    engine: str,
    output: Path,
    shape: tuple[int, int, int],
    material: Mapping[str, float] = SOFT,
    seed: int = 12345,
    **params: Any,
) -> DEM:
    """The settle scenario of ``benchmarks/settle.md`` ready to run: Hertz-Mindlin spheres of
    radius 1 mm at :func:`settle_positions` in a box periodic in x and y with a floor at
    z = 0, gravity, dt = 1e-5 s, skin 0.4 mm. ``params`` override keywords (``threads``,
    ``nprocs``, ``output``...)."""
    nx, ny, nz = shape
    a = SETTLE_SPACING
    sim = one_species(
        engine,
        output,
        material,
        RADIUS,
        **{
            "model": HertzMindlin,
            "box": (0.0, nx * a, 0.0, ny * a, 0.0, (nz + 3) * a),
            "boundary": ("p", "p", "f"),
            "gravity": GRAVITY,
            "dt": 1e-5,
            "nns_skin": 4e-4,
            **params,
        },
    )
    sim.setupWall(species=1, plane="zplane", peq=0.0)
    sim.createParticles(1, "single", settle_positions(shape, seed))
    return sim


def _slab_volume(z: np.ndarray, radii: np.ndarray, low: float, high: float) -> float:
    """Total volume of the spheres (centres at heights ``z``) between the planes ``low`` and ``high``."""
    a, b = (np.clip(h - z, -radii, radii) for h in (low, high))
    return float(np.sum(math.pi * (radii**2 * (b - a) - (b**3 - a**3) / 3)))


def settle(
    engine: str,
    output: Path,
    shape: tuple[int, int, int] = (6, 6, 10),
    material: Mapping[str, float] = SOFT,
    steps: tuple[int, int] = (8000, 4000),
    seed: int = 2024,
) -> Bed:
    """The settle scenario of ``benchmarks/settle.md`` with ``NX x NY x NZ = shape`` spheres.

    The spheres of :func:`settle_setup` fall onto the floor for ``steps`` (settle, dense bed)
    steps. The bulk is the slab from two diameters above the floor to two diameters below the
    bed's top (the highest sphere's top): its packing fraction counts the parts of spheres
    inside it exactly; the coordination number is the mean count of touching neighbours
    (:class:`~pygran_core.analysis.equilibrium.Neighbors`) of the spheres centred in it.
    """
    from pygran_core.analysis import Particles
    from pygran_core.analysis.equilibrium import Neighbors

    with settle_setup(engine, output, shape, material, seed) as sim:
        for nsteps in steps:
            sim.run(nsteps)
        x, radii = sim.extractCoords(), sim.extractRadii()
        box = sim.spec.domain.box
    low, high = 4 * RADIUS, float(np.max(x[:, 2] + radii)) - 4 * RADIUS
    fraction = _slab_volume(x[:, 2], radii, low, high) / (box[0][1] * box[1][1] * (high - low))
    periodic = {"box": np.array(box), "boundary": ("pp", "pp", "ff")}
    bed = Particles(x=x[:, 0], y=x[:, 1], z=x[:, 2], radius=radii, **periodic)
    bulk = (x[:, 2] > low) & (x[:, 2] < high)
    coordination = float(Neighbors(bed).coon[bulk].mean())
    return Bed(fraction, coordination, int(bulk.sum()))


# -- checks -------------------------------------------------------------------------------------------


def _measure(measure: Callable[[], Sequence[float | None]], *rows: CheckResult) -> list[CheckResult]:
    """``rows`` with ``obtained`` filled from ``measure()`` (one value per row), or marked
    unsupported, or failed with the error in their notes."""
    try:
        values = measure()
    except UnsupportedFeature as exc:
        return [replace(row, unsupported=True, notes=str(exc)) for row in rows]
    except PyGranError as exc:
        return [replace(row, notes=f"error: {type(exc).__name__}: {exc}") for row in rows]
    return [
        replace(row, obtained=None if value is None else float(value))
        for row, value in zip(rows, values, strict=True)
    ]


def check_hertz(engine: str, output: Path, material: Mapping[str, float] | None = None) -> list[CheckResult]:
    """Contact time and largest overlap of an undamped impact against Hertz's closed forms."""
    if material is None:
        material = dict(SOFT, coefficientRestitution=1.0)
    args = (sphere_mass(material, RADIUS), RADIUS, contact_modulus(material), IMPACT_SPEED)

    def measure() -> tuple[float, float | None]:
        impact = wall_impact(engine, output, HertzMindlin, material, samples=60)
        return impact.contact_time, impact.max_overlap

    return _measure(
        measure,
        CheckResult("Hertz contact time", hertz_contact_time(*args), None, 0.01, units="s"),
        CheckResult("Hertz max overlap", hertz_max_overlap(*args), None, 0.01, units="m"),
    )


#: The material of each model's wall impact: e = 0.5, or a yield pressure giving V_y = 0.01 m/s.
IMPACT_MATERIALS: dict[type[ContactModel], Mapping[str, float]] = {
    SpringDashpot: dict(SOFT, coefficientRestitution=0.5, characteristicVelocity=IMPACT_SPEED),
    HertzMindlin: dict(SOFT, coefficientRestitution=0.5),
    ThorntonNing: {k: v for k, v in SOFT.items() if k != "coefficientRestitution"} | {"yieldPress": 1e5},
}


def check_restitution(
    engine: str, output: Path, materials: Mapping[type[ContactModel], Mapping[str, float]] | None = None
) -> list[CheckResult]:
    """Realised restitution of a wall impact for each model: ``e``, or Thornton's formula."""
    results = []
    for model, material in (IMPACT_MATERIALS if materials is None else materials).items():
        if model.kernel == "thornton-ning":
            expected, notes = thornton_restitution(material, RADIUS, IMPACT_SPEED), "Thornton (1997)"
        else:
            expected, notes = material["coefficientRestitution"], "material e"

        def measure(
            model: type[ContactModel] = model, material: Mapping[str, float] = material
        ) -> tuple[float]:
            return (wall_impact(engine, output / model.__name__, model, material).restitution,)

        results += _measure(
            measure, CheckResult(f"restitution {model.__name__}", expected, None, 0.01, notes=notes)
        )
    return results


def check_rolling(
    engine: str, output: Path, frictions: Iterable[float] = (0.2, 0.8), material: Mapping[str, float] = SOFT
) -> list[CheckResult]:
    """Final over initial speed of a sphere sliding on a floor, for each friction coefficient: 5/7."""
    results = []
    for mu in frictions:

        def measure(mu: float = mu) -> tuple[float]:
            return (
                rolling_speed_ratio(engine, output / f"mu{mu:g}", dict(material, coefficientFriction=mu)),
            )

        results += _measure(measure, CheckResult(f"rolling speed / v0 (mu={mu:g})", 5 / 7, None, 0.01))
    return results


def check_energy(engine: str, output: Path, material: Mapping[str, float] | None = None) -> list[CheckResult]:
    """Largest relative change of the total energy without dissipation: within 1e-4."""
    if material is None:
        material = dict(SOFT, coefficientRestitution=1.0, coefficientFriction=0.0)
    return _measure(
        lambda: (energy_drift(engine, output, material),),
        CheckResult("energy change", 0.0, None, 1e-4, relative=False, notes="relative, over 1e4 steps"),
    )


def check_packing(engine: str, output: Path, material: Mapping[str, float] = SOFT) -> list[CheckResult]:
    """Bulk packing fraction of the settled bed: 0.55 to 0.62 for frictional monodisperse spheres."""

    def measure() -> tuple[float]:
        return (settle(engine, output, material=material).packing_fraction,)

    return _measure(
        measure,
        CheckResult("packing fraction (settle)", 0.585, None, 0.035, relative=False, notes="range 0.55-0.62"),
    )


#: Yield speed over impact speed of Thornton's (1997) restitution table (1, 0.931, 0.773, 0.659,
#: 0.557 and 0.374 for a non-adhesive sphere hitting a wall).
THORNTON_RATIOS = (1.0, 0.5, 0.2, 0.1, 0.05, 0.01)
#: The adhesive ThorntonNing material of the trace: Gamma = 0.05 J/m^2, V_y = 0.01 m/s ...
ADHESIVE: Mapping[str, float] = dict(IMPACT_MATERIALS[ThorntonNing], cohesionEnergyDensity=0.05)
#: ... and of the pull-off force, kept elastic (V_y far above the impact speed), so that R_p = R.
ELASTIC_ADHESIVE: Mapping[str, float] = dict(ADHESIVE, yieldPress=1e9)


def impact_trace(
    engine: str,
    output: Path,
    model: type[ContactModel],
    material: Mapping[str, float],
    radius: float = RADIUS,
    speed: float = IMPACT_SPEED,
) -> np.ndarray:
    """The impact of :func:`wall_impact` step by step for twice the reference contact time:
    ``(overlap, force on the sphere along z)`` after each step, shape ``(steps, 2)``."""
    reference = model(material=dict(material, radius=radius)).contactTime(speed)
    dt = reference / STEPS_PER_CONTACT
    box = (-2 * radius, 2 * radius, -2 * radius, 2 * radius, -radius, 4 * radius)
    trace = []
    with one_species(engine, output, material, radius, model=model, box=box, dt=dt) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, radius + 0.5 * speed * dt, vel=(0.0, 0.0, -speed))
        for _ in range(2 * STEPS_PER_CONTACT):
            sim.run(1)
            trace.append((radius - sim.extractCoords()[0, 2], sim.extractForces()[0, 2]))
    return np.array(trace)


def check_thornton_ning(engine: str, output: Path) -> list[CheckResult]:
    """ThorntonNing: restitution against Thornton's (1997) closed form at each yield-to-impact
    speed ratio of :data:`THORNTON_RATIOS`, the JKR pull-off force ``3 pi Gamma R*`` (the
    strongest pull of an elastic adhesive impact) and, on engines other than native, an
    adhesive plastic impact's force at every step against native's (the largest difference
    over the peak force)."""
    material = IMPACT_MATERIALS[ThorntonNing]
    yield_speed = ThorntonNing(material=dict(material, radius=RADIUS)).yield_velocity
    results = []
    for ratio in THORNTON_RATIOS:
        speed = yield_speed / ratio

        def measure(speed: float = speed, folder: Path = output / f"V_y-over-V-{ratio:g}") -> tuple[float]:
            return (wall_impact(engine, folder, ThorntonNing, material, speed=speed).restitution,)

        expected = thornton_restitution(material, RADIUS, speed)
        name = f"Thornton-Ning e at V_y/V = {ratio:g}"
        results += _measure(measure, CheckResult(name, expected, None, 0.01, notes="Thornton (1997)"))

    def pull_off() -> tuple[float]:
        return (-impact_trace(engine, output / "pull-off", ThorntonNing, ELASTIC_ADHESIVE)[:, 1].min(),)

    expected = 3 * math.pi * ELASTIC_ADHESIVE["cohesionEnergyDensity"] * RADIUS
    row = CheckResult(
        "JKR pull-off force", expected, None, 0.01, units="N", notes="3 pi Gamma R*, elastic impact"
    )
    results += _measure(pull_off, row)
    if engine != "native":

        def differ() -> tuple[float]:
            trace = impact_trace(engine, output / "trace", ThorntonNing, ADHESIVE)
            native = impact_trace("native", output / "trace-native", ThorntonNing, ADHESIVE)
            return (np.abs(trace[:, 1] - native[:, 1]).max() / np.abs(native[:, 1]).max(),)

        notes = "max |F - F_native| / max |F_native|, adhesive plastic impact"
        row = CheckResult("Thornton-Ning trace vs native", 0.0, None, 1e-6, relative=False, notes=notes)
        results += _measure(differ, row)
    return results


#: Check name -> function(engine, output directory) returning its rows, in table order.
CHECKS: dict[str, Callable[[str, Path], list[CheckResult]]] = {
    "hertz": check_hertz,
    "restitution": check_restitution,
    "thornton-ning": check_thornton_ning,
    "rolling": check_rolling,
    "energy": check_energy,
    "packing": check_packing,
}


def run_validation(
    engine: str | None = None,
    checks: Iterable[str] | None = None,
    output: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[CheckResult]:
    """Run ``checks`` (names in :data:`CHECKS`; default all) on ``engine`` (default: as
    :class:`DEM` chooses); one row per number. ``progress(name)`` is called as each check starts.

    Simulations write to ``<output>/<check>/`` (resolved against the working directory),
    or to a temporary directory removed afterwards.
    """
    engine = resolve_engine(engine)
    names = list(CHECKS) if checks is None else list(checks)
    for name in names:
        if name not in CHECKS:
            raise unknown_key("check", name, CHECKS)

    def run_all(base: Path) -> list[CheckResult]:
        results = []
        for name in names:
            if progress is not None:
                progress(name)
            results += CHECKS[name](engine, base / name)
        return results

    if output is not None:
        return run_all(Path(output).absolute())
    with tempfile.TemporaryDirectory(prefix="pygran-validate-") as scratch:
        return run_all(Path(scratch))


def _number(value: float | None, units: str = "") -> str:
    return "-" if value is None else f"{value:.5g}{' ' + units if units else ''}"


def format_table(results: Sequence[CheckResult]) -> str:
    """The rows as an aligned text table: check, expected, obtained, tolerance, result and the
    first line of the notes; notes of several lines (solver logs) follow the table in full."""
    header = ("check", "expected", "obtained", "tolerance", "result", "notes")
    lines = [
        (
            r.name,
            _number(r.expected, r.units),
            _number(r.obtained, r.units),
            f"±{100 * r.tolerance:.3g} %" if r.relative else f"±{r.tolerance:.3g}",
            r.status,
            r.notes.partition("\n")[0],
        )
        for r in results
    ]
    widths = [max(len(row[i]) for row in (header, *lines)) for i in range(len(header) - 1)]
    table = [
        ("  ".join(cell.ljust(width) for cell, width in zip(row, widths)) + "  " + row[-1]).rstrip()
        for row in (header, *lines)
    ]
    details = [f"\n{r.name}: {r.notes}" for r in results if "\n" in r.notes]
    return "\n".join(table + details)


def exit_status(results: Iterable[CheckResult]) -> int:
    """1 if any check failed or none could run (every row unsupported), else 0: an
    unsupported check alone is not a failure."""
    outcomes = [r.passed for r in results]
    return int(False in outcomes or all(o is None for o in outcomes))


def summary(results: Sequence[CheckResult], engine: str) -> str:
    """One line on the rows: how many passed, failed and were unsupported, or that none ran."""
    counts = {status: sum(r.status == status for r in results) for status in ("pass", "FAIL", "unsupported")}
    if counts["unsupported"] == len(results):
        return (
            f"no check could run on the {engine} engine: all {len(results)} rows need a feature it lacks "
            "(see the notes), so nothing was validated"
        )
    return (
        f"{counts['pass']} passed, {counts['FAIL']} failed, {counts['unsupported']} unsupported "
        f"on the {engine} engine"
    )
