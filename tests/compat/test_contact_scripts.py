"""PyGran 1.x contact-model scripts (manual chapter 3, Listings 3.2-3.4) run unchanged.

The listings' own import, ``import PyGran.simulation as sim``, is used (the ``PyGran`` alias of
``pygran_core``).
Expected values come from closed forms: the damped linear oscillator, Hertz, JKR and
Thornton's (1997) restitution with his published 1.56 constant.
"""

from __future__ import annotations

import math

import numpy as np
import PyGran.simulation as sim
import pytest
from numpy import arange, fabs

from pygran_core.errors import ConfigError

powderX = {
    "youngsModulus": 1e8,
    "poissonsRatio": 0.25,
    "coefficientRestitution": 0.9,
    "characteristicVelocity": 0.1,
    "density": 997.164,
    "radius": 1e-4,
}
MASS = 4 / 3 * math.pi * 1e-4**3 * 997.164
E_STAR = 1e8 / (2 * (1 - 0.25**2))  # the original's Y*: a sphere on a wall of its own material


def test_listing_3_2_force_displacement_of_the_viscoelastic_models():
    models = [sim.models.SpringDashpot, sim.models.HertzMindlin]
    curves = {}
    for model in models:
        model = model(material=powderX)
        time, soln, force = model.displacement()
        deltan = soln[:, 0]
        curves[type(model).__name__] = (time, deltan, soln[:, 1], force)
        assert len(time) == len(deltan) == len(force) and deltan[0] == 0 and soln[0, 1] == 0.1

    # spring-dashpot: the damped oscillator delta = v/w exp(-a t) sin(w t)
    kn = 16 / 15 * math.sqrt(1e-4) * E_STAR * (15 * MASS * 0.1**2 / (16 * math.sqrt(1e-4) * E_STAR)) ** 0.2
    gamma = math.sqrt(4 * MASS * kn / (1 + (math.pi / math.log(0.9)) ** 2))
    a, w = gamma / (2 * MASS), math.sqrt(kn / MASS - (gamma / (2 * MASS)) ** 2)
    t_max = math.atan2(w, a) / w
    time, deltan, rate, force = curves["SpringDashpot"]
    assert deltan.max() == pytest.approx(0.1 / w * math.exp(-a * t_max) * math.sin(w * t_max), rel=1e-7)
    assert time[-1] == pytest.approx(math.pi / w, rel=1e-7)
    assert fabs(rate[-1] / rate[0]) == pytest.approx(0.9, rel=1e-6)
    inside = slice(1, -1)  # in contact: overlap > 0
    np.testing.assert_allclose(force[inside], (kn * deltan + gamma * rate)[inside], rtol=1e-12, atol=1e-15)

    # Hertz-Mindlin: restitution 0.9 at any speed; less deep and longer than the undamped impact
    time, deltan, rate, force = curves["HertzMindlin"]
    hertz_depth = (15 * MASS * 0.1**2 / (16 * E_STAR * math.sqrt(1e-4))) ** 0.4
    hertz_time = 2.868 * (MASS**2 / (1e-4 * E_STAR**2 * 0.1)) ** 0.2
    assert fabs(rate[-1] / rate[0]) == pytest.approx(0.9, rel=1e-3)
    assert 0.9 * hertz_depth < deltan.max() < hertz_depth
    assert hertz_time < time[-1] < 1.1 * hertz_time


def test_the_original_limit_force_and_the_closed_form_spring_dashpot():
    for model in (sim.models.SpringDashpot, sim.models.HertzMindlin):
        time, soln, force = model(material=powderX, limitForce=True).displacement()
        assert force.min() >= 0  # never attractive at the end of the contact
        assert 0.9 < fabs(soln[-1, 1] / soln[0, 1]) < 1
    model = sim.models.SpringDashpot(material=powderX)
    time, soln, force = model.displacementAnalytical()
    numeric = model.displacement()
    assert len(time) == 101 and time[1] == pytest.approx(0.01 * model.contactTime(), rel=1e-12)
    assert fabs(soln[-1, 1] / soln[0, 1]) == pytest.approx(0.9, rel=1e-12)
    assert time[-1] == pytest.approx(numeric.time[-1], rel=1e-7)
    np.testing.assert_allclose(
        np.interp(time, numeric.time, numeric.soln[:, 0]), soln[:, 0], atol=1e-5 * 3e-7
    )


