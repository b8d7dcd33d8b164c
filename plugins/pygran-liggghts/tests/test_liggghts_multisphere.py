"""Multisphere species on real LIGGGHTS (fix multisphere, particletemplate/multisphere): rigid
clumps of spheres inserted with a random orientation, beside species of single spheres."""

import shutil

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import analysis, simulation
from pygran_core.errors import UnsupportedFeature
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT as MATERIAL

G, R = 9.81, 1e-4


def rod():
    """Four touching spheres in a line: PyGran 1.x's 'function' form."""
    return [(2 * R * i, 0.0, 0.0, R) for i in range(4)]


def dem(output, species, **params):
    require_solver(find_library)
    settings = {
        "engine": "liggghts",
        "model": "HertzMindlin",
        "box": (-5e-3, 5e-3, -5e-3, 5e-3, 0, 2e-2),
        "gravity": (G, 0, 0, -1),
        "dt": 1e-6,
        "output": str(output),
        "species": species,
        "traj": {"pfile": None},
        "progress": False,
    }
    return simulation.DEM(**settings | params)


def by_body(x, bodies):
    """The sphere centres of each body, in the order of their ids."""
    return [x[bodies == body] for body in np.unique(bodies[bodies > 0])]


def test_a_rod_falls_and_lands_as_one_rigid_body(tmp_path):
    """A rod of four spheres, inserted spinning with a random orientation, falls 15 mm onto
    the floor and comes to rest: every distance between its spheres stays what the template
    says (1e-9 relative) while it turns; a single sphere created beside it falls freely
    meanwhile (it is integrated by nve/sphere, the rod's spheres by fix multisphere only).
    Until the rod lands, the kinetic energy (the rod's from LIGGGHTS' computes, each of its
    spheres carrying the rod's mass) grows by what both lose in potential energy."""
    species = (
        {"material": MATERIAL, "style": "multisphere", "function": rod},
        {"material": MATERIAL, "radius": R},
    )
    template = np.array(rod())[:, :3]
    expected = np.linalg.norm(template[:, None] - template[None], axis=-1)
    with dem(tmp_path, species, traj={"pfile": "traj.dump", "freq": 10000}) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(2, "single", 3e-3, 3e-3, 1.5e-2)
        region = ("block", -2e-3, 2e-3, -2e-3, 2e-3, 1.4e-2, 1.8e-2)
        sim.insert(species=1, value=1, region=region, args={"orientation": "random"}, omega=(0, 50, 30))
        ke = sim.monitor(quantities=("ke",), freq=5000, file="ke.txt")
        frames = []
        for _ in range(16):
            sim.run(5000)
            frames.append((sim.time, sim.extractCoords(), sim.engine.bodies()))
        types, mass = sim.engine.extract("type"), sim.engine.extract("mass")
    assert types.tolist() == [2, 1, 1, 1, 1] and frames[0][2].tolist() == [-1, 1, 1, 1, 1]
    for t, x, bodies in frames:
        (spheres,) = by_body(x, bodies)
        distances = np.linalg.norm(spheres[:, None] - spheres[None], axis=-1)
        np.testing.assert_allclose(distances, expected, rtol=1e-9, atol=1e-9 * R)
        fall = 1.5e-2 - G * t**2 / 2
        if fall > R:  # the single sphere in free fall, exact under velocity Verlet
            assert x[0, 2] == pytest.approx(fall, rel=1e-12)
    # the rod's mass (each of its spheres has it) against its four spheres' (LIGGGHTS' Monte Carlo)
    assert mass[1:] == pytest.approx(np.full(4, 4 * mass[0]), rel=2e-3)
    heights = np.array([[x[0, 2], by_body(x, b)[0][:, 2].mean()] for _, x, b in frames])
    for k in range(1, 5):  # all in flight until step 25000
        gained = ke.values["ke"][k + 1] - ke.values["ke"][1]
        assert gained == pytest.approx(G * (heights[0] - heights[k]) @ mass[:2], rel=1e-3)
    first = by_body(frames[0][1], frames[0][2])[0]
    last = by_body(frames[-1][1], frames[-1][2])[0]
    assert first[:, 2].min() > 1e-2 and last[:, 2].min() < 1.1 * R  # it fell onto the floor
    axes = [np.ptp(by_body(x, b)[0], axis=0) for _, x, b in frames[:3]]
    assert not np.allclose(axes[0], axes[2], atol=1e-5)  # and turned on the way
    # LIGGGHTS' own dump has the body of each sphere (column mol): -1 for single spheres
    with analysis.System(Particles=str(tmp_path / "traj.dump")) as system:
        system.goto(-1)
        particles = system.Particles
        np.testing.assert_array_equal(particles.mol[np.argsort(particles.id)], [-1, 1, 1, 1, 1])


