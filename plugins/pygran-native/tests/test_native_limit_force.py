"""``configure(limitForce=True)`` on the native engine: the visco-elastic normal force is kept
from turning attractive at the end of an impact, as LIGGGHTS' ``limitForce on`` does."""

from __future__ import annotations

import pytest

from pygran_core import params, simulation
from pygran_core.simulation.models import HertzMindlin, SpringDashpot

R, V0 = 1e-3, 0.1


@pytest.mark.parametrize("base", [HertzMindlin, SpringDashpot])
@pytest.mark.parametrize("limit", [False, True])
def test_an_impact_rebounds_as_the_models_reference_says(tmp_path, base, limit):
    """A sphere thrown at a wall at 0.1 m/s, restitution coefficient 0.3: the dashpot pulls the
    sphere back at the end of the contact unless the force is limited; then it leaves faster
    (measured: 0.397 of its speed for both laws, against 0.300 without the limit)."""
    model = base.configure(limitForce=limit)
    material = dict(params.organic, coefficientRestitution=0.3)
    reference = model(material=dict(material, radius=R))  # a sphere on a wall of its material
    duration = reference.contactTime(V0)
    with simulation.DEM(
        engine="native",
        model=model,
        box=(-0.005, 0.005, -0.005, 0.005, 0, 0.01),
        species=({"material": material, "radius": R},),
        dt=duration / 500,
        output=str(tmp_path),
        traj={"pfile": None},
        progress=False,
        threads=1,
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, R + 0.2 * V0 * duration, vel=(0, 0, -V0))
        sim.run(3000)  # the approach, the contact (500 steps) and the flight back
        rebound = sim.extractVelocities()[0, 2] / V0
    expected = reference.restitution(V0)
    assert rebound == pytest.approx(expected, rel=0.01)
    assert (expected > 1.2 * 0.3) == limit  # the limit changes the rebound by over 20 %
