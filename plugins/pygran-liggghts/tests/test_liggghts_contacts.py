"""Contact records from LIGGGHTS (``traj`` ``cfile``): a bed of 48 spheres settled on a mesh
floor in a box periodic in x and y. In the settled bed the contact forces on each sphere,
with its wall contacts, balance its weight; the branch vectors are the minimum-image
differences of the positions written at the same step; the records are in step with the
particle frames, in the H5MD file or in a dump local beside LIGGGHTS' own dump, on 1 and 2
MPI ranks."""

from __future__ import annotations

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import analysis, simulation
from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import GRAVITY, RADIUS, SETTLE_SPACING, SOFT, settle_positions

SHAPE = (4, 4, 3)
SIDES = (SHAPE[0] * SETTLE_SPACING, SHAPE[1] * SETTLE_SPACING)
COLUMNS = ("id", "type", "x", "y", "z", "radius", "mass", "fx", "fy", "fz")


def floor_stl(path):
    """Two triangles covering the box's floor at z = 0."""
    lx, ly = SIDES
    corners = [((0, 0), (lx, 0), (lx, ly)), ((0, 0), (lx, ly), (0, ly))]
    facets = "".join(
        "facet normal 0 0 1\n outer loop\n"
        + "".join(f"  vertex {x!r} {y!r} 0\n" for x, y in triangle)
        + " endloop\nendfacet\n"
        for triangle in corners
    )
    path.write_text(f"solid floor\n{facets}endsolid floor\n")
    return path


def settled_bed(output, traj, nprocs=1, steps=200_000):
    require_solver(find_library)
    output.mkdir(parents=True)
    with simulation.DEM(
        engine="liggghts",
        output=str(output),
        progress=False,
        nprocs=nprocs,
        model=HertzMindlin,
        box=(0.0, SIDES[0], 0.0, SIDES[1], -RADIUS, (SHAPE[2] + 3) * SETTLE_SPACING),
        boundary=("p", "p", "f"),
        gravity=GRAVITY,
        dt=1e-5,
        nns_skin=4e-4,
        species=({"material": dict(SOFT), "radius": RADIUS},),
        mesh={"floor": {"file": str(floor_stl(output / "floor.stl")), "material": dict(SOFT)}},
        traj={"freq": 50_000, "args": COLUMNS, **traj},
    ) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="floor")
        sim.createParticles(1, "single", settle_positions(SHAPE, 5))
        sim.run(steps)


def check_frame(particles, contacts, rtol=1e-6, atol=1e-15):
    """The last frame: forces balance to ``rtol`` of the weight, branch vectors and contact
    points to ``atol`` (m), wall rows. (LIGGGHTS' own dump writes 6 digits.)"""
    index = {int(i): k for k, i in enumerate(particles.id)}
    x = np.column_stack([particles.x, particles.y, particles.z])
    force = np.column_stack([contacts.fx, contacts.fy, contacts.fz])
    pair = np.asarray(contacts.id2) > 0
    one = np.array([index[int(i)] for i in contacts.id1])
    two = np.array([index[int(i)] for i in np.asarray(contacts.id2)[pair]])
    net = np.zeros_like(x)
    np.add.at(net, one, force)  # on id1 by id2, and the opposite on id2
    np.add.at(net, two, -force[pair])
    weight = np.asarray(particles.mass) * 9.81
    # static bed: every sphere's contacts (walls included) carry its weight
    np.testing.assert_allclose(net[:, 2], weight, rtol=rtol)
    assert np.abs(net[:, :2]).max() < rtol * weight.max()
    assert force[~pair, 2].sum() == pytest.approx(weight.sum(), rel=rtol)  # the floor carries the bed
    # LIGGGHTS' total force on each sphere at that step: contacts plus gravity
    total = np.column_stack([particles.fx, particles.fy, particles.fz])
    assert np.abs(total - net + np.outer(weight, [0, 0, 1])).max() < rtol * weight.max()
    # branch vectors: r1 - r2 at minimum image (pairs across the periodic sides among them)
    raw = x[one[pair]] - x[two]
    image = raw.copy()
    image[:, :2] -= np.array(SIDES) * np.round(raw[:, :2] / SIDES)
    branch = np.column_stack([contacts.bx, contacts.by, contacts.bz])
    np.testing.assert_allclose(branch[pair], image, rtol=0, atol=atol)
    assert np.any(np.abs(raw[:, :2]) > np.array(SIDES) / 2)
    distance = np.linalg.norm(branch[pair], axis=1)
    assert np.all((distance < 2 * RADIUS) & (distance > 1.99 * RADIUS))
    # the contact point halfway along the branch (equal radii), the wall's on the floor
    point = np.column_stack([contacts.cx, contacts.cy, contacts.cz])
    np.testing.assert_allclose(point[pair], x[one[pair]] - branch[pair] / 2, rtol=0, atol=atol)
    assert np.unique(np.asarray(contacts.id2)[~pair]).tolist() == [-1]  # the first wall set up
    np.testing.assert_array_equal(point[~pair, 2], 0.0)
    np.testing.assert_allclose(branch[~pair], x[one[~pair]] - point[~pair], rtol=0, atol=atol)


