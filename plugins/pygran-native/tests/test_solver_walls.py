"""Wall contacts of the native solver: primitives and triangle meshes, fixed and moving."""

import math

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.validation import SOFT

R = 1e-3
RHO, E, NU = SOFT["density"], SOFT["youngsModulus"], SOFT["poissonsRatio"]
OVERLAP = 2e-5


def solver(gravity=(0, 0, 0)):
    s = Solver(box=[[-0.02] * 3, [0.02] * 3], gravity=gravity, skin=2e-4, threads=1)
    s.set_contact_model("hertz", youngs=E, poisson=NU, restitution=0.5, friction=0.5)
    return s


def wall_force(delta=OVERLAP):
    """Hertz force of a flat wall at this overlap, from the plane wall of the solver."""
    s = solver()
    s.add_plane((0, 0, 0), (0, 0, 1))
    s.add_particles([[0, 0, R - delta]], R, densities=RHO)
    s.run(0, 1e-6)
    return s.forces[0, 2]


def grid_mesh(n=4, size=4e-3, z=0.0):
    """Square [-size, size]^2 split into n x n squares of two triangles each."""
    u = np.linspace(-size, size, n + 1)
    X, Y = np.meshgrid(u, u, indexing="ij")
    vertices = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1)

    def k(i, j):
        return i * (n + 1) + j

    triangles = []
    for i in range(n):
        for j in range(n):
            triangles += [[k(i, j), k(i + 1, j), k(i + 1, j + 1)], [k(i, j), k(i + 1, j + 1), k(i, j + 1)]]
    return vertices, np.array(triangles)


