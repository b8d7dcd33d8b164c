"""The pair loop's sublist (hertz without rolling resistance): it skips the listed pairs that
were not near contact when it was built, until a particle may have moved far enough to reach
one. It must never miss a contact: at the end of every run, the solver's contacts are exactly
the pairs of spheres that overlap, counted by brute force, whether the sublist was reused for
many steps (slow spheres) or rebuilt nearly every step (fast ones). That the forces are those
of the whole list to the bit is test_solver_bitwise.py's part (its shear case)."""

from __future__ import annotations

import numpy as np
import pytest
from pygran_native.solver import Solver
from scipy.spatial import cKDTree

R, SKIN, DT = 1e-3, 2e-4, 1e-5


def overlapping(x: np.ndarray, r: np.ndarray, ids: np.ndarray) -> tuple[set, int]:
    """Pairs of ids whose spheres overlap, and the pairs too close to the touching distance to
    say (within 1e-9 of it) left out."""
    pairs = cKDTree(x).query_pairs(2 * r.max(), output_type="ndarray")
    gap = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) - r[pairs].sum(axis=1)
    clear = np.abs(gap) > 1e-9 * R
    touching = pairs[clear & (gap < 0)]
    return {tuple(sorted(p)) for p in ids[touching]}, int((~clear).sum())


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize(("speed", "steps_per_run"), [(0.02, 20), (0.6, 3)])
def test_the_contacts_are_every_overlapping_pair(speed, steps_per_run, threads):
    rng = np.random.default_rng(7)
    side = 0.03
    lattice = np.indices((12, 12, 12)).reshape(3, -1).T * 2.3e-3 + 2e-3  # 0 to 0.5 mm apart
    x = lattice + rng.uniform(-5e-5, 5e-5, lattice.shape)
    r = rng.uniform(0.9 * R, 1.1 * R, len(x))  # polydisperse: each pair its own touching distance
    v = rng.normal(0.0, speed, x.shape)
    s = Solver(
        box=np.array([[0.0] * 3, [side] * 3]),
        periodic=(False,) * 3,
        gravity=(0, 0, -9.81),
        skin=SKIN,
        threads=threads,
    )
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.5, friction=0.4)
    for axis in range(3):
        normal = np.eye(3)[axis]
        s.add_plane(np.zeros(3), normal)
        s.add_plane(np.full(3, side), -normal)
    s.add_particles(x, r, densities=2500, velocities=v)
    runs, contacts, unclear = 60, [], 0
    for _ in range(runs):
        s.run(steps_per_run, DT)
        expected, ambiguous = overlapping(s.positions, s.radii, s.ids)
        unclear += ambiguous
        i, j, _, _ = s.contacts()
        found = {tuple(sorted(p)) for p in zip(i.tolist(), j.tolist())}
        assert found == expected
        contacts.append(len(found))
    assert unclear == 0
    assert min(contacts[20:]) > 30  # a granular gas colliding
    steps = runs * steps_per_run
    builds = s.timings["sublist_builds"]
    assert s.rebuilds < builds
    if speed < 0.1:  # reused for many steps between builds ...
        assert builds < steps / 5
    else:  # ... or built at most steps
        assert builds > steps / 3