def thornton(v, v_y):
    """Thornton (1997): restitution of an elastic-perfectly plastic sphere; 1 below yield."""
    if v <= v_y:
        return 1.0
    r = v_y / v
    return (
        math.sqrt(6 * math.sqrt(3) / 5 * (1 - r**2 / 6)) * (r / (r + 2 * math.sqrt(6 / 5 - r**2 / 5))) ** 0.25
    )


def test_listing_3_3_restitution_against_the_yield_pressure():
    cModel = sim.ThorntonNing  # as Listing 3.4 writes it
    COR, analytic = [], []
    pressure = arange(1, 6, 0.1) * 0.01 * powderX["youngsModulus"]
    for yieldPress in pressure:
        powderX["yieldPress"] = yieldPress
        model = cModel(material=powderX)

        time, disp, force = model.displacement()
        deltav = disp[:, 1]

        COR.append(fabs(deltav[-1] / deltav[0]))
        v_y = 1.56 * math.sqrt(yieldPress**5 / (E_STAR**4 * powderX["density"]))  # Thornton's V_y
        assert model.yieldVel == pytest.approx(v_y, rel=4e-4)
        analytic.append(thornton(powderX["characteristicVelocity"], v_y))
    del powderX["yieldPress"]
    COR, analytic = np.array(COR), np.array(analytic)
    assert len(COR) == 50 and np.all(np.diff(COR) >= -1e-12)
    np.testing.assert_allclose(COR, analytic, rtol=0.02)
    assert np.abs(COR / analytic - 1).max() < 2e-4  # measured 7.6e-5: only 1.56 vs pi^2/sqrt(40) differs
    assert 0.74 < COR[0] < 0.76 and COR[-1] == pytest.approx(1, abs=1e-6)  # plastic at 1 MPa, elastic at 5.9


def test_listing_3_4_cohesive_elastic_plastic_impact():
    powder = {
        "radius": 2e-5,
        "yieldPress": 4e7,
        "density": 1500.0,
        "youngsModulus": 6e9,
        "cohesionEnergyDensity": 0.04,
        "poissonsRatio": 0.25,
        "characteristicVelocity": 0.04,
    }
    model = sim.models.ThorntonNing(material=powder)
    time, delta, force = model.displacement()
    pull_off = 3 * math.pi * 0.04 * 2e-5  # JKR: 3 pi Gamma R*
    # snap-in at zero overlap: JKR contact radius a0 (a0^3 = 4 pi Gamma R^2 / E*), already above the
    # yield radius a_y, so the Thornton-Ning plastic load minus the JKR adhesion
    E, R, G, p_y = 6e9 / (2 * (1 - 0.25**2)), 2e-5, 0.04, 4e7
    a0, a_y = (4 * math.pi * G * R**2 / E) ** (1 / 3), math.pi * p_y * R / (2 * E)
    snap = (
        4 * E * a_y**3 / (3 * R) + math.pi * p_y * (a0**2 - a_y**2) - 4 * math.sqrt(math.pi * G * E * a0**3)
    )
    assert a0 > a_y and snap == pytest.approx(-8 / 9 * pull_off, rel=1e-3)
    assert model.normal_force(1e-20, 0.0) == pytest.approx(snap, rel=1e-9)
    assert force[1] == pytest.approx(snap, rel=1e-2)  # the first sample, 5e-11 m deep
    assert force.max() > 0 and -force.min() > pull_off  # plastic flattening raises the pull-off
    assert np.all(np.diff(time) > 0) and delta[0, 1] == 0.04
    assert model.displacement(0.4).restitution > 0  # a fast particle rebounds


def test_mistakes_in_listing_calls_are_named():
    with pytest.raises(ConfigError, match="Did you mean 'youngsModulus'"):
        sim.models.HertzMindlin(material=dict(powderX, youngModulus=1e8))
    with pytest.raises(ConfigError, match="needs the material key"):
        sim.models.ThorntonNing(material=powderX)  # no yieldPress
    with pytest.raises(TypeError):
        sim.models.SpringDashpot(materials=powderX)
    with pytest.raises(ConfigError, match="Did you mean 'epsd2'"):
        sim.models.HertzMindlin(material=powderX, rolling="espd2")
    assert sim.models.HertzMindlin(material=powderX, rolling="epsd2").rolling == "epsd2"
    assert sim.models.HertzMindlin.rolling == "cdt"
