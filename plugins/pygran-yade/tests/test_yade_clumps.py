"""Multisphere species on YADE's clumps: mass properties of the union, and clumps at rest on a floor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pygran_core import params, registry, simulation
from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.models import HertzMindlin, SpringDashpot
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import union_properties

R = 1e-3
#: The stock organic material (E = 10 MPa), less bouncy so that a dropped clump settles fast.
MATERIAL = dict(params.organic, coefficientRestitution=0.5)
#: An asymmetric clump of overlapping spheres of three sizes.
LUMP = [(0.0, 0.0, 0.0, R), (1.2 * R, 0.3 * R, 0.0, 0.8 * R), (0.4 * R, 1.1 * R, 0.5 * R, 1.2 * R)]
#: A straight rod of four spheres, 1.5 R apart (each overlapping the next).
ROD = [(1.5 * R * (k - 1.5), 0.0, 0.0, R) for k in range(4)]


@pytest.fixture(autouse=True)
def yade():
    require_solver(registry.get_engine("yade").locate_solver)


def _dem(tmp_path, species, **extra):
    params_ = dict(
        engine="yade",
        model=HertzMindlin,
        box=(-0.01, 0.01, -0.01, 0.01, 0.0, 0.02),
        species=species,
        dt=5e-6,
        output=str(tmp_path / "out"),
        traj={"pfile": None},
        progress=False,
    )
    return simulation.DEM(**(params_ | extra))


def test_clump_mass_centre_and_inertia_are_those_of_the_union(tmp_path):
    """YADE integrates an overlapping clump on a grid: within 0.5 % of a Monte Carlo integral
    of the union of its spheres (4e6 samples, 0.05 % noise), where the sum of the spheres'
    masses is 19 % too heavy."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": lambda: LUMP},)
    with _dem(tmp_path, species) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.01)
        found, x, mass = sim.engine.clumps(), sim.extractCoords(), sim.engine.extract("mass")
        bodies = sim.engine.bodies()
    density = MATERIAL["density"]
    expected_mass, expected_centre, expected_inertia = union_properties(LUMP, density, samples=4_000_000)
    summed = density * sum(4 / 3 * math.pi * r**3 for *_, r in LUMP)
    assert summed > 1.15 * expected_mass  # the overlaps matter
    assert found["mass"][0] == pytest.approx(expected_mass, rel=0.005)
    np.testing.assert_allclose(found["centre"][0] - [0, 0, 0.01], expected_centre, atol=0.005 * R)
    scale = np.linalg.norm(expected_inertia)
    assert np.abs(found["inertia"][0] - expected_inertia).max() < 0.005 * scale
    # the spheres are where the template puts them (template orientation), each with the body's mass
    np.testing.assert_allclose(x, np.array(LUMP)[:, :3] + [0, 0, 0.01], atol=1e-15)
    np.testing.assert_array_equal(mass, found["mass"][0])
    assert bodies.tolist() == [found["id"][0]] * len(LUMP)


def _drop(tmp_path, species, orientation, seed=1):
    """One particle of ``species`` inserted with ``orientation`` around (0, 0, 5 mm) and
    dropped on a floor for 0.2 s (40000 steps); its spheres before and after, and the
    kinetic energy at the end."""
    region = ("block", -1e-4, 1e-4, -1e-4, 1e-4, 5e-3 - 1e-4, 5e-3 + 1e-4)
    with _dem(tmp_path, species, gravity=(9.81, 0, 0, -1), seed=seed) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.insert(species=1, value=1, region=region, args={"orientation": orientation}, all_in=False)
        start = sim.extractCoords()
        ke = sim.monitor(quantities=("ke",), freq=40000)
        sim.run(40000)
        return start, sim.extractCoords(), ke.values["ke"][-1]


def _pose(x):
    """Height of the centre, and angle (degrees) of the axis to the floor, of a straight chain of spheres."""
    axis = x[-1] - x[0]
    return x[:, 2].mean(), math.degrees(math.asin(abs(axis[2]) / np.linalg.norm(axis)))


