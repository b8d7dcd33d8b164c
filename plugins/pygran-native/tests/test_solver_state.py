"""Determinism, checkpoints and argument checking of the native solver."""

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core.errors import ConfigError

R, RHO = 1e-3, 2500.0


def bed(threads, n_side=5, seed=3):
    a = 2.2e-3
    s = Solver(
        box=[[0, 0, 0], [n_side * a, n_side * a, (n_side + 3) * a]],
        periodic=(True, True, False),
        gravity=(0, 0, -9.81),
        skin=4e-4,
        threads=threads,
    )
    s.set_contact_model(
        "hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5, rolling_friction=0.02
    )
    s.add_plane((0, 0, 0), (0, 0, 1))
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    x = (grid + 0.5) * a + np.random.default_rng(seed).uniform(-1, 1, grid.shape) * 0.45 * (a - 2 * R)
    s.add_particles(x, R * np.random.default_rng(seed).uniform(0.9, 1.0, len(x)), densities=RHO)
    return s


def snapshot(s):
    return [s.positions, s.velocities, s.omegas, s.forces, s.torques]


def test_results_are_deterministic_for_a_thread_count():
    runs = []
    for _ in range(2):
        s = bed(threads=2)
        s.run(2500, 1e-5)
        runs.append(snapshot(s))
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
    one = bed(threads=1)
    one.run(2500, 1e-5)
    # another thread count sums forces in another order: same physics, not the same bits
    assert np.abs(one.positions - runs[0][0]).max() < 0.5 * R


def test_split_runs_equal_one_run_bitwise():
    straight, split = bed(2), bed(2)
    straight.run(2000, 1e-5)
    for steps in (1, 699, 1300):
        split.run(steps, 1e-5)
    for a, b in zip(snapshot(straight), snapshot(split)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("threads", [1, 2])
def test_state_round_trip_is_bitwise(threads):
    s = bed(threads)
    s.run(1500, 1e-5)
    s.rng.random(3)
    state = s.get_state()
    assert all(isinstance(v, np.ndarray) and v.dtype.kind in "biuf" for v in state.values())
    s.run(1500, 1e-5)
    straight = snapshot(s) + [s.contacts()[3]]
    restored = Solver(
        box=s.box, periodic=s.periodic, gravity=(0, 0, -9.81), skin=4e-4, threads=threads, seed=99
    )
    restored.set_state(state)
    assert restored.step == 1500 and restored.n == s.n
    np.testing.assert_array_equal(restored.rng.random(2), s.rng.random(2))
    restored.run(1500, 1e-5)
    for a, b in zip(straight, snapshot(restored) + [restored.contacts()[3]]):
        np.testing.assert_array_equal(a, b)
    assert restored.time == s.time and restored.rebuilds == s.rebuilds


def test_state_round_trip_keeps_wall_motion_and_plane_sides():
    # gravity upwards: one sphere rests under a plane (a contact from below, side -1), another
    # under a wiggling plate; the state is taken in mid-wiggle
    s = Solver(box=[[-0.01] * 3, [0.01] * 3], gravity=(0, 0, 9.81), skin=2e-4, threads=2)
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
    s.add_plane((0, 0, 0), (0, 0, 1))
    corners = [[-4e-3, -4e-3, 5e-3], [4e-3, -4e-3, 5e-3], [4e-3, 4e-3, 5e-3], [-4e-3, 4e-3, 5e-3]]
    plate = s.add_mesh(corners, [[0, 1, 2], [0, 2, 3]])
    s.set_mesh_motion(plate, amplitude=(3e-5, 0, 4e-5), period=7e-3)
    s.add_particles([[-5e-3, 0, -R], [0, 1e-3, 5e-3 - R]], R, densities=RHO)
    s.run(1234, 1e-5)
    state = s.get_state()
    restored = Solver(box=s.box, gravity=(0, 0, 9.81), skin=2e-4, threads=2)
    restored.set_state(state)
    for solver in (s, restored):
        solver.run(2000, 1e-5)
    for a, b in zip(
        snapshot(s) + [s.mesh_triangles(plate)], snapshot(restored) + [restored.mesh_triangles(plate)]
    ):
        np.testing.assert_array_equal(a, b)
    assert restored.time == s.time and -R < s.positions[0, 2] < -R + 1e-5  # pressed against the plane


def test_tangential_history_survives_rebuilds_and_resorting():
    # a sphere resting on a tilted frictional floor sticks (history holds it) while others move
    s = Solver(
        box=[[-0.02, -0.02, -0.01], [0.02, 0.02, 0.02]],
        gravity=(9.81 * np.sin(0.2), 0, -9.81 * np.cos(0.2)),
        skin=2e-4,
        threads=1,
    )
    s.set_contact_model(
        "hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5, rolling_friction=0.5
    )
    s.add_plane((0, 0, 0), (0, 0, 1))
    s.add_particles([[0, 0, R - 2e-6]], R, densities=RHO)
    s.add_particles([[-0.015, 0.01, 0.01]], R, densities=RHO, velocities=[[3.0, 0, 0]])  # forces rebuilds
    s.run(20000, 1e-6)
    assert s.rebuilds > 5
    assert abs(s.positions[0, 0]) < 1e-5  # held by static friction + rolling resistance


def test_remove_particles_by_id():
    s = bed(1)
    ids = s.ids
    s.remove_particles(ids[[3, 7]])
    assert s.n == len(ids) - 2 and not np.isin([3, 7], s.ids).any()
    s.run(10, 1e-5)
    with pytest.raises(ConfigError, match="ids"):
        s.remove_particles([3])


def test_set_velocities_omegas_and_radii_by_id():
    s = bed(1)
    ids = s.ids[[2, 5]]
    s.set_velocities(ids, [[0.1, 0, 0], [0, 0.2, 0]])
    s.set_omegas(ids[:1], [[0, 0, 30.0]])
    s.set_radii(ids, 1.1 * R)
    np.testing.assert_array_equal(s.velocities[ids], [[0.1, 0, 0], [0, 0.2, 0]])
    np.testing.assert_array_equal(s.omegas[ids[0]], [0, 0, 30.0])
    np.testing.assert_allclose(s.radii[ids], 1.1 * R)
    np.testing.assert_allclose(s.masses[ids], 4 / 3 * np.pi * (1.1 * R) ** 3 * RHO, rtol=1e-12)
    s.run(10, 1e-5)
    with pytest.raises(ConfigError, match="radii"):
        s.set_radii(ids, 0.0)


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: Solver(box=[[0, 0, 0], [1, 1]], skin=1e-3), "box"),
        (lambda: Solver(box=[[0, 0, 0], [1, 1, -1]], skin=1e-3), "box"),
        (lambda: Solver(box=[[0, 0, 0], [1, 1, 1]], skin=0), "skin"),
        (lambda: Solver(box=[[0, 0, 0], [1, 1, 1]], skin=1e-3, threads=0), "threads"),
    ],
)
def test_bad_constructor_arguments(call, match):
    with pytest.raises(ConfigError, match=match):
        call()


