"""Multisphere species on the native engine's clumps: mass properties of the union, a free
body's rotation, clumps at rest on a floor (and where LIGGGHTS puts them), insertion, restart
and threads."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from pygran_liggghts.library import find_library
from pygran_native.solver import Solver

from pygran_core import params, simulation
from pygran_core.errors import ConfigError, UnsupportedFeature
from pygran_core.simulation.clumps import mass_properties
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import union_properties

R = 1e-3
#: The stock organic material (E = 10 MPa), less bouncy so that a dropped clump settles fast.
MATERIAL = dict(params.organic, coefficientRestitution=0.5)
#: An asymmetric clump of overlapping spheres of three sizes.
LUMP = [(0.0, 0.0, 0.0, R), (1.2 * R, 0.3 * R, 0.0, 0.8 * R), (0.4 * R, 1.1 * R, 0.5 * R, 1.2 * R)]
#: A straight rod of four spheres, 1.5 R apart (each overlapping the next).
ROD = [(1.5 * R * (k - 1.5), 0.0, 0.0, R) for k in range(4)]


def lump():
    return LUMP


def rod():
    return ROD


def dem(tmp_path, species, engine="native", **extra):
    settings = dict(
        engine=engine,
        model=HertzMindlin,
        box=(-0.01, 0.01, -0.01, 0.01, 0.0, 0.02),
        species=species,
        dt=5e-6,
        output=str(tmp_path / engine),
        traj={"pfile": None},
        progress=False,
    )
    if engine == "native":
        settings["threads"] = 1
    return simulation.DEM(**(settings | extra))


def test_clump_mass_centre_and_inertia_are_those_of_the_union(tmp_path):
    """A clump's mass, centre and inertia are those of the union of its spheres (within 0.5 % of
    a Monte Carlo integral in the bounding box, 2e6 samples), where the sum of the spheres'
    masses is 19 % too heavy; its spheres are where the template puts them, each with its mass."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": lump},)
    with dem(tmp_path, species) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.01)
        found, x, mass = sim.engine.clumps(), sim.extractCoords(), sim.engine.extract("mass")
        bodies = sim.engine.bodies()
    density = MATERIAL["density"]
    expected_mass, expected_centre, expected_inertia = union_properties(LUMP, density)
    summed = density * sum(4 / 3 * math.pi * r**3 for *_, r in LUMP)
    assert summed > 1.15 * expected_mass  # the overlaps matter
    assert found["mass"][0] == pytest.approx(expected_mass, rel=0.005)
    np.testing.assert_allclose(found["centre"][0] - [0, 0, 0.01], expected_centre, atol=0.005 * R)
    assert np.abs(found["inertia"][0] - expected_inertia).max() < 0.005 * np.linalg.norm(expected_inertia)
    np.testing.assert_allclose(x, np.array(LUMP)[:, :3] + [0, 0, 0.01], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(mass, found["mass"][0])
    assert bodies.tolist() == [1, 1, 1]
    # two touching spheres: the Monte Carlo is exact for spheres that do not overlap
    pair = mass_properties([(0, 0, 0, R), (2 * R, 0, 0, R)], density)
    assert pair.mass == pytest.approx(2 * density * 4 / 3 * math.pi * R**3, rel=1e-12)


def test_a_free_clump_spinning_about_a_non_principal_axis_conserves_momentum_and_energy(tmp_path):
    """The lump spinning at 250 rad/s about an axis that is not principal (11 degrees off its
    angular momentum) tumbles (its angular velocity turns by more than 0.1 rad) for 10^5 steps
    of 1 us: its angular momentum and its kinetic energy stay what they were to 1e-6, its
    centre moves on at its velocity, and its spheres keep the template's distances."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": lump},)
    with dem(tmp_path, species, dt=1e-6) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.01, vel=(0.01, 0.0, 0.0), omega=(0.0, 250.0, 0.0))

        def now():
            body = sim.engine.clumps()
            inertia, omega, v = body["inertia"][0], body["omega"][0], body["velocity"][0]
            energy = 0.5 * body["mass"][0] * v @ v + 0.5 * omega @ inertia @ omega
            return inertia @ omega, energy, omega, sim.extractCoords(), body["centre"][0]

        momentum, energy, omega, x, centre = now()
        sim.run(100_000)
        momentum_end, energy_end, omega_end, x_end, centre_end = now()
        ke = sim.monitor(quantities=("ke", "ke_rot"), freq=1)
        sim.run(1)
    assert np.linalg.norm(np.cross(momentum, omega)) > 0.15 * np.linalg.norm(momentum) * np.linalg.norm(omega)
    assert math.acos(omega @ omega_end / np.linalg.norm(omega) / np.linalg.norm(omega_end)) > 0.1
    assert np.linalg.norm(momentum_end - momentum) < 1e-6 * np.linalg.norm(momentum)
    assert energy_end == pytest.approx(energy, rel=1e-6)
    assert ke.values["ke"][-1] + ke.values["ke_rot"][-1] == pytest.approx(energy, rel=1e-6)

    def distances(p):
        return np.linalg.norm(p[:, None] - p[None], axis=-1)

    np.testing.assert_allclose(distances(x_end), distances(x), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(centre_end - centre, [0.01 * 0.1, 0, 0], rtol=1e-9, atol=1e-15)


def drop(tmp_path, species, orientation, engine="native", seed=1, steps=40000):
    """One particle of ``species`` inserted with ``orientation`` around (0, 0, 5 mm) and dropped
    on a floor for ``steps`` steps of 5 us; its spheres before and after."""
    region = ("block", -1e-4, 1e-4, -1e-4, 1e-4, 5e-3 - 1e-4, 5e-3 + 1e-4)
    with dem(tmp_path, species, engine=engine, gravity=(9.81, 0, 0, -1), seed=seed) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=1, region=region, args={"orientation": orientation}, all_in=False)
        sim.run(1)
        start = sim.extractCoords()
        sim.run(steps)
        return start, sim.extractCoords(), sim.extractVelocities()


def pose(x):
    """Height of the centre, and angle (degrees) of the axis to the floor, of a straight chain of spheres."""
    axis = x[-1] - x[0]
    return x[:, 2].mean(), math.degrees(math.asin(abs(axis[2]) / np.linalg.norm(axis)))


def test_tablet_dropped_on_a_floor_ends_on_its_flat_face(tmp_path):
    """A multisphere tablet (3 spheres of radius R over 5 R) dropped in a random orientation
    ends lying on the floor: every sphere one radius high (within a hundredth of a radius)."""
    species = (
        {"style": "multisphere/tablet", "material": MATERIAL, "nspheres": 3, "radius": R, "length": 5 * R},
    )
    start, x, v = drop(tmp_path, species, "random")
    assert pose(start)[1] > 5  # it started tilted
    assert np.all(np.abs(x[:, 2] - R) < 0.01 * R), x
    assert np.abs(v).max() < 1e-3


def test_rod_comes_to_rest_where_liggghts_puts_it(tmp_path):
    """A 4-sphere rod dropped from 5 mm with its axis 30 degrees from the floor comes to rest
    lying flat, each of its spheres where LIGGGHTS' multisphere puts it within a tenth of a radius."""
    require_solver(find_library)
    species = ({"style": "multisphere", "material": MATERIAL, "function": rod},)
    half = math.radians(30) / 2  # a turn of 30 degrees about y
    tilt = ("constant", math.cos(half), 0.0, math.sin(half), 0.0)
    region_centre = np.array([0.0, 0.0, 5e-3])
    rests = {}
    for engine in ("native", "liggghts"):
        start, x, v = drop(tmp_path, species, tilt, engine=engine, steps=30000)
        assert pose(start)[1] == pytest.approx(30, abs=1e-6)
        # LIGGGHTS and the native engine each place the rod somewhere in the small region
        rests[engine] = x - (start.mean(axis=0) - region_centre)
        height, angle = pose(x)
        assert height == pytest.approx(R, abs=0.01 * R) and angle < 0.5, (engine, x)
    shift = np.abs(rests["native"] - rests["liggghts"]).max()
    assert shift < 0.1 * R, rests
    travel = np.abs(rests["native"] - (start - (start.mean(axis=0) - region_centre))).max()
    assert travel > 3 * R  # it fell and slid: agreeing on where it stopped means something


def test_insertion_places_turned_clumps_without_overlaps_and_counts_each_once(tmp_path):
    """Rods inserted in random orientations lie wholly in the region, no two overlapping; a
    second insert(value=10) adds 10 rods to the 20 there (each counted once, not per sphere);
    the same seed gives the same rods."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": rod},)
    region = ("block", -0.019, 0.019, -0.019, 0.019, 1e-3, 0.039)
    found = []
    for run in range(2):
        with dem(tmp_path / str(run), species, seed=3, box=(-0.02, 0.02, -0.02, 0.02, 0.0, 0.04)) as sim:
            sim.insert(species=1, value=20, region=region)
            x, bodies = sim.extractCoords(), sim.engine.bodies()
            sim.run(1)
            sim.insert(species=1, value=10, region=region)
            total = len(np.unique(sim.engine.bodies()))
            found.append(x)
    assert len(np.unique(bodies)) == 20 and len(x) == 20 * len(ROD)
    np.testing.assert_array_equal(found[0], found[1])
    lo, hi = np.array(region[1::2]), np.array(region[2::2])
    assert np.all((x - R >= lo - 1e-12) & (x + R <= hi + 1e-12))
    gaps = np.linalg.norm(x[:, None] - x[None], axis=-1) - 2 * R
    other = bodies[:, None] != bodies[None]
    assert gaps[other].min() > 0
    axes = np.array([x[bodies == b][-1] - x[bodies == b][0] for b in np.unique(bodies)])
    assert np.abs(axes[:, 2]).max() > 0.5 * np.linalg.norm(axes[0])  # turned, not all in the template's
    assert total == 30


def test_refusals(tmp_path):
    """What the native engine does not do with clumps is refused by name."""
    species = (
        {"style": "multisphere", "material": MATERIAL, "function": rod},
        {"material": MATERIAL, "radius": R},
    )
    with dem(tmp_path, species) as sim:
        with pytest.raises(UnsupportedFeature, match="clumps by number"):
            sim.insert(
                species=1,
                value=0.1,
                mech="volumefraction_region",
                region=("block", -5e-3, 5e-3, -5e-3, 5e-3, 5e-3, 1.5e-2),
            )
        sim.createParticles(1, "single", 0.0, 0.0, 0.01)
        sim.createParticles(2, "single", 0.0, 0.0, 0.005)
        with pytest.raises(UnsupportedFeature, match=r"set\(\) on the spheres of multisphere species \[1\]"):
            sim.set(vel=(0, 0, 1))
        assert sim.set(species=2, vel=(0, 0, 1)) == 1
        with pytest.raises(ConfigError, match="leave radius out"):
            sim.createParticles(1, "single", 0.0, 0.0, 0.015, radius=R)


def rods(output, restart, threads=1):
    """Four rods inserted above a floor and dropped, checkpointed every 3000 steps."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": rod},)
    with dem(output, species, restart=restart, threads=threads, gravity=(9.81, 0, 0, -1)) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=4, region=("block", -8e-3, 8e-3, -8e-3, 8e-3, 1e-3, 1.9e-2))
        sim.run(6000)
        sim.run(6000)
        return sim.extractCoords(), sim.extractVelocities(), sim.engine.clumps()


