"""Front-end calls on real LIGGGHTS: insertion by rate, mesh motion, .h5 trajectories,
viscous drag, createParticles 'random' and angular velocities, run chunks with ``pre no``."""

import math
from pathlib import Path

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import analysis, simulation
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT as MATERIAL

R = 1e-3
MASS = 4 / 3 * math.pi * R**3 * MATERIAL["density"]
G = 9.81
DT = 1e-5
VTK = 1e-8  # rounding of the mesh coordinates (about 1e-3 m) in LIGGGHTS' VTK files
PLATE = """solid plate
facet normal 0 0 1
 outer loop
  vertex 0.002 -0.001 0.005
  vertex 0.004 -0.001 0.005
  vertex 0.004 0.001 0.005
 endloop
endfacet
facet normal 0 0 1
 outer loop
  vertex 0.002 -0.001 0.005
  vertex 0.004 0.001 0.005
  vertex 0.002 0.001 0.005
 endloop
endfacet
endsolid plate
"""


def dem(path, **params):
    require_solver(find_library)
    settings = {
        "engine": "liggghts",
        "model": "HertzMindlin",
        "box": (-0.01, 0.01, -0.01, 0.01, 0, 0.03),
        "dt": DT,
        "output": str(path),
        "species": ({"material": MATERIAL, "radius": R},),
        "traj": {"pfile": None},
        "progress": False,
    }
    return simulation.DEM(**settings | params)


def test_insertion_by_rate(tmp_path):
    """Every ``freq`` steps from the next step on, rate * freq * dt particles (here 2):
    after t = k * freq * dt the count is rate * t; ``duration`` caps it, and without
    ``freq`` batches come every insertion.RATE_INTERVAL (0.01 s) as on other engines."""
    region = ("block", -0.009, 0.009, -0.009, 0.009, 0.001, 0.029)
    rate = 2000.0
    with dem(tmp_path / "freq") as sim:
        sim.insert(species=1, insert="by_rate", rate=rate, freq=100, region=region)
        sim.run(1000)
        assert len(sim.extractIds()) == rate * 1000 * DT == 20
        sim.run(1500)
        assert len(sim.extractIds()) == 50
    with dem(tmp_path / "duration") as sim:
        sim.insert(species=1, insert="by_rate", rate=rate, freq=100, duration=0.015, region=region)
        sim.run(3000)
        assert len(sim.extractIds()) == rate * 0.015 == 30
    with dem(tmp_path / "default", dt=2 * DT) as sim:
        sim.insert(species=1, insert="by_rate", rate=rate, region=region)
        sim.run(1250)  # batches of 20 at steps 1, 501 and 1001
        count = len(sim.extractIds())
    assert count == 60
    assert abs(count - rate * 1250 * 2 * DT) <= rate * 0.01  # within one batch


def _plate_motion(tmp_path, **motion):
    """The plate's corner points (frames, 6, 3) in the mesh files written every 250 steps over
    two runs of 500 steps after ``moveMesh(**motion)`` (LIGGGHTS writes 6 significant digits)."""
    tmp_path.mkdir(exist_ok=True)
    stl = tmp_path / "plate.stl"
    stl.write_text(PLATE)
    with dem(
        tmp_path / "out",
        mesh={"plate": {"file": str(stl)}},
        traj={"freq": 250, "pfile": None, "mfile": "plate*.vtk"},
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="plate")
        sim.moveMesh("plate", **motion)
        sim.run(500)
        sim.run(500)
    system = analysis.System(Mesh=str(tmp_path / "out" / "plate*.vtk"))
    frames = []
    for _ in system.frames():
        frames.append(np.array(system.Mesh.points))
    system.close()
    return np.array(frames)


def _rotated(points, angle):
    c, s = math.cos(angle), math.sin(angle)
    return points @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T