def test_contacts_in_the_h5md_file(tmp_path):
    settled_bed(tmp_path / "h5", {"pfile": "traj.h5", "cfile": "traj.h5"})
    with analysis.System(Particles=str(tmp_path / "h5" / "traj.h5")) as system:
        assert system.names == ["Particles", "Contacts"] and len(system) == 5
        steps = [(system.Particles.timestep, system.Contacts.timestep) for _ in system.frames()]
        assert steps == [(s, s) for s in range(0, 200_001, 50_000)]
        system.goto(-1)
        assert system.Particles.timestep == system.Contacts.timestep == 200_000
        check_frame(system.Particles, system.Contacts)


def test_contacts_dump_local_on_two_ranks(tmp_path):
    """LIGGGHTS writes the particles' .dump, PyGran the contacts' dump local beside it; on two
    ranks every contact is there once (the balance above holds)."""
    out = tmp_path / "np2"
    settled_bed(out, {"pfile": "traj.dump", "cfile": "contacts.dump"}, nprocs=2, steps=100_000)
    assert not list((out / "liggghts-contacts").iterdir())  # LIGGGHTS' own files read and removed
    with analysis.System(Particles=str(out / "traj.dump"), Contacts=str(out / "contacts.dump")) as system:
        assert len(system) == 3
        system.goto(-1)
        assert system.Particles.timestep == system.Contacts.timestep == 100_000
        check_frame(system.Particles, system.Contacts, rtol=2e-5, atol=1e-8)


def test_primitive_walls_are_refused_with_contact_output(tmp_path):
    require_solver(find_library)
    with simulation.DEM(
        engine="liggghts",
        output=str(tmp_path),
        progress=False,
        model=HertzMindlin,
        box=(0, 0.01, 0, 0.01, 0, 0.01),
        species=({"material": dict(SOFT), "radius": RADIUS},),
        traj={"cfile": "contacts.dump"},
    ) as sim:
        with pytest.raises(UnsupportedFeature, match="mesh walls set up before the first run.*wtype='mesh'"):
            sim.setupWall(species=1, plane="zplane", peq=0.0)


def bed_with_checkpoints(output, runs, resume):
    with simulation.DEM(
        engine="liggghts",
        output=str(output),
        progress=False,
        model=HertzMindlin,
        box=(0.0, SIDES[0], 0.0, SIDES[1], -RADIUS, (SHAPE[2] + 3) * SETTLE_SPACING),
        boundary=("p", "p", "f"),
        gravity=GRAVITY,
        dt=1e-5,
        nns_skin=4e-4,
        species=({"material": dict(SOFT), "radius": RADIUS},),
        mesh={"floor": {"file": str(floor_stl(output / "floor.stl")), "material": dict(SOFT)}},
        restart={"freq": 1000, "resume": resume},
        traj={"freq": 500, "pfile": "traj.h5", "cfile": "traj.h5", "args": COLUMNS},
    ) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="floor")
        sim.createParticles(1, "single", settle_positions(SHAPE, 5))
        for _ in range(runs):
            sim.run(1000)


def test_contacts_resume(tmp_path):
    """A script resumed from its checkpoint at step 2000 continues the contacts with the
    particles: LIGGGHTS' computes are defined anew after its restart file, and the frame it
    writes again at the resumed step is not written twice."""
    require_solver(find_library)
    bed_with_checkpoints(tmp_path, 2, resume=False)
    bed_with_checkpoints(tmp_path, 3, resume=True)
    with analysis.System(Particles=str(tmp_path / "traj.h5")) as system:
        steps = [(system.Particles.timestep, system.Contacts.timestep) for _ in system.frames()]
        assert steps == [(s, s) for s in range(0, 3001, 500)]
        system.goto(-1)
        assert len(system.Contacts) > len(system.Particles)  # the falling spheres have met
