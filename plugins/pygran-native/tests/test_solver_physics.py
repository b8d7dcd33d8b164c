"""The native solver against analytic results and the reference contact models."""

import math

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core.simulation.models import HertzMindlin, SpringDashpot
from pygran_core.testing.validation import SOFT

R = 1e-3
RHO, E, NU = SOFT["density"], SOFT["youngsModulus"], SOFT["poissonsRatio"]
MASS = 4 / 3 * math.pi * R**3 * RHO


def material(**extra):
    """The suite's soft material for spheres of radius R."""
    return dict(SOFT, radius=R, **extra)


def solver(
    kind="hertz",
    gravity=(0, 0, 0),
    periodic=(False, False, False),
    box=((-0.01,) * 3, (0.01,) * 3),
    threads=1,
    **model,
):
    s = Solver(box=np.array(box), periodic=periodic, gravity=gravity, skin=2e-4, threads=threads)
    coefficients = dict(youngs=E, poisson=NU, restitution=SOFT["coefficientRestitution"])
    coefficients |= dict(friction=SOFT["coefficientFriction"]) | model
    s.set_contact_model(kind, **coefficients)
    return s


def impact(s, v0, dt, steps):
    """Step a particle moving in -z onto a plane at z=0; contact time and restitution."""
    z, vz = [], []
    for _ in range(steps):
        s.run(1, dt)
        z.append(s.positions[0, 2])
        vz.append(s.velocities[0, 2])
    z, vz = np.array(z), np.array(vz)
    overlap = R - z
    touching = np.flatnonzero(overlap > 0)
    first, last = touching[0], touching[-1]
    # linear interpolation of the times where the overlap crosses zero
    t_in = first - overlap[first] / (overlap[first] - overlap[first - 1])
    t_out = last + overlap[last] / (overlap[last] - overlap[last + 1])
    assert last + 2 < steps, "contact not finished"
    return (t_out - t_in) * dt, -vz[-1] / v0


def test_free_fall_matches_analytic_trajectory():
    s = solver(gravity=(0, 0, -9.81))
    s.add_particles([[0.0, 0.0, 0.005]], R, densities=RHO, velocities=[[0.1, 0.0, 0.2]])
    dt = 1e-5
    s.run(1000, dt)
    t = 1000 * dt
    expected = [0.1 * t, 0.0, 0.005 + 0.2 * t - 0.5 * 9.81 * t * t]
    np.testing.assert_allclose(s.positions[0], expected, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s.velocities[0], [0.1, 0, 0.2 - 9.81 * t], rtol=1e-12, atol=1e-15)
    assert s.time == pytest.approx(t) and s.step == 1000


@pytest.mark.parametrize("kind,model", [("hertz", HertzMindlin), ("hooke", SpringDashpot)])
def test_sphere_plane_impact_matches_reference_model(kind, model):
    v0 = 0.5
    ref = model(material=material(characteristicVelocity=v0)).displacement(velocity=v0)
    s = solver(kind, friction=0.0, characteristic_velocity=v0)
    s.add_plane((0, 0, 0), (0, 0, 1))
    s.add_particles([[0, 0, R + 1e-6]], R, densities=RHO, velocities=[[0, 0, -v0]])
    dt = ref.contact_time / 1000
    tc, e = impact(s, -v0, dt, 1100)
    assert tc == pytest.approx(ref.contact_time, rel=0.01)
    assert e == pytest.approx(ref.restitution, rel=0.01)
    assert e == pytest.approx(0.3, rel=0.01)