def test_a_resumed_simulation_of_clumps_continues_bitwise(tmp_path):
    """Resumed from its checkpoint at step 9000, with the rods in contact with the floor and
    one another, the script ends with the same bits as without the resume."""
    x, v, bodies = rods(tmp_path, (3000, "restart", "restart.*.h5"))
    assert np.abs(bodies["force"]).max() > 0 and x[:, 2].min() < R  # they reached the floor
    again = rods(tmp_path, (3000, "restart", "restart.*.h5", True, "restart.9000.h5"))
    assert "resumed from" in (tmp_path / "native" / "pygran.log").read_text()
    np.testing.assert_array_equal(again[0], x)
    np.testing.assert_array_equal(again[1], v)
    for key, value in bodies.items():
        np.testing.assert_array_equal(again[2][key], value, err_msg=key)


# A heap of 64 lumps and 64 spheres settling in a periodic box on a floor for 1500 steps, with
# the threads given (on one CPU when told to); saves the particles' and the clumps' state.
SCRIPT = """
import os, sys
import numpy as np
from pygran_native.solver import Solver

if sys.argv[3] == "one-cpu":
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
R, a = 1e-3, 4e-3
lump = [(0.0, 0.0, 0.0, R), (1.2 * R, 0.3 * R, 0.0, 0.8 * R), (0.4 * R, 1.1 * R, 0.5 * R, 1.2 * R)]
s = Solver(box=[[0, 0, 0], [4 * a, 4 * a, 10 * a]], periodic=(True, True, False), gravity=(0, 0, -9.81),
           skin=4e-4, threads=int(sys.argv[2]), seed=2)
s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5)
s.add_plane((0, 0, 0), (0, 0, 1))
grid = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
q = s.rng.normal(size=(64, 4))
s.add_clumps(lump, (grid + 0.3) * a + [0, 0, a], 2500, orientations=q / np.linalg.norm(q, axis=1)[:, None],
             velocities=s.rng.normal(0, 0.2, (64, 3)))
s.add_particles((grid + 0.8) * a + [0, 0, a], R, densities=2500)
s.run(700, 1e-5)
s.run(800, 1e-5)
b = s.clumps()
np.save(sys.argv[1], np.concatenate([s.positions.ravel(), s.velocities.ravel(), s.forces.ravel(),
                                     b["centre"].ravel(), b["orientation"].ravel(), b["omega"].ravel()]))
"""