@pytest.mark.parametrize("sense", [1, -1])
def test_mesh_rotates_by_omega_t(tmp_path, sense):
    omega = sense * math.pi / 2 / 0.01  # a quarter turn in 1000 steps, right-handed about +z
    frames = _plate_motion(tmp_path, rotate=True, axis=(0, 0, 1), origin=(0, 0, 0), omega=omega)
    assert len(frames) == 5
    for k, points in enumerate(frames):
        np.testing.assert_allclose(points, _rotated(frames[0], omega * 250 * k * DT), atol=VTK)
    assert frames[-1][0] == pytest.approx([sense * 0.001, sense * 0.002, 0.005], abs=VTK)


def test_mesh_moves_linearly_and_wiggles(tmp_path):
    frames = _plate_motion(tmp_path / "linear", linear=(0.1, -0.05, 0))
    for k, points in enumerate(frames):
        np.testing.assert_allclose(points, frames[0] + np.array([0.1, -0.05, 0]) * 250 * k * DT, atol=VTK)
    amplitude, period = 1e-3, 0.02
    frames = _plate_motion(tmp_path / "wiggle", wiggle=True, amplitude=(0, 0, amplitude), period=period)
    omega = 2 * math.pi / period
    for k, points in enumerate(frames):
        shift = amplitude * math.sin(omega * 250 * k * DT)
        # LIGGGHTS integrates the wiggle's velocity with one-sided sums: error below A omega dt
        np.testing.assert_allclose(points, frames[0] + [0, 0, shift], atol=amplitude * omega * DT)
    assert frames[2][:, 2] - frames[0][:, 2] == pytest.approx(amplitude, rel=2e-3)  # a quarter period


def test_mesh_vibrates_linearly_and_rotationally(tmp_path):
    """viblin moves the plate along its axis by sum_i a_i (cos(w_i t + p_i) - cos(p_i)),
    w_i = 2 pi / T_i (LIGGGHTS integrates the velocity -sum_i a_i w_i sin(w_i t + p_i) to first
    order in dt); vibrot turns it about its axis through origin by that angle."""
    amplitudes, phases, periods = (1e-4, 5e-5), (0.0, 1.0), (0.01, 0.004)

    def shift(t, scale=1.0):
        return sum(
            scale * a * (math.cos(2 * math.pi / T * t + p) - math.cos(p))
            for a, p, T in zip(amplitudes, phases, periods)
        )

    frames = _plate_motion(
        tmp_path / "viblin",
        viblin=("axis", 0, 0, 2),
        order=2,
        amplitude=amplitudes,
        phase=phases,
        period=periods,
    )
    bound = sum(a * 2 * math.pi / T for a, T in zip(amplitudes, periods)) * DT  # first order in dt
    for k, points in enumerate(frames):
        np.testing.assert_allclose(points, frames[0] + [0, 0, shift(250 * k * DT)], atol=bound + VTK)
    # a quarter period of the first harmonic and 5/8 of the second: 1.16e-4 m down
    assert frames[1][0, 2] - frames[0][0, 2] == pytest.approx(shift(250 * DT), rel=0.02)
    radians = 1e3  # amplitudes in radians here: 0.1 and 0.05
    frames = _plate_motion(
        tmp_path / "vibrot",
        vibrot=("origin", 0, 0, 0),
        axis=(0, 0, 1),
        order=2,
        amplitude=tuple(a * radians for a in amplitudes),
        phase=phases,
        period=periods,
    )
    for k, points in enumerate(frames):
        angle = shift(250 * k * DT, radians)
        np.testing.assert_allclose(points, _rotated(frames[0], angle), atol=bound * radians * 5e-3 + VTK)