def test_head_on_hertz_collision_matches_closed_form():
    v = 0.4  # relative approach speed
    s = solver(restitution=1.0, friction=0.0)
    s.add_particles(
        [[-R - 1e-7, 0, 0], [R + 1e-7, 0, 0]], R, densities=RHO, velocities=[[v / 2, 0, 0], [-v / 2, 0, 0]]
    )
    Rs, ms = R / 2, MASS / 2
    Es = 1 / (2 * (1 - NU**2) / E)
    tc = 2.868 * (ms**2 / (Rs * Es**2 * v)) ** 0.2
    delta_max = (15 * ms * v**2 / (16 * Es * math.sqrt(Rs))) ** 0.4
    f_max = 4 / 3 * Es * math.sqrt(Rs) * delta_max**1.5
    dt = tc / 2000
    overlaps, forces = [], []
    for _ in range(2300):
        s.run(1, dt)
        x = s.positions[:, 0]
        overlaps.append(2 * R - (x[1] - x[0]))
        forces.append(s.forces[1, 0])
    overlaps = np.array(overlaps)
    touching = np.flatnonzero(overlaps > 0)
    assert touching[-1] < len(overlaps) - 1
    first, last = touching[0], touching[-1]
    t_in = first - overlaps[first] / (overlaps[first] - overlaps[first - 1])
    t_out = last + overlaps[last] / (overlaps[last] - overlaps[last + 1])
    assert (t_out - t_in) * dt == pytest.approx(tc, rel=0.01)
    assert overlaps.max() == pytest.approx(delta_max, rel=0.01)
    assert max(forces) == pytest.approx(f_max, rel=0.01)
    np.testing.assert_allclose(s.velocities[:, 0], [-v / 2, v / 2], rtol=1e-6)


def test_sliding_sphere_ends_rolling_at_five_sevenths():
    v0 = 0.2
    s = solver(gravity=(0, 0, -9.81), restitution=0.5, friction=0.3)
    s.add_plane((0, 0, 0), (0, 0, 1))
    mg = MASS * 9.81
    rest = R - (3 * mg / (4 * E / (1 - NU**2) * math.sqrt(R))) ** (2 / 3)  # Hertz static overlap
    s.add_particles([[-0.008, 0, rest]], R, densities=RHO, velocities=[[v0, 0, 0]])
    dt = 2e-6
    s.run(20000, dt)  # sliding lasts 2 v0 / (7 mu g) = 19 ms
    v, w = s.velocities[0], s.omegas[0]
    assert v[0] == pytest.approx(5 / 7 * v0, rel=0.01)
    assert w[1] * R == pytest.approx(v[0], rel=0.01)  # rolling without slip: omega_y = v_x / R


def hertz_energy(s):
    """Kinetic + gravitational + Hertz elastic energy (planes at z = 0, unit types)."""
    kt, kr = s.kinetic_energy()
    x, r, m = s.positions, s.radii, s.masses
    Es = 1 / (2 * (1 - NU**2) / E)
    elastic = 0.0
    i, j, overlap, _ = s.contacts()
    for a, b, d in zip(i, j, overlap):
        Rs = r[a] * r[b] / (r[a] + r[b])
        elastic += 8 / 15 * Es * math.sqrt(Rs) * d**2.5
    wall = np.clip(r - x[:, 2], 0, None)
    elastic += np.sum(8 / 15 * Es * np.sqrt(r) * wall**2.5)
    return kt + kr + np.sum(m * 9.81 * x[:, 2]) + elastic


def test_energy_conserved_without_dissipation():
    s = solver(
        gravity=(0, 0, -9.81),
        periodic=(True, True, False),
        box=((0, 0, 0), (0.012, 0.012, 0.02)),
        restitution=1.0,
        friction=0.0,
    )
    s.add_plane((0, 0, 0), (0, 0, 1))
    rng = np.random.default_rng(1)
    grid = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    x = (grid + 0.5) * 0.004 + np.array([0, 0, 0.001]) + rng.uniform(-4e-4, 4e-4, (27, 3))
    s.add_particles(x, R, densities=RHO, velocities=rng.normal(0, 0.05, (27, 3)))
    dt = 5e-6  # 10^4 steps: the particles fall onto the floor and collide
    s.run(0, dt)
    e0 = hertz_energy(s)
    touching = 0
    for _ in range(100):
        s.run(100, dt)
        touching += len(s.contacts()[0]) + np.sum(s.positions[:, 2] < R)
        assert hertz_energy(s) == pytest.approx(e0, rel=1e-4)
    assert touching > 20


