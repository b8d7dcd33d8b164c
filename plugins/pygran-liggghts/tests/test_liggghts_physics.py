"""Impacts on real LIGGGHTS against the reference contact models (within 2%)."""

import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.simulation.models import HertzMindlin, SpringDashpot
from pygran_core.testing.solvers import require_solver

MATERIAL = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.45,
    "coefficientRestitution": 0.3,
    "coefficientFriction": 0.5,
    "characteristicVelocity": 0.5,
    "density": 2500.0,
}
R, V = 1e-3, 0.5
GAP = 1e-5  # free flight before the contact


def _run(tmp_path, model, steps, dt, place):
    """One LIGGGHTS run without gravity; ``place(sim)`` creates the bodies."""
    require_solver(find_library)
    with simulation.DEM(
        engine="liggghts",
        model=model,
        box=(0, 0.02, 0, 0.02, 0, 0.02),
        dt=dt,
        output=str(tmp_path / model.__name__),
        species=({"material": MATERIAL, "radius": R},),
        traj={"pfile": None},
        progress=False,
    ) as sim:
        place(sim)
        sim.run(steps)
        return sim.extractCoords(), sim.extractVelocities(), sim.extractIds()


@pytest.mark.parametrize("model", [SpringDashpot, HertzMindlin])
def test_sphere_wall_impact(tmp_path, model):
    impact = model(material=dict(MATERIAL, radius=R)).displacement(V)
    dt = impact.contact_time / 400
    steps = int(round(3 * impact.contact_time / dt))

    def place(sim):
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.01, 0.01, R + GAP, vel=(0, 0, -V))

    x, v, _ = _run(tmp_path, model, steps, dt, place)
    v_out = v[0, 2]
    contact = steps * dt - GAP / V - (x[0, 2] - R) / v_out
    assert v_out / V == pytest.approx(impact.restitution, rel=0.02)
    assert contact == pytest.approx(impact.contact_time, rel=0.02)


@pytest.mark.parametrize("model", [SpringDashpot, HertzMindlin])
def test_two_sphere_collision(tmp_path, model):
    sphere = dict(MATERIAL, radius=R)
    impact = model(material=sphere, partner=sphere).displacement(V)
    dt = impact.contact_time / 400
    steps = int(round(3 * impact.contact_time / dt))

    def place(sim):
        sim.createParticles(1, "single", 0.01 - R - GAP / 2, 0.01, 0.01, vel=(V / 2, 0, 0))
        sim.createParticles(1, "single", 0.01 + R + GAP / 2, 0.01, 0.01, vel=(-V / 2, 0, 0))

    x, v, ids = _run(tmp_path, model, steps, dt, place)
    assert list(ids) == [1, 2]
    v_out = v[1, 0] - v[0, 0]
    gap_out = x[1, 0] - x[0, 0] - 2 * R
    contact = steps * dt - GAP / V - gap_out / v_out
    assert v_out / V == pytest.approx(impact.restitution, rel=0.02)
    assert contact == pytest.approx(impact.contact_time, rel=0.02)