def test_h5_trajectory_reads_back(tmp_path):
    """.h5 frames go through PyGran's H5MD writer; free fall is exact under velocity Verlet."""
    out = tmp_path / "h5"
    with dem(out, gravity=(G, 0, 0, -1), traj={"freq": 100, "pfile": "traj.h5"}) as sim:
        for x in (-0.004, 0.0, 0.004):
            sim.createParticles(1, "single", x, 0.0, 0.02)
        sim.run(300)
        sim.run(200)
        final = sim.extractCoords()
    with analysis.System(Particles=str(out / "traj.h5")) as system:
        assert len(system) == 6
        assert list(system) == [1, 2, 3, 4, 5]  # as the original: the frames after the first
        steps = []
        for _ in system.frames():
            particles = system.Particles
            steps.append(particles.timestep)
            t = particles.timestep * DT
            np.testing.assert_allclose(particles.z, 0.02 - G * t**2 / 2, rtol=0, atol=1e-12)
            np.testing.assert_allclose(particles.x, [-0.004, 0.0, 0.004], atol=1e-15)
            np.testing.assert_allclose(particles.radius, R)
        assert steps == [0, 100, 200, 300, 400, 500]
        system.goto(-1)
        np.testing.assert_array_equal(system.Particles.positions, final)


def test_viscous_drag_gives_terminal_velocity(tmp_path):
    """fix viscous is F = -gamma * scale * v: m dv/dt = m g - gamma v, terminal velocity
    m g / gamma reached as 1 - exp(-t / tau), tau = m / gamma. Species 2 has no drag; a sphere
    of species 1 created after addViscous has it too."""
    tau = 0.01
    gamma = MASS / tau / 2  # scale=2 below
    species = ({"material": MATERIAL, "radius": R}, {"material": MATERIAL, "radius": R})
    with dem(tmp_path, gravity=(G, 0, 0, -1), species=species) as sim:
        sim.createParticles(1, "single", -0.005, 0.0, 0.025)
        sim.createParticles(2, "single", 0.005, 0.0, 0.025)
        sim.engine.expect_outflow("z-")  # the sphere without drag falls out of the box
        sim.addViscous(gamma=gamma, scale=2, species=1)
        sim.createParticles(1, "single", 0.0, 0.005, 0.025)
        sim.run(round(tau / DT))
        v = sim.extractVelocities()[:, 2]
        assert -v[0] == pytest.approx(G * tau * (1 - math.exp(-1)), rel=0.01)
        assert -v[1] == pytest.approx(G * tau, rel=1e-9)  # free fall
        assert v[2] == v[0]
        sim.run(round(9 * tau / DT))
        assert -sim.extractVelocities()[0, 2] == pytest.approx(MASS * G / (2 * gamma), rel=1e-3)


def test_random_creation_clears_particles_and_walls(tmp_path):
    region = ("block", -0.005, 0.005, -0.005, 0.005, 0.0, 0.01)
    with dem(tmp_path) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.004)
        assert sim.createParticles(1, "single", 0.0, 0.0, 0.002) == 1
        assert sim.createParticles(1, "random", 40, region=region, radius=5e-4, vel=(0, 0, -0.1)) == 40
        x, r, v = sim.extractCoords(), sim.extractRadii(), sim.extractVelocities()
        mass = sim.engine.extract("mass")
    assert len(x) == 41
    assert np.all(r[1:] == 5e-4) and r[0] == R
    gaps = np.linalg.norm(x[:, None] - x[None], axis=-1) - (r[:, None] + r[None])
    assert gaps[~np.eye(len(x), dtype=bool)].min() >= 0  # no overlaps, the single one included
    assert np.all(np.abs(x[:, 2] - 0.004) >= r)  # clear of the plane wall
    inside = np.all(
        (x[1:] >= [-0.005, -0.005, 0] + r[1:, None]) & (x[1:] <= [0.005, 0.005, 0.01] - r[1:, None])
    )
    assert inside
    np.testing.assert_array_equal(v[1:], np.tile([0, 0, -0.1], (40, 1)))
    assert mass[1] == pytest.approx(4 / 3 * math.pi * 5e-4**3 * MATERIAL["density"], rel=1e-12)


