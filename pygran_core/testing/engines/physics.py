"""The engine suite's physics: pair tables, impacts of every contact model against the
reference models, a settle of every stock material, cohesion and rolling friction."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from pygran_core import params
from pygran_core.errors import LostParticlesWarning, TimeStepWarning, UnsupportedFeature
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.models import ContactModel, HertzMindlin
from pygran_core.testing.engines.base import (
    GRAVITY,
    MATERIAL,
    MODELS,
    RADIUS,
    EngineSuite,
    G,
    Lazy,
    Outcome,
    attempt,
    create,
    safe_dt,
)
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

#: The pair values of the pair-table checks (Dosta et al. 2024's M1-M2 pair).
PAIR: Mapping[str, float] = {"coefficientRestitution": 0.45, "coefficientFriction": 0.2}
#: The settle runs until the slowest vibration about rest has fallen to this fraction.
SETTLE_DECAY = 1e-2


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


class PhysicsChecks(EngineSuite):
    """Contact models and materials against the reference models and closed forms."""

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
        return Lazy(lambda name: attempt(lambda: cls().settle(tmp_path_factory.mktemp(name), name)))

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
