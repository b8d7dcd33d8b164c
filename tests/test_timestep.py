"""The time-step check before every run: Rayleigh and contact times, warning, error, override."""

import math
import warnings

import pytest
from scipy.optimize import brentq

from pygran_core import params
from pygran_core.errors import ConfigError, TimeStepWarning
from pygran_core.simulation import timestep
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.models import HertzMindlin, SpringDashpot
from pygran_core.simulation.timestep import Body, contact_time, rayleigh_time

R = 1e-3


def _material():
    return dict(params.organic)


def _sim(tmp_path, material=None, model=HertzMindlin, **extra):
    material = _material() if material is None else material
    settings = {
        "engine": "native",
        "model": model,
        "box": (0, 0.02, 0, 0.02, 0, 0.02),
        "species": ({"material": material, "radius": R}, {"material": material, "radius": R / 2}),
        "output": str(tmp_path / "out"),
        "traj": {"pfile": None},
        "progress": False,
        "dt": 1e-7,
    }
    return DEM(**settings | extra)


def _hertz_time(material, m1, r1, m2=math.inf, r2=math.inf, speed=None):
    """2.868 (m*^2 / (R* E*^2 v))^(1/5) for two bodies of ``material`` (a wall: infinite m, r)."""
    mass = 1 / (1 / m1 + 1 / m2)
    radius = 1 / (1 / r1 + 1 / r2)
    modulus = material["youngsModulus"] / (2 * (1 - material["poissonsRatio"] ** 2))
    speed = material["characteristicVelocity"] if speed is None else speed
    return 2.868 * (mass**2 / (radius * modulus**2 * speed)) ** 0.2


def _mass(material, radius):
    return 4 / 3 * math.pi * radius**3 * material["density"]


@pytest.mark.parametrize("nu", [0.0, 0.2, 0.3, 0.45])
def test_rayleigh_time_matches_the_rayleigh_wave_speed(nu):
    # exact Rayleigh wave speed c_R = eta c_S from Rayleigh's equation in eta^2; the formula
    # of LIGGGHTS (and EDEM) approximates eta by 0.1631 nu + 0.8766
    xi2 = (1 - 2 * nu) / (2 * (1 - nu))
    eta = brentq(lambda h: h**3 - 8 * h**2 + 8 * (3 - 2 * xi2) * h - 16 * (1 - xi2), 1e-9, 1 - 1e-12) ** 0.5
    youngs, density, radius = 7e10, 2700.0, 2e-3
    shear_speed = math.sqrt(youngs / (2 * (1 + nu)) / density)
    exact = math.pi * radius / (eta * shear_speed)
    assert rayleigh_time(radius, density, youngs, nu) == pytest.approx(exact, rel=5e-3)


def test_contact_times_are_the_models_hertz_times():
    material = _material()
    particle = Body("species 1", material, R, material["density"])
    small = Body("species 2", material, R / 2, material["density"])
    wall = Body("wall", material)
    m1, m2 = _mass(material, R), _mass(material, R / 2)
    v = material["characteristicVelocity"]
    assert contact_time(HertzMindlin, particle, wall, v) == pytest.approx(_hertz_time(material, m1, R))
    assert contact_time(HertzMindlin, particle, small, v) == pytest.approx(
        _hertz_time(material, m1, R, m2, R / 2)
    )
    # SpringDashpot: the damped linear spring whose stiffness makes the Hertz overlap at v
    spring = contact_time(SpringDashpot, particle, wall, v)
    model = SpringDashpot(material=dict(material, radius=R))
    assert spring == pytest.approx(math.pi / math.sqrt(model.kn / m1 - (model.gamman / (2 * m1)) ** 2))