def test_bad_arguments_name_the_argument():
    s = Solver(box=[[0, 0, 0], [0.01, 0.01, 0.01]], skin=1e-4)
    with pytest.raises(ConfigError, match="set_contact_model"):
        s.add_particles([[0.005] * 3], R, densities=RHO)
    with pytest.raises(ConfigError, match="kind"):
        s.set_contact_model("hertzian", youngs=1e7, poisson=0.3, restitution=0.5)
    with pytest.raises(ConfigError, match="restitution"):
        s.set_contact_model("hertz", youngs=1e7, poisson=0.3, restitution=1.5)
    with pytest.raises(ConfigError, match="characteristic_velocity"):
        s.set_contact_model("hooke", youngs=1e7, poisson=0.3, restitution=0.5)
    with pytest.raises(ConfigError, match="yield_pressure"):
        s.set_contact_model("thornton-ning", youngs=1e7, poisson=0.3)
    with pytest.raises(ConfigError, match="poisson"):
        s.set_contact_model("hertz", youngs=[1e7, 2e7], poisson=[0.3], restitution=0.5)
    s.set_contact_model("hertz", youngs=1e7, poisson=0.3, restitution=0.5)
    with pytest.raises(ConfigError, match="positions"):
        s.add_particles([[0.005, 0.005]], R, densities=RHO)
    with pytest.raises(ConfigError, match="positions"):
        s.add_particles([[0.005, 0.005, 0.5]], R, densities=RHO)
    with pytest.raises(ConfigError, match="radii"):
        s.add_particles([[0.005] * 3], -R, densities=RHO)
    with pytest.raises(ConfigError, match="densities/masses"):
        s.add_particles([[0.005] * 3], R)
    with pytest.raises(ConfigError, match="types"):
        s.add_particles([[0.005] * 3], R, densities=RHO, types=1)
    with pytest.raises(ConfigError, match="normal"):
        s.add_plane((0, 0, 0), (0, 0, 0))
    with pytest.raises(ConfigError, match="axis"):
        s.add_cylinder("w", (0, 0), 1e-2)
    with pytest.raises(ConfigError, match="triangles"):
        s.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    with pytest.raises(ConfigError, match="mesh"):
        s.set_mesh_motion(s.add_plane((0, 0, 0), (0, 0, 1)), velocity=(0, 0, 1))
    mesh = s.add_mesh([[0, 0, 0], [1e-3, 0, 0], [0, 1e-3, 0]], [[0, 1, 2]])
    with pytest.raises(ConfigError, match="period"):
        s.set_mesh_motion(mesh, amplitude=(0, 0, 1e-4))
    with pytest.raises(ConfigError, match="period"):
        s.set_mesh_motion(mesh, amplitude=(0, 0, 1e-4), period=0.0)
    with pytest.raises(ConfigError, match="wall"):
        s.remove_wall(42)
    with pytest.raises(ConfigError, match="dt"):
        s.run(10, -1.0)
    with pytest.raises(ConfigError, match="nsteps"):
        s.run(1.5, 1e-6)
    p = Solver(box=[[0, 0, 0], [0.004, 0.01, 0.01]], periodic=(True, False, False), skin=1e-4)
    p.set_contact_model("hertz", youngs=1e7, poisson=0.3, restitution=0.5)
    p.add_particles([[0.002, 0.005, 0.005]], R, densities=RHO)
    with pytest.raises(ConfigError, match="periodic axis x"):
        p.run(1, 1e-6)