def test_momentum_conserved_in_particle_collisions():
    s = solver(friction=0.5, rolling_friction=0.1)
    rng = np.random.default_rng(2)
    grid = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    x = grid * 2.5e-3 + rng.uniform(-5e-5, 5e-5, (27, 3))
    s.add_particles(
        x, R * rng.uniform(0.8, 1.2, 27), densities=RHO, velocities=-x * 40, omegas=rng.normal(0, 50, (27, 3))
    )
    p0 = (s.masses[:, None] * s.velocities).sum(axis=0)
    scale = np.abs(s.masses[:, None] * s.velocities).sum()
    s.run(20000, 1e-6)
    assert s.kinetic_energy()[0] < 0.8 * 0.5 * np.sum(s.masses * np.sum((40 * x) ** 2, axis=1))  # collided
    p1 = (s.masses[:, None] * s.velocities).sum(axis=0)
    np.testing.assert_allclose(p1, p0, atol=1e-13 * scale)


@pytest.mark.parametrize("threads", [1, 2])
def test_momentum_conserved_across_the_periodic_wrap(threads):
    # a compressed periodic lattice: every sphere touches its 6 neighbours, across each face of
    # the box too; with 2 threads, the last rows of the cell order get forces from the first
    # through the wrap (the pair blocks' far halos), which the particle loop must add
    n, a = 10, 1.9 * R
    s = solver(periodic=(True, True, True), box=((0, 0, 0), (n * a,) * 3), threads=threads)
    rng = np.random.default_rng(5)
    grid = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    v = rng.normal(0, 0.05, grid.shape)
    s.add_particles(
        (grid + 0.5) * a + rng.uniform(-0.02 * R, 0.02 * R, grid.shape),
        R,
        densities=RHO,
        velocities=v - v.mean(axis=0),
    )
    p0 = (s.masses[:, None] * s.velocities).sum(axis=0)
    s.run(200, 1e-6)
    assert len(s.contacts()[0]) == 3 * n**3
    p1 = (s.masses[:, None] * s.velocities).sum(axis=0)
    np.testing.assert_allclose(p1, p0, atol=1e-12 * np.abs(s.masses[:, None] * s.velocities).sum())


def test_periodic_wrap_and_collision_across_the_boundary():
    s = solver(
        periodic=(True, False, False),
        box=((0, -0.01, -0.01), (0.01, 0.01, 0.01)),
        restitution=1.0,
        friction=0.0,
    )
    # b sits just inside the upper x boundary, a just above the lower one: they collide across it
    s.add_particles(
        [[0.0015, 0, 0], [0.0085, 0, 0]], R, densities=RHO, velocities=[[-0.1, 0, 0], [0.1, 0, 0]]
    )
    s.run(4000, 2e-6)
    v = s.velocities[:, 0]
    np.testing.assert_allclose(v, [0.1, -0.1], rtol=1e-6)  # elastic exchange through the boundary
    x = s.positions[:, 0]
    assert np.all((x >= 0) & (x < 0.01))
    s.run(60000, 2e-6)  # travel several box lengths
    assert s.n == 2 and s.lost == 0
    assert np.all((s.positions[:, 0] >= -1e-3) & (s.positions[:, 0] < 0.011))


def test_particles_leaving_a_fixed_boundary_are_deleted_and_counted():
    s = solver(box=((0, 0, 0), (0.01, 0.01, 0.01)))
    ids = s.add_particles(
        [[0.005, 0.005, 0.005], [0.005, 0.005, 0.009]], R, densities=RHO, velocities=[[0, 0, 0], [0, 0, 1.0]]
    )
    s.run(500, 1e-5)
    assert s.n == 1 and s.lost == 1
    np.testing.assert_array_equal(s.ids, ids[:1])