def test_the_shortest_contact_of_the_particles_present_limits_dt(tmp_path):
    material = _material()
    with _sim(tmp_path) as sim:
        sim.createParticles(1, "single", 0.005, 0.005, 0.005)
        sim.run(1)  # one particle, no wall: no contact can happen
        assert sim.engine.time_step_check is None
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.run(1)
        limits = sim.engine.time_step_check.limits
        assert limits.contact_of == "species 1 on walls of species 1's material"
        assert limits.contact == pytest.approx(_hertz_time(material, _mass(material, R), R))
        assert limits.rayleigh == pytest.approx(
            rayleigh_time(R, material["density"], material["youngsModulus"], material["poissonsRatio"])
        )
        sim.createParticles(2, "single", 0.015, 0.015, 0.015)
        sim.run(1)
        limits = sim.engine.time_step_check.limits
        small = _mass(material, R / 2)
        assert limits.contact_of == "species 2 on walls of species 1's material"
        assert limits.contact == pytest.approx(_hertz_time(material, small, R / 2))
        assert limits.rayleigh_of == "species 2, radius 0.0005 m"
        sim.createParticles(2, "single", 0.012, 0.015, 0.015, radius=R / 4)  # radius given: smaller
        sim.run(1)
        limits = sim.engine.time_step_check.limits
        tiny = _mass(material, R / 4)
        assert limits.contact_of == "species 2 on species 2"
        assert limits.contact == pytest.approx(_hertz_time(material, tiny, R / 4, tiny, R / 4))


def test_species_being_inserted_count_before_they_appear(tmp_path):
    material = _material()
    with _sim(tmp_path) as sim:
        sim.insert(2, value=100, insert="by_rate", freq=1000)  # none inserted before step 1000
        sim.run(1)
        limits = sim.engine.time_step_check.limits
        small = _mass(material, R / 2)
        assert limits.contact_of == "species 2 on species 2"
        assert limits.contact == pytest.approx(_hertz_time(material, small, R / 2, small, R / 2))


def test_warning_names_both_times_and_a_safe_step_once(tmp_path):
    with _sim(tmp_path) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.005, 0.005, 0.005)
        sim.run(1)
        limits = sim.engine.time_step_check.limits
        dt = 0.15 * limits.contact  # within 3 steps per contact, above 10 %
        with pytest.warns(TimeStepWarning) as caught:
            sim.run(2, dt=dt)
        (warning,) = caught
        text = str(warning.message)
        assert f"dt = {dt:.3g} s is 15 % of the contact time {limits.contact:.3g} s" in text
        assert f"the Rayleigh time {limits.rayleigh:.3g} s" in text
        assert f"use dt <= {limits.safe_dt:.2g} s" in text
        assert warning.filename == __file__  # points at the user's line
        assert text in (sim.output / "pygran.log").read_text()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sim.run(2, dt=dt)  # warned once for this dt
            sim.run(2, dt=limits.safe_dt)  # the safe dt is safe
        assert limits.safe_dt <= min(0.2 * limits.rayleigh, 0.1 * limits.contact) < 1.1 * limits.safe_dt


def test_a_step_longer_than_a_third_of_a_contact_is_refused_unless_overridden(tmp_path):
    with _sim(tmp_path) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.005, 0.005, 0.005)
        sim.run(1)
        contact = sim.engine.time_step_check.limits.contact
        for dt in (8 * contact, 0.34 * contact):
            with pytest.raises(ConfigError, match=r"dt = .* the contact time .* fewer than 3 steps") as info:
                sim.run(10, dt=dt)
            assert "pass check_dt=False to run()" in str(info.value)
        assert sim.step == 1 and sim.engine.dt == 1e-7  # nothing ran, the time step is unchanged
        assert "run refused: dt = " in (sim.output / "pygran.log").read_text()
        with pytest.warns(TimeStepWarning, match="8.0 times the contact time"):
            sim.engine.run(10, dt=8 * contact, check_dt=False)
        assert sim.step == 11


def test_limits_are_computed_once_per_set_of_contacts(tmp_path, monkeypatch):
    calls = []
    original = timestep.limits
    monkeypatch.setattr(
        "pygran_core.simulation.diagnostics.limits", lambda *args: calls.append(args) or original(*args)
    )
    with _sim(tmp_path) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.005, 0.005, 0.005)
        for _ in range(20):
            sim.run(1)
        sim.createParticles(1, "single", 0.015, 0.005, 0.005)  # two particles: a new pair
        for _ in range(20):
            sim.run(1)
    assert len(calls) == 2