def test_rod_dropped_on_a_floor_lies_flat(tmp_path):
    """A 4-sphere rod dropped with its axis 30 degrees from the floor, its centre 5 R high, comes
    to rest lying flat: centre one radius high (within a tenth of a radius), axis horizontal."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": lambda: ROD},)
    half = math.radians(30) / 2  # a turn of 30 degrees about y
    start, x, ke = _drop(tmp_path, species, ("constant", math.cos(half), 0.0, math.sin(half), 0.0))
    height, angle = _pose(start)
    assert angle == pytest.approx(30, abs=1e-6) and height == pytest.approx(5e-3, abs=1e-4)
    height, angle = _pose(x)
    assert height == pytest.approx(R, abs=0.1 * R), x
    assert angle < 0.5, x
    assert ke < 1e-12


def test_tablet_dropped_on_a_floor_ends_on_its_flat_face(tmp_path):
    """A multisphere tablet (3 spheres of radius R over 5 R) dropped in a random orientation
    ends lying on the floor: every sphere one radius high (within a tenth of a radius). (It
    may still roll about its axis, which nothing resists: YADE's grid puts the centre of a
    turned clump up to about 1e-4 R off the axis, so it rocks like an eccentric wheel.)"""
    species = (
        {"style": "multisphere/tablet", "material": MATERIAL, "nspheres": 3, "radius": R, "length": 5 * R},
    )
    start, x, _ = _drop(tmp_path, species, "random")
    assert _pose(start)[1] > 5  # it started tilted
    assert np.all(np.abs(x[:, 2] - R) < 0.1 * R), x


def test_refusals(tmp_path):
    """What the yade engine cannot do with clumps is refused by name."""
    rod = ({"style": "multisphere", "material": MATERIAL, "function": lambda: ROD},)
    with pytest.raises(UnsupportedFeature, match="multisphere species with HertzMindlin only"):
        _dem(tmp_path, rod, model=SpringDashpot)
    with _dem(tmp_path, rod) as sim:
        with pytest.raises(UnsupportedFeature, match="clumps by number"):
            sim.insert(
                species=1,
                value=0.1,
                mech="volumefraction_region",
                region=("block", -5e-3, 5e-3, -5e-3, 5e-3, 5e-3, 0.015),
            )
        with pytest.raises(UnsupportedFeature, match="addViscous on multisphere"):
            sim.addViscous(species=1, gamma=0.1)


def test_insertion_places_turned_clumps_without_overlaps_and_counts_each_once(tmp_path):
    """Rods inserted in random orientations lie wholly in the region, no two overlapping; a
    second insert(value=10) adds 10 rods to the 20 there (each counted once, not per sphere)."""
    species = ({"style": "multisphere", "material": MATERIAL, "function": lambda: ROD},)
    region = ("block", -0.019, 0.019, -0.019, 0.019, 1e-3, 0.039)
    with _dem(tmp_path, species, seed=3, box=(-0.02, 0.02, -0.02, 0.02, 0.0, 0.04)) as sim:
        sim.insert(species=1, value=20, region=region)
        x, bodies = sim.extractCoords(), sim.engine.bodies()
        sim.run(1)
        sim.insert(species=1, value=10, region=region)
        total = len(np.unique(sim.engine.bodies()))
    assert len(np.unique(bodies)) == 20 and len(x) == 20 * len(ROD)
    lo, hi = np.array(region[1::2]), np.array(region[2::2])
    assert np.all((x - R >= lo - 1e-12) & (x + R <= hi + 1e-12))
    gaps = np.linalg.norm(x[:, None] - x[None], axis=-1) - 2 * R
    other = bodies[:, None] != bodies[None]
    assert gaps[other].min() > 0
    axes = np.array([x[bodies == b][-1] - x[bodies == b][0] for b in np.unique(bodies)])
    assert np.abs(axes[:, 2]).max() > 0.5 * np.linalg.norm(axes[0])  # turned, not all in the template's
    assert total == 30