def test_spinning_sphere_ends_rolling_at_two_sevenths(tmp_path):
    """A sphere spinning at omega0 without moving, set on a floor, ends rolling at 2/7 r omega0
    (angular momentum about the contact point), whatever the friction."""
    omega0 = 10.0
    with dem(tmp_path / "spin", gravity=(G, 0, 0, -1)) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, R, omega=(0, omega0, 0))
        np.testing.assert_array_equal(sim.extractOmegas(), [[0, omega0, 0]])
        sim.run(5000)
        v, w = sim.extractVelocities()[0], sim.extractOmegas()[0]
    assert v[0] == pytest.approx(2 / 7 * R * omega0, rel=0.01)
    assert w[1] * R == pytest.approx(v[0], rel=0.01)  # rolling without slip
    assert "# PyGran: omega 0 10 0 given to atoms 1*1" in (tmp_path / "spin" / "in.pygran").read_text()


def test_omega_on_two_ranks(tmp_path):
    """Angular velocities written into LIGGGHTS' arrays reach atoms on both ranks (the box is
    split in z) and stay through runs (no torque without contacts)."""
    with dem(tmp_path, nprocs=2) as sim:
        region = ("block", -0.005, 0.005, -0.002, 0.002, 0.002, 0.028)
        # sites at x = -3, 1 mm, y = 0, z = 4, 8, ..., 24 mm
        assert sim.createParticles(1, "lattice", 0.004, region=region, omega=(1, 2, 3)) == 12
        x = sim.extractCoords()
        assert x[:, 2].min() < 0.015 < x[:, 2].max()
        assert sim.set(region=("block", 0, 0.01, -0.01, 0.01, 0, 0.03), omega=(4, 5, 6)) == 6
        sim.run(100)
        w = sim.extractOmegas()
        assert sim.createParticles(1, "single", 0.0, 0.005, 0.02, omega=(0, 0, -5)) == 1
        sim.run(100)
        w_new = sim.extractOmegas()
    right = x[:, 0] > 0
    np.testing.assert_array_equal(w[right], np.tile([4, 5, 6], (6, 1)))
    np.testing.assert_array_equal(w[~right], np.tile([1, 2, 3], (6, 1)))
    np.testing.assert_array_equal(w_new[:-1], w)
    np.testing.assert_array_equal(w_new[-1], [0, 0, -5])


def test_run_chunks_with_pre_no_match_one_run(tmp_path):
    """A run split into chunks (``run N pre no`` after the first) gives what one run gives."""
    results = []
    for chunks in (1, 10):
        with dem(tmp_path / f"chunks{chunks}", gravity=(G, 0, 0, -1)) as sim:
            sim.engine.max_run_chunks = chunks
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            region = ("block", -0.004, 0.004, -0.004, 0.004, 0.002, 0.008)
            sim.createParticles(1, "lattice", 0.0025, region=region)
            sim.run(3000)
            results.append(sim.extractCoords())
        runs = (tmp_path / f"chunks{chunks}" / "in.pygran").read_text().count("pre no")
        assert runs == chunks - 1
    assert len(results[0]) == 18  # x, y at -2.75, -0.25, 2.25 mm; z at 3.25, 5.75 mm
    np.testing.assert_array_equal(results[0], results[1])


def test_particles_created_one_by_one_stream_to_liggghts(tmp_path):
    """Once the worker is up, every 1000 queued lines of particles created one by one go to
    LIGGGHTS without waiting; their ``set atom`` lines are ranges. (1100 sites of a lattice of
    spacing 2.05 mm, in random order, so that no two spheres overlap.)"""
    axes = [np.arange(-8.2e-3, 8.3e-3, 2.05e-3)] * 2 + [np.arange(1.025e-3, 0.029, 2.05e-3)]
    sites = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    centres = np.random.default_rng(7).permutation(sites)[:1100]
    with dem(tmp_path) as sim:
        assert len(sim.extractIds()) == 0  # waits for the worker
        for k, centre in enumerate(centres):
            sim.createParticles(1, "single", *centre, vel=(0, 0, -0.5) if k < 1050 else (0, 0, 0))
        x, v, ids = sim.extractCoords(), sim.extractVelocities(), sim.extractIds()
        mass = sim.engine.extract("mass")
    np.testing.assert_array_equal(ids, np.arange(1, 1101))
    np.testing.assert_array_equal(x, centres)
    np.testing.assert_array_equal(v[:, 2], np.where(ids <= 1050, -0.5, 0.0))
    np.testing.assert_allclose(mass, MASS, rtol=1e-12)
    sets = [line for line in (tmp_path / "in.pygran").read_text().splitlines() if line.startswith("set")]
    assert sets == [
        "set atom 1*1000 diameter 0.002 density 2500 vx 0 vy 0 vz -0.5",
        "set atom 1001*1050 diameter 0.002 density 2500 vx 0 vy 0 vz -0.5",
        "set atom 1051*1100 diameter 0.002 density 2500",
    ]


