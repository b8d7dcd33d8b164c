"""The native solver's per-contact forces (``Solver.contact_forces``): the forces its last step
applied, with contact points and branch vectors, for coarse-graining."""

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core.errors import ConfigError

R, A, G = 1e-3, 2.2e-3, 9.81
BOX = dict(
    box=[[0, 0, 0], [6 * A, 6 * A, 12 * A]], periodic=(True, True, False), gravity=(0, 0, -G), skin=3e-4
)


def bed(threads: int = 1) -> Solver:
    """216 spheres of two sizes settling on a floor for 3000 steps, with friction (tangential
    forces) and without viscous drag, periodic across x and y."""
    s = Solver(**BOX, threads=threads)
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
    s.add_plane((0, 0, 0), (0, 0, 1))
    grid = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(3)
    x = (grid + 0.5) * A + rng.uniform(-0.1, 0.1, grid.shape) * A
    s.add_particles(x, rng.uniform(0.85, 1.0, len(x)) * R, densities=2500)
    s.run(3000, 1e-5)
    return s


@pytest.mark.parametrize("threads", [1, 2])
def test_contact_forces_are_those_the_step_applied(threads):
    """Summed over its contacts (id1 gets f, id2 -f; the floor's rows have id2 = -1), with its
    weight, every sphere gets the force the step gave it (1e-9 of the largest force on it); the
    branch vector joins the centres (the image in contact across a periodic side), the contact
    point lies in the middle of the overlap, and friction tilts forces off the line of centres.
    Floor rows: the contact point on the floor, the branch from it to the centre."""
    s = bed(threads)
    c = s.contact_forces()
    assert len(c["id1"]) > 100 and c["id1"].dtype == c["id2"].dtype == np.int64
    wall = c["id2"] < 0
    assert wall.sum() > 10 and np.all(c["id2"][wall] == -1)  # the plane is the solver's wall 0
    f = np.stack([c["fx"], c["fy"], c["fz"]], 1)
    b = np.stack([c["bx"], c["by"], c["bz"]], 1)
    point = np.stack([c["cx"], c["cy"], c["cz"]], 1)
    x, r, m, total = s.positions, s.radii, s.masses, s.forces
    summed = np.zeros_like(x)
    np.add.at(summed, c["id1"], f)
    np.add.at(summed, c["id2"][~wall], -f[~wall])
    scale = np.zeros(len(x))
    np.add.at(scale, c["id1"], np.linalg.norm(f, axis=1))
    np.add.at(scale, c["id2"][~wall], np.linalg.norm(f[~wall], axis=1))
    weight = m[:, None] * [0, 0, -G]
    error = np.abs(summed + weight - total).max(axis=1)
    assert np.all(error <= 1e-9 * (scale + m * G))
    np.testing.assert_allclose(point[wall, 2], 0, atol=1e-15)
    np.testing.assert_allclose(b[wall], x[c["id1"][wall]] - point[wall], rtol=0, atol=1e-15)
    f, b, point, c = f[~wall], b[~wall], point[~wall], {k: v[~wall] for k, v in c.items()}
    # geometry: centres, overlaps, the periodic image
    dist = np.linalg.norm(b, axis=1)
    image = x[c["id1"]] - x[c["id2"]] - b
    np.testing.assert_allclose(image[:, :2] / (6 * A), np.round(image[:, :2] / (6 * A)), atol=1e-9)
    np.testing.assert_allclose(image[:, 2], 0, atol=1e-15)
    assert np.any(np.abs(image[:, :2]) > 3 * A)  # some contacts are across a periodic side
    overlap = r[c["id1"]] + r[c["id2"]] - dist
    assert np.all(overlap > 0)
    to_point = np.linalg.norm(point - x[c["id1"]], axis=1)
    np.testing.assert_allclose(to_point, r[c["id1"]] - overlap / 2, rtol=1e-12)
    np.testing.assert_allclose(np.cross(point - x[c["id1"]], b), 0, atol=1e-12 * R * R)
    # the normal part, and a tangential part
    normal = np.einsum("ij,ij->i", f, b) / dist
    assert np.mean(normal > 0) > 0.8  # repulsive mostly (damping pulls while a contact opens)
    tangential = np.linalg.norm(f - normal[:, None] * b / dist[:, None], axis=1)
    assert tangential.max() > 0.05 * normal.max()


def test_no_contact_forces_after_a_restored_state_until_a_step():
    s = bed()
    fresh = Solver(**BOX, threads=1)
    fresh.set_state(s.get_state())
    with pytest.raises(ConfigError, match="run a step first"):
        fresh.contact_forces()
    fresh.run(1, 1e-5)
    s.run(1, 1e-5)
    again, straight = fresh.contact_forces(), s.contact_forces()
    for key, value in straight.items():
        np.testing.assert_array_equal(again[key], value, err_msg=key)


def test_contact_forces_of_clumps_are_between_their_spheres_and_others():
    """Two rods on a floor: contacts between spheres of different rods only, none within one."""
    s = Solver(box=[[-0.01] * 3, [0.01, 0.01, 0.02]], gravity=(0, 0, -G), skin=2e-4, threads=1)
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
    s.add_plane((0, 0, 0), (0, 0, 1))
    rod = [(1.5 * R * (k - 1.5), 0.0, 0.0, R) for k in range(4)]
    s.add_clumps(rod, [[0, 0, 1.2 * R], [0, 0, 3.1 * R]], 2500)
    s.run(2000, 1e-5)
    c = s.contact_forces()
    c = {k: v[c["id2"] >= 0] for k, v in c.items()}  # the spheres' contacts, not the floor's
    body = s.bodies
    assert len(c["id1"]) >= 4 and np.all(body[c["id1"]] != body[c["id2"]])
    f = np.stack([c["fx"], c["fy"], c["fz"]], 1)
    top = body[c["id1"]] == 1
    on_top = f[top].sum(axis=0) - f[~top].sum(axis=0)  # on the upper rod by the lower one
    rods = s.clumps()
    assert rods["centre"][1, 2] > rods["centre"][0, 2] + R  # it lies on the other
    np.testing.assert_allclose(
        on_top + rods["mass"][1] * np.array([0, 0, -G]),
        rods["force"][1],
        rtol=0,
        atol=1e-9 * rods["mass"][1] * G,
    )