@pytest.mark.parametrize("kind,model", [("hertz", HertzMindlin), ("hooke", SpringDashpot)])
def test_kernel_forces_match_reference_at_sampled_overlaps(kind, model):
    extra = dict(characteristicVelocity=0.3, cohesionEnergyDensity=2e4, coefficientRollingFriction=0.05)
    partner = dict(radius=0.7 * R, density=RHO)
    ref = model(material=material(**extra), partner=partner)
    # cdt's rolling torque bears the elastic part of the normal force (no damping, no cohesion)
    elastic = model(
        material=material(characteristicVelocity=0.3, coefficientRollingFriction=0.05), partner=partner
    )
    for overlap, rate, vt, spin in [
        (1e-6, 0.01, 0.002, 3.0),
        (2e-5, -0.05, 0.03, -10.0),
        (8e-5, 0.2, 0.0, 1.0),
    ]:
        s = solver(kind, characteristic_velocity=0.3, cohesion_energy=2e4, rolling_friction=0.05)
        d = 1.7 * R - overlap
        s.add_particles(
            [[0, 0, 0], [d, 0, 0]],
            [R, 0.7 * R],
            densities=RHO,
            velocities=[[rate, vt, 0], [0, 0, 0]],
            omegas=[[0, 0, spin], [0, 0, 0]],
        )
        s.run(0, 1e-6)  # forces of the initial state (no history yet)
        fn = ref.normal_force(overlap, rate)
        # the contact point is at lever = R - overlap/2 from particle 0's centre (LIGGGHTS'
        # surface model); relative tangential velocity there: v_t - (lever w x n), n = -x
        lever = R - overlap / 2
        vt_rel = vt + spin * lever
        ft, _ = ref.tangential_force(overlap, [0.0, 0.0], [vt_rel, 0.0], fn)
        f = s.forces[0]
        assert -f[0] == pytest.approx(fn, rel=1e-10)
        assert f[1] == pytest.approx(ft[0], rel=1e-10)
        torque = ref.rolling_torque(elastic.normal_force(overlap, 0.0), [0, 0, spin])
        # the tangential force acts at lever x (the contact point seen from particle 0)
        assert s.torques[0, 2] == pytest.approx(torque[2] + lever * ft[0], rel=1e-10)
        i, j, ov, force = s.contacts()
        assert ov[0] == pytest.approx(overlap, rel=1e-6) and force[0] == pytest.approx(fn, rel=1e-10)


def settle(threads, n_side=6, steps=3000):
    a = 2.2e-3
    s = Solver(
        box=[[0, 0, 0], [n_side * a, n_side * a, (n_side + 3) * a]],
        periodic=(True, True, False),
        gravity=(0, 0, -9.81),
        skin=4e-4,
        threads=threads,
    )
    s.set_contact_model("hertz", youngs=E, poisson=NU, restitution=0.3, friction=0.5)
    s.add_plane((0, 0, 0), (0, 0, 1))
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    x = (grid + 0.5) * a + np.random.default_rng(3).uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * R)
    s.add_particles(x, R, densities=RHO)
    s.run(steps, 1e-5)
    return s


def test_settled_packing_fraction_of_frictional_spheres():
    s = settle(threads=1, n_side=8, steps=15000)
    z = s.positions[:, 2]
    assert np.abs(s.velocities).max() < 0.05
    lo, hi = 3 * R, np.sort(z)[-64] - 3 * R  # bulk slab: away from the floor and the free surface
    assert hi - lo > 4 * R
    # exact volume of each sphere inside the slab
    a, b = np.clip(lo - z, -R, R), np.clip(hi - z, -R, R)
    volume = np.pi * ((R * R * b - b**3 / 3) - (R * R * a - a**3 / 3))
    area = (8 * 2.2e-3) ** 2
    phi = volume.sum() / (area * (hi - lo))
    assert 0.55 <= phi <= 0.62


def test_viscous_damping_decays_exponentially():
    s = solver()
    s.set_viscous([2e-4])
    s.add_particles([[0, 0, 0]], R, densities=RHO, velocities=[[0.1, 0, 0]])
    s.run(10000, 1e-6)
    assert s.velocities[0, 0] == pytest.approx(0.1 * math.exp(-2e-4 * s.time / MASS), rel=1e-5)