def test_create_many_single_particles_from_an_array(tmp_path):
    grid = np.stack(np.meshgrid(np.linspace(-0.0075, 0.0075, 6), np.linspace(-0.005, 0.005, 5)), axis=-1)
    positions = np.column_stack([grid.reshape(-1, 2), np.full(30, 0.01)])  # 2.5 mm apart
    with dem(tmp_path) as sim:
        assert sim.createParticles(1, "single", positions, vel=(0, 0, -0.5)) == 30
        np.testing.assert_array_equal(sim.extractIds(), np.arange(1, 31))
        np.testing.assert_array_equal(sim.extractCoords(), positions)
        np.testing.assert_array_equal(sim.extractVelocities()[:, 2], -0.5)
        np.testing.assert_array_equal(sim.extractRadii(), R)


def test_dump_settings_reach_liggghts(tmp_path):
    """nns_type and dump_modify are LIGGGHTS' own (dump_modify's words, as PyGran 1.x wrote
    them, on one line); traj sel picks the species at every frame, so particles inserted after
    the dump was set up are in it too."""
    species = ({"material": MATERIAL, "radius": R}, {"material": MATERIAL, "radius": R})
    traj = {"freq": 100, "pfile": "traj.dump", "sel": 2, "args": ("id", "type", "x", "y", "z")}
    region = ("block", -0.009, 0.009, -0.009, 0.009, 0.002, 0.028)
    with dem(
        tmp_path, species=species, nns_type="nsq", dump_modify=("append", "yes", "sort", "id"), traj=traj
    ) as sim:
        sim.insert(species=(1, 2), value=20, region=region)
        sim.run(200)
        types = sim.engine.extract("type")
    text = (tmp_path / "in.pygran").read_text()
    assert "neighbor 0.001 nsq\n" in text and "dump_modify pg_dump append yes sort id\n" in text
    with analysis.System(Particles=str(tmp_path / "traj.dump")) as system:
        system.goto(-1)
        ids = system.Particles.id
    assert 0 < (types == 2).sum() < 20
    np.testing.assert_array_equal(ids, np.flatnonzero(types == 2) + 1)  # sorted by id, species 2 only


def test_particles_of_the_second_species_only(tmp_path):
    """LIGGGHTS wants some atom or fix of type 1 ('Atom types must start from 1'): a simulation
    whose particles are all of species 2 runs (free fall, exact under velocity Verlet)."""
    species = ({"material": MATERIAL, "radius": R}, {"material": MATERIAL, "radius": 2 * R})
    with dem(tmp_path, species=species, gravity=(G, 0, 0, -1)) as sim:
        sim.createParticles(2, "single", 0.0, 0.0, 0.02)
        sim.run(1000)
        z = sim.extractCoords()[0, 2]
    assert z == pytest.approx(0.02 - G * (1000 * DT) ** 2 / 2, rel=1e-12)


