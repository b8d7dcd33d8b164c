"""Every stock material runs on LIGGGHTS (hard_particles/soft_particles as its moduli need), and
impacts of stiff materials agree with closed forms.

- Settle: for each material of ``params.MATERIALS``, a sphere resting on the floor and a
  stack of two come to rest at the overlaps where the reference model's normal force
  (Hertz plus SJKR cohesion) carries their weight, within 1 % (plus delta / R between the
  spheres, the order of the reference's SJKR area there).
- Hertz: a glass sphere-sphere impact (after Chung & Ooi 2011, test 1) and an aluminium
  sphere on a rigid wall at 0.2 m/s (their test 2): maximum overlap within 1 % and contact
  time within 2 % of Hertz's closed forms.
- Oblique impacts of glass on a wall in the sliding regime (their test 6, at incidences 1.5
  and 4 times beyond the onset of sliding throughout): a contact that
  slides throughout takes a tangential impulse mu (1 + e) m v_n, so the tangential
  restitution is ``1 - mu (1 + e) v_n / v_t`` and the spin ``5 mu (1 + e) v_n / (2 R)``;
  both within 2 %.

Time steps are a fraction of the Hertz contact time: 1/50 at the material's characteristic
velocity for the settle, 1/400 at the impact speed for the impacts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import params
from pygran_core.simulation.models import HertzMindlin
from pygran_core.simulation.timestep import rayleigh_time
from pygran_core.testing.engines import rest_overlap, slowest_decay
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import (
    GRAVITY,
    contact_modulus,
    hertz_contact_time,
    hertz_max_overlap,
    one_species,
    sphere_mass,
)

RADIUS = 1e-3
#: Aluminium alloy of Chung & Ooi (2011), test 2.
ALUMINIUM = {
    "youngsModulus": 7.0e10,
    "poissonsRatio": 0.33,
    "coefficientRestitution": 1.0,
    "coefficientFriction": 0.0,
    "density": 2700.0,
}
#: A wall this many times stiffer than the sphere is rigid to 1e-9.
RIGID = 1e9


@pytest.mark.parametrize("name", sorted(params.MATERIALS))
def test_every_material_settles_at_its_hertz_overlap(tmp_path, name):
    """A lone sphere and a stack of two start touching the floor and each other at rest."""
    require_solver(find_library)
    material = params.MATERIALS[name]
    sphere = dict(material, radius=RADIUS)
    on_wall, on_sphere = HertzMindlin(material=sphere), HertzMindlin(material=sphere, partner=sphere)
    weight = sphere_mass(material, RADIUS) * GRAVITY[0]
    contact = hertz_contact_time(
        sphere_mass(material, RADIUS), RADIUS, contact_modulus(material), material["characteristicVelocity"]
    )
    rayleigh = rayleigh_time(
        RADIUS, material["density"], material["youngsModulus"], material["poissonsRatio"]
    )
    dt = min(contact / 50, rayleigh / 10)
    lone, bottom = rest_overlap(on_wall, weight), rest_overlap(on_wall, 2 * weight)
    top = rest_overlap(on_sphere, weight)
    decay = slowest_decay(sphere_mass(material, RADIUS), (on_wall, bottom), (on_sphere, top))
    steps = int(math.ceil(math.log(1e4) / decay / dt))  # the vibration falls to 1e-4 of its start
    box = (-4 * RADIUS, 4 * RADIUS, -2 * RADIUS, 2 * RADIUS, -RADIUS, 6 * RADIUS)
    with one_species(
        "liggghts", tmp_path, material, RADIUS, model=HertzMindlin, box=box, dt=dt, gravity=GRAVITY
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", np.array([[-2 * RADIUS, 0, RADIUS], [2 * RADIUS, 0, RADIUS]]))
        sim.createParticles(1, "single", 2 * RADIUS, 0.0, 3 * RADIUS)
        sim.run(steps)
        z, v = sim.extractCoords()[:, 2], sim.extractVelocities()
    text = (tmp_path / "in.pygran").read_text()
    assert ("hard_particles yes" in text) == (material["youngsModulus"] > 1e9)
    assert ("soft_particles yes" in text) == (material["youngsModulus"] < 5e6)
    assert RADIUS - z[0] == pytest.approx(lone, rel=0.01)
    assert RADIUS - z[1] == pytest.approx(bottom, rel=0.01)
    # the reference's SJKR area between spheres is LIGGGHTS' lens area to first order in
    # delta / R only: with cohesion that dominates (``cohesive``) allow that much more
    assert 2 * RADIUS - (z[2] - z[1]) == pytest.approx(top, rel=0.01 + top / RADIUS)
    assert np.abs(v).max() < 1e-2 * math.sqrt(GRAVITY[0] * lone)


@dataclass(frozen=True)
class Rebound:
    """What an impact left: contact time, largest overlap, velocity and spin after it."""

    contact_time: float
    max_overlap: float
    velocity: np.ndarray
    omega: np.ndarray


def impact(
    tmp_path, material: Mapping[str, float], radius: float, velocity: tuple[float, float, float], target: str
) -> Rebound:
    """A sphere at ``velocity`` hitting ``target`` head-on or obliquely, without gravity:
    ``"sphere"`` (an equal one coming the other way at the same normal speed), ``"wall"`` (a
    plane wall of the same material) or ``"rigid wall"`` (one :data:`RIGID` times stiffer).

    400 steps per Hertz contact time; the overlap is sampled every 6 steps over 1.2 contact
    times for its maximum; the contact ends when the free flight after it extrapolates back
    to touching (as in :func:`pygran_core.testing.validation.wall_impact`).
    """
    speed = abs(velocity[2])
    mass, modulus = sphere_mass(material, radius), contact_modulus(material)
    if target == "sphere":  # each at speed: relative speed 2 speed, m* = m/2, R* = R/2
        reference = hertz_contact_time(mass / 2, radius / 2, modulus, 2 * speed)
    else:
        modulus *= 2 if target == "rigid wall" else 1
        reference = hertz_contact_time(mass, radius, modulus, speed)
    dt = reference / 400
    species = [{"material": dict(material), "radius": radius}]
    if target == "rigid wall":
        species.append(
            {"material": dict(material, youngsModulus=RIGID * material["youngsModulus"]), "radius": radius}
        )
    box = (-20 * radius, 20 * radius, -4 * radius, 4 * radius, -4 * radius, 4 * radius)
    gap = 0.5 * speed * dt  # touching half a step after the start
    overlaps = []
    with one_species(
        "liggghts", tmp_path, material, radius, model=HertzMindlin, box=box, dt=dt, species=tuple(species)
    ) as sim:
        if target == "sphere":
            sim.createParticles(1, "single", 0.0, 0.0, -radius - gap, vel=(0.0, 0.0, speed))
            sim.createParticles(1, "single", 0.0, 0.0, radius + gap, vel=tuple(velocity))
        else:
            sim.setupWall(species=len(species), plane="zplane", peq=0.0)
            sim.createParticles(1, "single", 0.0, 0.0, radius + gap, vel=tuple(velocity))
        samples, every = 80, 6
        for _ in range(samples):
            sim.run(every)
            z = sim.extractCoords()[:, 2]
            overlaps.append(radius - z[-1] if target != "sphere" else 2 * radius - (z[1] - z[0]))
        sim.run(4 * 400 - samples * every)
        z, v, w, end = sim.extractCoords()[:, 2], sim.extractVelocities(), sim.extractOmegas(), sim.time
    if target == "sphere":
        separation, rate = z[1] - z[0] - 2 * radius, v[1, 2] - v[0, 2]
        contact = end - separation / rate - 2 * gap / (2 * speed)
    else:
        separation, rate = z[0] - radius, v[0, 2]
        contact = end - separation / rate - gap / speed
    return Rebound(contact, max(overlaps), v[-1], w[-1])


def test_glass_spheres_collide_as_hertz(tmp_path):
    require_solver(find_library)
    glass = dict(params.glass, coefficientRestitution=1.0)  # Hertz's closed forms are elastic
    radius, speed = 0.01, 5.0  # each sphere: 10 m/s relative
    rebound = impact(tmp_path, glass, radius, (0.0, 0.0, -speed), "sphere")
    m, E = sphere_mass(glass, radius), contact_modulus(glass)
    assert rebound.max_overlap == pytest.approx(hertz_max_overlap(m / 2, radius / 2, E, 2 * speed), rel=0.01)
    assert rebound.contact_time == pytest.approx(
        hertz_contact_time(m / 2, radius / 2, E, 2 * speed), rel=0.02
    )
    assert rebound.velocity[2] == pytest.approx(speed, rel=0.01)


def test_aluminium_sphere_on_a_rigid_wall(tmp_path):
    require_solver(find_library)
    radius, speed = 0.1, 0.2
    rebound = impact(tmp_path, ALUMINIUM, radius, (0.0, 0.0, -speed), "rigid wall")
    m = sphere_mass(ALUMINIUM, radius)
    E = ALUMINIUM["youngsModulus"] / (1 - ALUMINIUM["poissonsRatio"] ** 2)  # the wall does not deform
    assert rebound.max_overlap == pytest.approx(hertz_max_overlap(m, radius, E, speed), rel=0.01)
    assert rebound.contact_time == pytest.approx(hertz_contact_time(m, radius, E, speed), rel=0.02)


@pytest.mark.parametrize("beyond", [1.5, 4.0])
def test_oblique_glass_impact_in_the_sliding_regime(tmp_path, beyond):
    """Incidence angles (from the normal) with tan(theta) ``beyond`` times the rigid-body limit
    3.5 mu (1 + e) of sliding throughout."""
    require_solver(find_library)
    glass = dict(params.glass, coefficientRollingFriction=0.0)  # Chung & Ooi have no rolling torque
    mu, e = glass["coefficientFriction"], glass["coefficientRestitution"]
    angle = math.atan(beyond * 3.5 * mu * (1 + e))
    radius, speed = RADIUS, 1.0
    vt, vn = speed * math.sin(angle), speed * math.cos(angle)
    rebound = impact(tmp_path, glass, radius, (vt, 0.0, -vn), "wall")
    assert rebound.velocity[2] / vn == pytest.approx(e, rel=0.01)
    assert rebound.velocity[0] / vt == pytest.approx(1 - mu * (1 + e) * vn / vt, rel=0.02)
    assert rebound.omega[1] * radius == pytest.approx(2.5 * mu * (1 + e) * vn, rel=0.02)