def settle(tmp_path, threads: int, cpus: str = "all") -> np.ndarray:
    out = tmp_path / f"{threads}-{cpus}.npy"
    subprocess.run([sys.executable, "-c", SCRIPT, str(out), str(threads), cpus], check=True)
    return np.load(out)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this system")
def test_clumps_have_the_same_bits_whichever_thread_runs_a_block(tmp_path):
    """Two threads give the same bits on one CPU (taking turns) as on two; one thread sums in
    another order, so it ends near but not on the same bits."""
    two = settle(tmp_path, 2)
    np.testing.assert_array_equal(settle(tmp_path, 2, "one-cpu"), two)
    one = settle(tmp_path, 1)
    assert not np.array_equal(one, two)
    n = 64 * 3 + 64
    assert np.abs(one[: 3 * n] - two[: 3 * n]).max() < 1e-4


def test_solver_clumps_lost_whole_and_wrapped_whole():
    """At the solver: a clump crossing a periodic boundary keeps its shape, one falling through
    the bottom of the box is deleted whole and counted once; clumps' spheres cannot be set."""
    s = Solver(
        box=[[0, 0, 0], [0.02, 0.02, 0.02]], periodic=(True, False, False), gravity=(0, 0, -9.81), skin=2e-4
    )
    s.set_contact_model("hertz", youngs=1e7, poisson=0.3, restitution=0.5)
    ids = s.add_clumps(
        ROD, [[0.018, 0.01, 0.01], [0.005, 0.01, 0.003]], 1000, velocities=[[1, 0, 0.5], [0, 0, -1]]
    )
    assert ids.tolist() == [0, 1] and s.bodies.tolist() == [0] * 4 + [1] * 4
    with pytest.raises(ConfigError, match="spheres of clumps"):
        s.set_velocities([0], [[0, 0, 0]])
    s.run(2000, 1e-5)  # 20 ms: the first clump crosses x = 0.02, the second leaves through z = 0
    where, _ = s.take_lost()
    assert s.lost == 1 and where == {"z-": 1} and s.n == 4 and s.bodies.tolist() == [0] * 4
    x = s.positions
    assert x[:, 0].min() < 0.002 and x[:, 0].max() > 0.018  # across the boundary
    gaps = np.diff(np.sort((x[:, 0] - x[0, 0] + 0.01) % 0.02))
    np.testing.assert_allclose(gaps, 1.5 * R, rtol=1e-9)


def test_solver_clumps_feel_gravity_and_drag_as_bodies():
    """A rod falling against viscous drag gamma reaches its terminal speed M g / gamma (after ten
    relaxation times M / gamma, to 1e-4), the drag acting once on the body, not per sphere."""
    s = Solver(box=[[-0.01] * 3, [0.01] * 3], gravity=(0, 0, -9.81), skin=2e-4, threads=1)
    s.set_contact_model("hertz", youngs=1e7, poisson=0.3, restitution=0.5)
    s.add_clumps(ROD, [[0.0, 0.0, 0.005]], 1000)
    mass = s.clumps()["mass"][0]
    s.set_viscous(mass / 1e-3)  # relaxation time 1 ms
    s.run(10_000, 1e-6)
    velocity = s.clumps()["velocity"][0]
    np.testing.assert_allclose(velocity, [0, 0, -9.81e-3], rtol=1e-4, atol=1e-15)
    np.testing.assert_allclose(s.velocities, np.tile(velocity, (4, 1)), rtol=1e-12)