def test_tablets_settle_flat_on_the_floor(tmp_path):
    """Three tablets (five overlapping spheres of 0.2 mm along 1.6 mm, PyGran 1.x's
    multisphere/tablet), dropped with random orientations from 1 to 5 mm, end lying flat: their
    long axes horizontal (to 1e-3), every sphere on the floor."""
    radius = 2e-4
    tablet = {
        "material": MATERIAL,
        "style": "multisphere/tablet",
        "nspheres": 5,
        "radius": radius,
        "length": 1.6e-3,
    }
    with dem(tmp_path, (tablet,), dt=2e-6, box=(-5e-3, 5e-3, -5e-3, 5e-3, 0, 6e-3)) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        region = ("block", -4e-3, 4e-3, -4e-3, 4e-3, 1e-3, 5e-3)
        sim.insert(species=1, value=3, region=region, args={"orientation": "random"})
        sim.run(1)
        start = by_body(sim.extractCoords(), sim.engine.bodies())
        sim.run(30000)
        tablets = by_body(sim.extractCoords(), sim.engine.bodies())
        speed = np.abs(sim.extractVelocities()).max()
    assert len(tablets) == 3 and all(len(spheres) == 5 for spheres in tablets)
    tilt = [abs(t[-1] - t[0])[2] / np.linalg.norm(t[-1] - t[0]) for t in start]
    assert max(tilt) > 0.2  # they started tilted
    for spheres in tablets:
        axis = spheres[-1] - spheres[0]
        assert np.linalg.norm(axis) == pytest.approx(1.6e-3 - 2 * radius, rel=1e-9)
        assert abs(axis[2]) / np.linalg.norm(axis) < 1e-3
        np.testing.assert_allclose(spheres[:, 2], radius, rtol=1e-2)
    assert speed < 1e-3


def test_multisphere_particles_are_made_by_insertion_only(tmp_path):
    """LIGGGHTS has no command creating a clump at a position; its spheres move with it."""
    species = (
        {"material": MATERIAL, "style": "multisphere", "function": rod},
        {"material": MATERIAL, "radius": R},
    )
    with dem(tmp_path, species) as sim:
        with pytest.raises(UnsupportedFeature, match="multisphere particles .* only by insertion"):
            sim.createParticles(1, "single", 0, 0, 1e-2)
        sim.insert(species=1, value=2, region=("block", -4e-3, 4e-3, -4e-3, 4e-3, 5e-3, 1.5e-2))
        sim.createParticles(2, "single", 0, 0, 1.8e-2)
        sim.run(10)
        with pytest.raises(UnsupportedFeature, match=r"set\(\) on the spheres of multisphere species \[1\]"):
            sim.set(vel=(0, 0, 1))
        assert sim.set(species=2, vel=(0, 0, 1)) == 1
        # two more rods on top of the two present: multisphere particles count once
        sim.insert(species=1, value=2, region=("block", -4e-3, 4e-3, -4e-3, 4e-3, 5e-3, 1.5e-2))
        sim.run(10)
        bodies = sim.engine.bodies()
    assert sorted(set(bodies.tolist())) == [-1, 1, 2, 3, 4]
    assert all(n == 4 for n in np.bincount(bodies[bodies > 0])[1:])
    assert np.count_nonzero(bodies > 0) == 16


def rods(output, restart):
    """Six rods dropped onto the floor, checkpointed every 10000 steps."""
    species = ({"material": MATERIAL, "style": "multisphere", "function": rod},)
    with dem(output, species, restart=restart) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        region = ("block", -4e-3, 4e-3, -4e-3, 4e-3, 1e-3, 1.8e-2)
        sim.insert(species=1, value=6, region=region, args={"orientation": "random"})
        sim.run(20000)
        return sim.extractCoords(), sim.engine.bodies()


def test_a_resumed_multisphere_simulation_continues_where_it_stopped(tmp_path):
    """LIGGGHTS' restart file keeps the bodies (fix multisphere by id): resumed from step
    10000, the rods end where they ended without the resume (here to the last bit)."""
    x, bodies = rods(tmp_path / "straight", (10000, "restart", "restart.*.h5"))
    shutil.copytree(tmp_path / "straight", tmp_path / "resumed")
    again, bodies_again = rods(
        tmp_path / "resumed", (10000, "restart", "restart.*.h5", True, "restart.10000.h5")
    )
    assert len(x) == 24 and bodies.tolist() == bodies_again.tolist()
    np.testing.assert_allclose(again, x, rtol=0, atol=1e-3 * R)
    assert "resumed from" in (tmp_path / "resumed" / "pygran.log").read_text()
