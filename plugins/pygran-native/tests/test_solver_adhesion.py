"""Thornton-Ning (plasticity, JKR adhesion), SJKR cohesion and rolling friction of the native solver."""

import math

import pytest
from pygran_native.solver import Solver

from pygran_core.simulation.models import HertzMindlin, ThorntonNing
from pygran_core.testing.validation import SOFT

R, RHO, E, NU, PY = 1e-3, 1000.0, 4e7, 0.25, 2e5


def tn_solver(gamma, **extra):
    s = Solver(box=[[-0.01] * 3, [0.01] * 3], skin=2e-4, threads=1, **extra)
    s.set_contact_model(
        "thornton-ning", youngs=E, poisson=NU, friction=0.5, yield_pressure=PY, cohesion_energy=gamma
    )
    return s


def material(gamma):
    return dict(
        youngsModulus=E,
        poissonsRatio=NU,
        coefficientFriction=0.5,
        yieldPress=PY,
        cohesionEnergyDensity=gamma,
        density=RHO,
        radius=R,
    )


@pytest.mark.parametrize("gamma,v0", [(0.0, 1.0), (0.05, 1.0)], ids=["plastic", "plastic-adhesive"])
def test_thornton_ning_impact_matches_reference(gamma, v0):
    ref = ThorntonNing(material=material(gamma)).displacement(velocity=v0)
    assert ref.max_overlap > ThorntonNing(material=material(gamma)).yield_overlap  # plastic
    s = tn_solver(gamma)
    s.add_plane((0, 0, 0), (0, 0, 1))
    s.add_particles([[0, 0, R]], R, densities=RHO, velocities=[[0, 0, -v0]])
    dt = ref.time[-1] / 2000
    overlap, force = [], []
    for _ in range(2600):
        s.run(1, dt)
        overlap.append(R - s.positions[0, 2])
        force.append(s.forces[0, 2])
    assert s.velocities[0, 2] / v0 == pytest.approx(ref.restitution, rel=0.01)
    assert max(overlap) == pytest.approx(ref.max_overlap, rel=0.01)
    assert max(force) == pytest.approx(ref.max_force, rel=0.01)
    assert min(force) == pytest.approx(ref.force.min(), rel=0.01, abs=1e-9)


@pytest.mark.parametrize("side", [1, -1], ids=["above", "below"])
def test_slow_adhesive_impact_is_captured(side):
    ref = ThorntonNing(material=material(0.3)).displacement(velocity=0.2)
    assert ref.captured
    s = tn_solver(0.3)
    s.add_plane((0, 0, 0), (0, 0, 1))  # two-sided: the same from below
    s.add_particles([[0, 0, side * R]], R, densities=RHO, velocities=[[0, 0, -side * 0.2]])
    s.run(40000, ref.time[-1] / 2000)
    assert R - side * s.positions[0, 2] > -1e-5 and s.walls()  # still stuck to the wall
    assert side * s.positions[0, 2] < 0  # the centre sank past the plane: held by the contact's side


def test_plane_contact_side_survives_rebuilds_and_checkpoints():
    ref = ThorntonNing(material=material(0.3)).displacement(velocity=0.2)
    dt = ref.time[-1] / 2000
    s = tn_solver(0.3)
    s.add_plane((0, 0, 0), (0, 0, 1))
    s.add_particles([[0, 0, R]], R, densities=RHO, velocities=[[0, 0, -0.2]])
    s.run(20000, dt)
    sunk = s.positions[0, 2]
    assert -0.2 * R < sunk < 0  # centre past the plane
    s.add_particles([[-0.009, 0.005, 0.005]], R, densities=RHO, velocities=[[20.0, 0, 0]])  # forces rebuilds
    s.run(1000, dt)
    restored = tn_solver(0.3)
    restored.set_state(s.get_state())
    for solver in (s, restored):
        solver.run(1000, dt)
        assert solver.rebuilds > 5
        assert solver.positions[0, 2] == pytest.approx(sunk, abs=0.05 * R)  # not pushed to the other side
    assert restored.positions[0, 2] == s.positions[0, 2]


@pytest.mark.parametrize("gamma", [0.0, 0.05])
def test_thornton_ning_loading_force_matches_reference(gamma):
    partner = dict(radius=0.6 * R, density=RHO)
    ref = ThorntonNing(material=material(gamma), partner=partner)
    for overlap in (1e-6, 1e-5, 6e-5):
        s = tn_solver(gamma)
        s.add_particles([[0, 0, 0], [1.6 * R - overlap, 0, 0]], [R, 0.6 * R], densities=RHO)
        s.run(0, 1e-6)
        assert -s.forces[0, 0] == pytest.approx(float(ref.normal_force(overlap, 0.0)), rel=1e-9)


def test_sjkr_cohesion_holds_a_particle_against_gravity():
    # k pi delta (2R - delta) must exceed m g + the elastic force: hang a particle under a ceiling
    s = Solver(box=[[-0.01] * 3, [0.01] * 3], gravity=(0, 0, -9.81), skin=2e-4, threads=1)
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5, cohesion_energy=3e5)
    s.add_plane((0, 0, 0), (0, 0, -1))
    s.add_particles([[0, 0, -R + 1e-6]], R, densities=2500.0)
    s.run(30000, 1e-6)
    model = HertzMindlin(material=dict(SOFT, cohesionEnergyDensity=3e5, radius=R))
    mg = 4 / 3 * math.pi * R**3 * 2500.0 * 9.81
    overlap = R + s.positions[0, 2]
    assert overlap > 0 and abs(s.velocities[0, 2]) < 1e-4
    assert float(model.normal_force(overlap, 0.0)) == pytest.approx(-mg, rel=1e-3)  # static balance


def test_rolling_friction_decelerates_at_five_sevenths_mu_r_g():
    mu_r, g = 0.02, 9.81
    s = Solver(box=[[-0.05] * 3, [0.05] * 3], gravity=(0, 0, -g), skin=2e-4, threads=1)
    s.set_contact_model(
        "hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5, rolling_friction=mu_r
    )
    s.add_plane((0, 0, 0), (0, 0, 1))
    m = 4 / 3 * math.pi * R**3 * 2500.0
    rest = R - (3 * m * g / (4 * 5e6 / (1 - 0.45**2) * math.sqrt(R))) ** (2 / 3)
    s.add_particles(
        [[-0.04, 0, rest]], R, densities=2500.0, velocities=[[0.1, 0, 0]], omegas=[[0, 0.1 / R, 0]]
    )
    s.run(5000, 2e-6)
    v1, t1 = s.velocities[0, 0], s.time
    s.run(20000, 2e-6)
    v2, t2 = s.velocities[0, 0], s.time
    assert (v1 - v2) / (t2 - t1) == pytest.approx(5 / 7 * mu_r * g, rel=0.01)