def test_a_lattice_fills_its_region_with_whole_spheres(tmp_path):
    """createParticles 'lattice' of spacing 2.5 mm in a block 10 mm x 5 mm x 7 mm from (-5, -2, 1)
    mm: sites from each lower bound plus half a spacing where a sphere of 1 mm lies wholly
    inside (4 x 2 x 2 = 16; at z = 7.25 mm it would reach 8.25 > 8), as every engine places them."""
    region = ("block", -0.005, 0.005, -0.002, 0.003, 0.001, 0.008)
    with dem(tmp_path) as sim:
        assert sim.createParticles(1, "lattice", 0.0025, region=region) == 16
        x = sim.extractCoords()
    xs, ys, zs = (-3.75e-3, -1.25e-3, 1.25e-3, 3.75e-3), (-0.75e-3, 1.75e-3), (2.25e-3, 4.75e-3)
    expected = sorted((a, b, c) for a in xs for b in ys for c in zs)
    np.testing.assert_allclose(sorted(map(tuple, x)), expected, atol=1e-12)
    assert "lattice sc" not in (tmp_path / "in.pygran").read_text()


@pytest.mark.parametrize("nprocs", [1, 2])
@pytest.mark.parametrize(("chosen", "expected"), [(None, "^cm"), ("ob1", "ob1")])
def test_the_worker_leaves_out_open_mpis_cm_pml_unless_the_user_chose_one(
    tmp_path, monkeypatch, nprocs, chosen, expected
):
    """The cm PML probes PSM, PSM2 and libfabric at each start (0.2 s of every simulation's
    start-up); a PML the environment chooses is kept. Read from the worker job's own
    environment, and the job runs either way."""
    monkeypatch.delenv("OMPI_MCA_mtl", raising=False)
    if chosen is None:
        monkeypatch.delenv("OMPI_MCA_pml", raising=False)
    else:
        monkeypatch.setenv("OMPI_MCA_pml", chosen)
    with dem(tmp_path, nprocs=nprocs) as sim:
        environ = (Path("/proc") / str(sim.engine._channel.session.process.pid) / "environ").read_bytes()
        assert f"OMPI_MCA_pml={expected}".encode() in environ.split(b"\0")
        assert sim.createParticles(1, "single", 0.0, 0.0, 0.01, vel=(0.0, 0.0, -1.0)) == 1
        sim.run(10)
        assert sim.extractCoords()[0, 2] == pytest.approx(0.01 - 10 * DT)


def test_beds_from_arrays_on_two_ranks_beside_mesh_walls(tmp_path):
    """LIGGGHTS 3.8 crashes when ``read_dump`` moves new atoms between ranks beside contact
    histories: on 2 ranks with a mesh wall, and again after a run (the pair style's), a bed
    from an array still comes out whole, each particle where it was asked, and settles on
    the mesh floor."""
    floor = np.array([[[-0.01, -0.01, 0.0], [0.01, -0.01, 0.0], [0.01, 0.01, 0.0]],
                      [[-0.01, -0.01, 0.0], [0.01, 0.01, 0.0], [-0.01, 0.01, 0.0]]])  # fmt: skip
    grid = np.arange(-0.0075, 0.0076, 0.0025)
    first = np.array([(x, y, z) for x in grid for y in grid for z in (0.004, 0.008, 0.022, 0.026)])
    second = np.array([(x, y, z) for x in grid for y in grid for z in (0.013, 0.017)])
    with dem(tmp_path, nprocs=2, mesh={"floor": {"triangles": floor, "material": MATERIAL}}) as sim:
        assert sim.createParticles(1, "single", first) == len(first)  # below and above z = 0.015
        np.testing.assert_allclose(sim.extractCoords(), first, atol=1e-12)
        sim.run(100)
        assert sim.createParticles(1, "single", second) == len(second)
        assert len(sim.extractIds()) == len(first) + len(second)
        np.testing.assert_allclose(sim.extractCoords()[len(first) :], second, atol=1e-12)
        sim.run(3000)
        assert sim.extractCoords()[:, 2].min() > R * 0.9  # held by the mesh floor
    log = (tmp_path / "pygran.log").read_text()
    assert log.count("created one by one") == 2