def cube_mesh(half=2e-3):
    """Closed cube of 12 triangles, given as an STL would: three unmerged corners per triangle."""
    c = np.array([[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, cc, d in quads for t in ((a, b, cc), (a, cc, d))]
    return c[np.array(tris)].reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3)


@pytest.mark.parametrize(
    "where",
    [(3e-4, 7e-4), (1e-3, 3e-4), (0.0, 0.0), (1e-3, 1e-3), (2e-3, 2e-3)],
    ids=["face", "edge", "vertex-of-six", "diagonal-edge", "vertex"],
)
def test_flat_mesh_counts_shared_edges_and_vertices_once(where):
    s = solver()
    s.add_mesh(*grid_mesh())
    s.add_particles([[where[0], where[1], R - OVERLAP]], R, densities=RHO)
    s.run(0, 1e-6)
    np.testing.assert_allclose(s.forces[0], [0, 0, wall_force()], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    "where", [(2e-5, 1e-5), (3e-5, 0.0), (0.0, 0.0)], ids=["near-centre", "on-a-spoke", "centre"]
)
def test_flat_fan_of_triangles_around_a_sphere_gives_one_contact(where):
    """Eight triangles meeting at the origin (like a meshed square's centre): a sphere near the
    centre reaches all of them, with closest points on edges of triangles not sharing an edge
    with the one under it; the flat surface still pushes once, as the plane."""
    angles = np.arange(8) * np.pi / 4
    rim = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(8)]) * 1e-3
    vertices = np.vstack([[0, 0, 0], rim])
    triangles = [[0, 1 + k, 1 + (k + 1) % 8] for k in range(8)]
    s = solver()
    s.add_mesh(vertices, triangles)
    s.add_particles([[where[0], where[1], R - OVERLAP]], R, densities=RHO)
    s.run(0, 1e-6)
    np.testing.assert_allclose(s.forces[0], [0, 0, wall_force()], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("direction", [(1, 1, 0), (1, 0, 1), (1, 1, 1)], ids=["edge", "edge2", "corner"])
def test_convex_edges_and_corners_of_a_cube_give_one_contact(direction):
    s = solver()
    s.add_mesh(*cube_mesh())
    n = np.array(direction, float) / np.linalg.norm(direction)
    feature = 2e-3 * np.array(direction, float)  # the edge point or corner nearest to the sphere
    s.add_particles([feature + (R - OVERLAP) * n], R, densities=RHO)
    s.run(0, 1e-6)
    np.testing.assert_allclose(s.forces[0], wall_force() * n, rtol=1e-9, atol=1e-12)


def test_concave_corner_gives_one_contact_per_face():
    s = solver()
    floor = grid_mesh()
    wall = floor[0][:, [2, 1, 0]] + [-4e-3, 0, 4e-3]  # the plane x = -4e-3, z from 0 to 8e-3
    s.add_mesh(*floor)
    s.add_mesh(wall, floor[1])
    s.add_particles([[-4e-3 + R - OVERLAP, 0, R - OVERLAP]], R, densities=RHO)
    s.run(0, 1e-6)
    np.testing.assert_allclose(s.forces[0], [wall_force(), 0, wall_force()], rtol=1e-9, atol=1e-12)


def test_sphere_bouncing_on_a_mesh_matches_the_plane():
    results = []
    for mesh in (True, False):
        s = solver(gravity=(0, 0, -9.81))
        if mesh:
            s.add_mesh(*grid_mesh())
        else:
            s.add_plane((0, 0, 0), (0, 0, 1))
        s.add_particles([[1e-3, 1e-3, 2e-3]], R, densities=RHO, velocities=[[0.0, 0, -0.3]])
        s.run(3000, 2e-6)
        results.append(np.concatenate([s.positions[0], s.velocities[0]]))
    np.testing.assert_allclose(results[0], results[1], rtol=1e-9, atol=1e-15)


def test_plane_is_two_sided_with_the_model_restitution():
    v0 = 0.5
    ref = HertzMindlin(material=dict(SOFT, coefficientRestitution=0.5, radius=R)).displacement(velocity=v0)
    final = {}
    for side in (1, -1):  # from above and from below the plane z = 0 of normal +z
        s = solver()
        s.add_plane((0, 0, 0), (0, 0, 1))
        s.add_particles([[0, 0, side * (R + 1e-6)]], R, densities=RHO, velocities=[[0, 0, -side * v0]])
        s.run(1500, ref.contact_time / 1000)
        assert s.forces[0, 2] == 0  # the contact is over
        final[side] = (s.positions[0, 2], s.velocities[0, 2])
        assert side * s.velocities[0, 2] / v0 == pytest.approx(ref.restitution, rel=0.01)
    assert final[1] == (-final[-1][0], -final[-1][1])  # mirror images, bit for bit


def wiggling_plate(amplitude, period):
    s = solver(gravity=(0, 0, -9.81))
    plate = s.add_mesh(*grid_mesh())
    s.set_mesh_motion(plate, amplitude=amplitude, period=period)
    return s, plate


def test_wiggle_displacement_follows_the_closed_form():
    amplitude, period = np.array([1e-4, -2e-4, 3e-4]), 0.01
    s, plate = wiggling_plate(amplitude, period)
    start = s.mesh_triangles(plate)
    s.run(250, period / 1000)  # a quarter period: displaced by the amplitude
    np.testing.assert_allclose(
        s.mesh_triangles(plate) - start, np.broadcast_to(amplitude, start.shape), atol=1e-15
    )
    s.run(750, period / 1000)  # back at the start after the full period
    np.testing.assert_allclose(s.mesh_triangles(plate), start, atol=1e-15)
    s.run(99_000, period / 1000)  # and after 100 periods: nothing accumulates
    np.testing.assert_allclose(s.mesh_triangles(plate), start, atol=1e-15)


def test_particle_resting_on_a_wiggling_plate_moves_with_it():
    amplitude, period = 5e-5, 0.02  # peak acceleration 0.5 g: the particle stays on the plate
    omega = 2 * math.pi / period
    s, _ = wiggling_plate((0, 0, amplitude), period)
    s.add_particles([[1e-3, 1e-3, R]], R, densities=RHO)
    dt = 2e-6
    s.run(int(period / dt), dt)  # one period: the start-up transient dies out
    deviation = []
    for _ in range(50):
        s.run(int(period / dt / 50), dt)
        deviation.append(s.velocities[0, 2] - amplitude * omega * math.cos(omega * s.time))
    assert np.abs(deviation).max() < 0.01 * amplitude * omega


def test_cylinder_inside_holds_particles():
    s = solver(gravity=(9.81, 0, 0))
    s.add_cylinder("z", (0, 0), 5e-3, inside=True)
    s.add_particles([[5e-3 - R + OVERLAP / 10, 0, 0]], R, densities=RHO)
    s.run(20000, 2e-6)
    mg = 4 / 3 * math.pi * R**3 * RHO * 9.81
    assert s.forces[0, 0] == pytest.approx(0, abs=1e-3 * mg)  # equilibrium against the wall
    assert 5e-3 - R < s.positions[0, 0] < 5e-3


def test_moving_mesh_translation_rotation_and_lift():
    s = solver(gravity=(0, 0, -9.81))
    plate = s.add_mesh(*grid_mesh())
    s.add_particles([[1e-3, 0, R]], R, densities=RHO)
    s.set_mesh_motion(plate, velocity=(0, 0, 0.05))
    s.run(20000, 1e-6)  # 0.02 s at 5 cm/s: lifted by 1 mm
    np.testing.assert_allclose(s.mesh_triangles(plate)[..., 2], 1e-3, rtol=1e-9)
    assert s.positions[0, 2] == pytest.approx(1e-3 + R, abs=2e-5)
    assert s.velocities[0, 2] == pytest.approx(0.05, rel=0.05)
    # rotation about the z axis through the origin: vertices follow the exact rotation
    before = s.mesh_triangles(plate).copy()
    s.set_mesh_motion(plate, angular_velocity=(0, 0, 2.0), origin=(0, 0, 0))
    s.run(1000, 1e-6)
    angle = 2.0 * 1e-3
    rot = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    np.testing.assert_allclose(s.mesh_triangles(plate), before @ rot.T, rtol=1e-9, atol=1e-15)
    # friction drags the particle (at x = 1 mm) along with the plate, in +y
    assert 0 < s.velocities[0, 1] <= 2.0 * 1e-3 * 1.001


def test_walls_can_be_removed():
    s = solver(gravity=(0, 0, -9.81))
    floor = s.add_plane((0, 0, 0), (0, 0, 1))
    mesh = s.add_mesh(*grid_mesh(z=-1e-2))
    s.add_particles([[0, 0, R - OVERLAP]], R, densities=RHO)
    s.run(10, 1e-6)
    assert s.forces[0, 2] > 0
    s.remove_wall(floor)
    assert s.walls() == {mesh: "mesh"}
    s.run(10, 1e-6)
    assert s.forces[0, 2] < 0  # falls now
    s.remove_mesh(mesh)
    assert s.walls() == {}
