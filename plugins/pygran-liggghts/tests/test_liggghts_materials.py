"""Stock materials on LIGGGHTS beyond the conformance suite (which settles every one and
checks impacts against the reference models and Hertz's closed forms):

- each material's moduli send ``hard_particles yes`` / ``soft_particles yes`` as LIGGGHTS
  needs them (its guard refuses moduli above 1 GPa or below 5 MPa otherwise);
- an aluminium sphere on a wall of a second species 1e9 times stiffer (Chung & Ooi 2011,
  test 2): the wall takes that species' material, so the contact is Hertz's against a
  rigid wall: maximum overlap within 1 %, contact time within 2 % of the closed forms;
- oblique impacts of glass on a wall in the sliding regime (their test 6, at incidences 1.5
  and 4 times beyond the onset of sliding throughout): a contact that slides throughout
  takes a tangential impulse mu (1 + e) m v_n, so the tangential restitution is
  ``1 - mu (1 + e) v_n / v_t`` and the spin ``5 mu (1 + e) v_n / (2 R)``; both within 2 %.

Impacts run 400 steps per Hertz contact time at the impact speed.
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
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import (
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
def test_moduli_outside_liggghts_guard_are_allowed(tmp_path, name):
    require_solver(find_library)
    material = params.MATERIALS[name]
    box = (-2 * RADIUS, 2 * RADIUS) * 3
    with one_species("liggghts", tmp_path, material, RADIUS, model=HertzMindlin, box=box, dt=1e-9) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.0)
        sim.run(1)
    text = (tmp_path / "in.pygran").read_text()
    assert ("hard_particles yes" in text) == (material["youngsModulus"] > 1e9)
    assert ("soft_particles yes" in text) == (material["youngsModulus"] < 5e6)


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
    ``"wall"`` (a plane wall of the same material) or ``"rigid wall"`` (one of a second
    species :data:`RIGID` times stiffer).

    400 steps per Hertz contact time; the overlap is sampled every 6 steps over 1.2 contact
    times for its maximum; the contact ends when the free flight after it extrapolates back
    to touching (as in :func:`pygran_core.testing.validation.wall_impact`).
    """
    speed = abs(velocity[2])
    modulus = contact_modulus(material) * (2 if target == "rigid wall" else 1)
    dt = hertz_contact_time(sphere_mass(material, radius), radius, modulus, speed) / 400
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
        sim.setupWall(species=len(species), plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, radius + gap, vel=tuple(velocity))
        samples, every = 80, 6
        for _ in range(samples):
            sim.run(every)
            overlaps.append(radius - sim.extractCoords()[0, 2])
        sim.run(4 * 400 - samples * every)
        z, v, w, end = sim.extractCoords()[0, 2], sim.extractVelocities()[0], sim.extractOmegas()[0], sim.time
    contact = end - (z - radius) / v[2] - gap / speed
    return Rebound(contact, max(overlaps), v, w)


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
