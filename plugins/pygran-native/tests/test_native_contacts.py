"""Contact records from the native engine (``traj`` ``cfile``): 48 spheres settled on a floor in
a box periodic in x and y, the floor a plane or a mesh. In the settled bed the contact forces
on each sphere, pairs and walls, balance its weight; the floor carries the bed; branch vectors
are the minimum-image differences of the positions written at the same step; wall contacts
lie on the wall and name it by the order walls were set up (``id2 = -(k + 1)``), as on
LIGGGHTS; a resumed run writes the contacts of the run it continues."""

from __future__ import annotations

import numpy as np
import pytest

from pygran_core import analysis, simulation
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import GRAVITY, RADIUS, SETTLE_SPACING, SOFT, settle_positions

SHAPE = (4, 4, 3)
SIDES = (SHAPE[0] * SETTLE_SPACING, SHAPE[1] * SETTLE_SPACING)
TOP = (SHAPE[2] + 3) * SETTLE_SPACING
COLUMNS = ("id", "type", "x", "y", "z", "radius", "mass", "fx", "fy", "fz")
G = GRAVITY[0]


def square_stl(path, z):
    """Two triangles covering the box's x-y section at height ``z`` (their shared edge a diagonal)."""
    lx, ly = SIDES
    corners = [((0, 0), (lx, 0), (lx, ly)), ((0, 0), (lx, ly), (0, ly))]
    facets = "".join(
        "facet normal 0 0 1\n outer loop\n"
        + "".join(f"  vertex {x!r} {y!r} {z!r}\n" for x, y in triangle)
        + " endloop\nendfacet\n"
        for triangle in corners
    )
    path.write_text(f"solid square\n{facets}endsolid square\n")
    return str(path)


def settled_bed(output, traj, floor="plane", engine="native", steps=80_000, **params):
    """The bed after ``steps``. Walls, in the order they are set up: the mesh ``lid`` under
    the top of the box (a wall from the start: wall 0), then the floor (wall 1, ``id2 = -2``):
    a plane, or the mesh ``floor`` (not a wall until set up) after the lid is removed."""
    output.mkdir(parents=True, exist_ok=True)
    meshes = {"lid": {"file": square_stl(output / "lid.stl", TOP - RADIUS), "material": dict(SOFT)}}
    if floor == "mesh":
        meshes["floor"] = {
            "file": square_stl(output / "floor.stl", 0.0),
            "material": dict(SOFT),
            "import": False,
        }
    with simulation.DEM(
        engine=engine,
        output=str(output),
        progress=False,
        model=HertzMindlin,
        box=(0.0, SIDES[0], 0.0, SIDES[1], -RADIUS, TOP),
        boundary=("p", "p", "f"),
        gravity=GRAVITY,
        dt=1e-5,
        nns_skin=4e-4,
        species=({"material": dict(SOFT), "radius": RADIUS},),
        mesh=meshes,
        traj={"freq": steps // 4, "args": COLUMNS, **traj},
        **params,
    ) as sim:
        sim.setupWall(species=1, wtype="mesh", mesh="lid")  # a wall already: no new one
        if floor == "mesh":
            sim.remove("lid")  # removed walls keep their numbers
            sim.setupWall(species=1, wtype="mesh", mesh="floor")
        else:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", settle_positions(SHAPE, 5))
        sim.run(steps)


def check_frame(particles, contacts, rtol=1e-6):
    """The last frame: every sphere's contacts balance its weight to ``rtol``, the floor
    carries the bed, branch vectors are minimum-image differences, wall contacts are on the
    floor (wall 1) once per sphere there. Returns the wall rows' mask."""
    index = {int(i): k for k, i in enumerate(particles.id)}
    x = np.column_stack([particles.x, particles.y, particles.z])
    force = np.column_stack([contacts.fx, contacts.fy, contacts.fz])
    id2 = np.asarray(contacts.id2)
    pair = id2 > 0
    one = np.array([index[int(i)] for i in contacts.id1])
    two = np.array([index[int(i)] for i in id2[pair]])
    net = np.zeros_like(x)
    np.add.at(net, one, force)  # on id1 by id2, and the opposite on id2
    np.add.at(net, two, -force[pair])
    weight = np.asarray(particles.mass) * G
    np.testing.assert_allclose(net[:, 2], weight, rtol=rtol)
    assert np.abs(net[:, :2]).max() < rtol * weight.max()
    assert force[~pair, 2].sum() == pytest.approx(weight.sum(), rel=rtol)
    # the total force on each sphere at that step is its contacts' plus gravity
    total = np.column_stack([particles.fx, particles.fy, particles.fz])
    assert np.abs(total - net + np.outer(weight, [0, 0, 1])).max() < 1e-12 * weight.max()
    # branch vectors: r1 - r2 at minimum image, some across the periodic sides
    raw = x[one[pair]] - x[two]
    image = raw.copy()
    image[:, :2] -= np.array(SIDES) * np.round(raw[:, :2] / SIDES)
    branch = np.column_stack([contacts.bx, contacts.by, contacts.bz])
    np.testing.assert_allclose(branch[pair], image, rtol=0, atol=1e-15)
    assert np.any(np.abs(raw[:, :2]) > np.array(SIDES) / 2)
    point = np.column_stack([contacts.cx, contacts.cy, contacts.cz])
    np.testing.assert_allclose(point[pair], x[one[pair]] - branch[pair] / 2, rtol=0, atol=1e-15)
    # walls: the floor only, the second wall set up; one contact per sphere, on the floor
    assert set(id2[~pair].tolist()) == {-2}
    assert (~pair).sum() == SHAPE[0] * SHAPE[1] == len(set(one[~pair].tolist()))
    np.testing.assert_array_equal(point[~pair, 2], 0.0)
    np.testing.assert_array_equal(branch[~pair], x[one[~pair]] - point[~pair])
    np.testing.assert_allclose(point[~pair, :2], x[one[~pair], :2], rtol=0, atol=1e-15)
    return ~pair


def test_plane_floor_contacts_in_the_h5md_file(tmp_path):
    settled_bed(tmp_path, {"pfile": "traj.h5", "cfile": "traj.h5"}, steps=120_000)
    with analysis.System(Particles=str(tmp_path / "traj.h5")) as system:
        assert system.names == ["Particles", "Contacts"] and len(system) == 5
        steps = [(system.Particles.timestep, system.Contacts.timestep) for _ in system.frames()]
        assert steps == [(s, s) for s in range(0, 120_001, 30_000)]
        system.goto(0)
        assert len(system.Contacts) == 0  # no force evaluated yet
        system.goto(-1)
        walls = check_frame(system.Particles, system.Contacts)
        assert len(system.Contacts) - walls.sum() > len(system.Particles)  # a packed bed


def test_mesh_floor_contacts_in_a_dump_local(tmp_path):
    """The floor's two triangles meet under the bed: a sphere touching both counts once."""
    settled_bed(tmp_path, {"pfile": "traj.dump", "cfile": "contacts.dump"}, floor="mesh", steps=160_000)
    with analysis.System(
        Particles=str(tmp_path / "traj.dump"), Contacts=str(tmp_path / "contacts.dump")
    ) as system:
        assert len(system) == 5
        system.goto(-1)
        assert system.Particles.timestep == system.Contacts.timestep == 160_000
        walls = check_frame(system.Particles, system.Contacts)
        on_floor = np.isin(system.Particles.id, np.asarray(system.Contacts.id1)[walls])
        x, y = np.asarray(system.Particles.x)[on_floor], np.asarray(system.Particles.y)[on_floor]
        to_diagonal = np.abs(SIDES[1] * x - SIDES[0] * y) / np.hypot(*SIDES)
        assert np.count_nonzero(to_diagonal < RADIUS) >= 2  # spheres that reach both triangles


def bed_with_checkpoints(output, runs, resume):
    output.mkdir(exist_ok=True)
    with simulation.DEM(
        engine="native",
        output=str(output),
        progress=False,
        model=HertzMindlin,
        box=(0.0, SIDES[0], 0.0, SIDES[1], -RADIUS, TOP),
        boundary=("p", "p", "f"),
        gravity=GRAVITY,
        dt=1e-5,
        nns_skin=4e-4,
        species=({"material": dict(SOFT), "radius": RADIUS},),
        restart={"freq": 1000, "resume": resume},
        traj={"freq": 500, "pfile": "traj.h5", "cfile": "traj.h5", "args": COLUMNS},
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", settle_positions(SHAPE, 5))
        for _ in range(runs):
            sim.run(1000)


def test_resumed_run_writes_the_contacts_of_the_run_it_continues(tmp_path):
    """Resumed at its checkpoint of step 2000, a script writes every later contact exactly as
    the uninterrupted run does (the first frame after the resume comes after a step)."""
    bed_with_checkpoints(tmp_path / "straight", 3, resume=False)
    bed_with_checkpoints(tmp_path / "resumed", 2, resume=False)
    bed_with_checkpoints(tmp_path / "resumed", 3, resume=True)
    with (
        analysis.System(Particles=str(tmp_path / "straight" / "traj.h5")) as straight,
        analysis.System(Particles=str(tmp_path / "resumed" / "traj.h5")) as resumed,
    ):
        assert len(straight) == len(resumed) == 7
        for _ in zip(straight.frames(), resumed.frames()):
            assert resumed.Contacts.timestep == straight.Contacts.timestep
            for name in ("id1", "id2", "fx", "fy", "fz", "cx", "cy", "cz", "bx", "by", "bz"):
                np.testing.assert_array_equal(
                    getattr(resumed.Contacts, name), getattr(straight.Contacts, name)
                )
        assert np.count_nonzero(np.asarray(resumed.Contacts.id2) == -1) > 0  # the bed reached the floor


def test_a_wall_has_the_same_id_on_liggghts(tmp_path):
    """The mesh floor set up after the lid was removed is wall 1 on both engines (LIGGGHTS
    numbers it 0 among its mesh walls); both beds rest on it with one contact per sphere."""
    from pygran_liggghts.library import find_library  # the other engine's plugin: only here

    require_solver(find_library)
    found = {}
    for engine in ("native", "liggghts"):
        settled_bed(
            tmp_path / engine,
            {"pfile": "traj.h5", "cfile": "traj.h5"},
            floor="mesh",
            engine=engine,
            steps=40_000,
        )
        with analysis.System(Particles=str(tmp_path / engine / "traj.h5")) as system:
            system.goto(-1)
            wall = np.asarray(system.Contacts.id2) < 0
            found[engine] = (
                sorted(set(np.asarray(system.Contacts.id2)[wall].tolist())),
                wall.sum(),
                np.asarray(system.Contacts.fz)[wall].sum() / (np.asarray(system.Particles.mass).sum() * G),
            )
    assert found["native"][:2] == found["liggghts"][:2] == ([-2], SHAPE[0] * SHAPE[1])
    assert found["native"][2] == pytest.approx(1.0, rel=1e-4)
    assert found["liggghts"][2] == pytest.approx(1.0, rel=1e-4)


def test_cylinder_contacts_are_on_its_surface(tmp_path):
    """Spheres settled in a cylinder on a plane: the floor is wall 0, the cylinder wall 1; a
    cylinder contact's point is the foot of the radius through the centre; each sphere's
    contacts and weight sum to the force the engine applied, and vertically they balance.
    (Horizontally they need not: without rolling resistance the stack keeps turning in the
    cylinder like a planetary gear, every contact rolling.)"""
    inner = 3.2 * RADIUS
    with simulation.DEM(
        engine="native",
        output=str(tmp_path),
        progress=False,
        model=HertzMindlin,
        box=(-inner, inner, -inner, inner, 0.0, 0.03),
        gravity=GRAVITY,
        dt=1e-5,
        nns_skin=4e-4,
        species=({"material": dict(SOFT), "radius": RADIUS},),
        traj={"freq": 80_000, "pfile": "traj.h5", "cfile": "traj.h5", "args": COLUMNS},
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.setupWall(species=1, axis="z", centre=(0.0, 0.0), radius=inner)
        rng = np.random.default_rng(1)
        centres = [  # 4 layers of 3 spheres, each turned at random
            (1.6 * RADIUS * np.cos(a), 1.6 * RADIUS * np.sin(a), (2.5 + 2.2 * k) * RADIUS)
            for k in range(4)
            for a in rng.uniform(0, 2 * np.pi, 1) + np.arange(3) * 2 * np.pi / 3
        ]
        sim.createParticles(1, "single", np.array(centres))
        sim.run(80_000)
    with analysis.System(Particles=str(tmp_path / "traj.h5")) as system:
        system.goto(-1)
        p, c = system.Particles, system.Contacts
        index = {int(i): k for k, i in enumerate(p.id)}
        x = np.column_stack([p.x, p.y, p.z])
        force = np.column_stack([c.fx, c.fy, c.fz])
        id2 = np.asarray(c.id2)
        one = np.array([index[int(i)] for i in c.id1])
        net = np.zeros_like(x)
        np.add.at(net, one, force)
        np.add.at(net, [index[int(i)] for i in id2[id2 > 0]], -force[id2 > 0])
        weight = np.asarray(p.mass) * G
        total = np.column_stack([p.fx, p.fy, p.fz])
        np.testing.assert_allclose(
            net - np.outer(weight, [0, 0, 1]), total, rtol=0, atol=1e-12 * weight.max()
        )
        np.testing.assert_allclose(net[:, 2], weight, rtol=1e-6)
        assert set(id2[id2 < 0].tolist()) == {-1, -2}
        side = id2 == -2
        point = np.column_stack([c.cx, c.cy, c.cz])[side]
        np.testing.assert_allclose(np.hypot(point[:, 0], point[:, 1]), inner, rtol=1e-15)
        np.testing.assert_array_equal(point[:, 2], x[one[side], 2])
        centre = x[one[side]]
        np.testing.assert_allclose(
            point[:, :2] * np.hypot(centre[:, 0], centre[:, 1])[:, None],
            centre[:, :2] * inner,
            rtol=1e-14,
            atol=0,
        )
        branch = np.column_stack([c.bx, c.by, c.bz])[side]
        np.testing.assert_array_equal(branch, centre - point)
