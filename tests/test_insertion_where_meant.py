"""Insertion where the user means it (issue 44, item 2), written as a user writes a study:
a drum built with the geometry helpers and filled inside the mesh on native and LIGGGHTS with
no particle lost; a hopper filled through a region intersected with a cone; a shortfall
reported at the user's line, as a warning or, asked strictly, an error; no particle placed
across a wall."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from pygran_core import params, registry, simulation
from pygran_core.errors import ConfigError, InsertionWarning
from pygran_core.simulation import geometry
from pygran_core.simulation.geometry import triangle_distance
from pygran_core.testing.solvers import in_ci, require_solver

R, L = 0.03, 0.012  # the drum's radius and length (m)
BEADS = (1.5e-3, 1.0e-3)  # two sizes


def require_engine(engine: str) -> None:
    installed = registry.available("engine")
    if engine not in installed:
        if in_ci():
            pytest.fail(f"CI=true and the {engine} engine is not installed", pytrace=False)
        pytest.skip(f"the {engine} engine is not installed")
    locate = installed[engine].spec.locate_solver
    if locate is not None:
        require_solver(locate)


def drum_study(engine: str, output: Path, count: int, steps: int) -> tuple[np.ndarray, np.ndarray, int]:
    """A half-filled drum of two bead sizes turned for ``steps``: positions, radii, lost count."""
    drum = geometry.drum(radius=R, length=L, axis="y")
    with simulation.DEM(
        engine=engine,
        box=(-0.032, 0.032, -0.008, 0.008, -0.032, 0.032),
        gravity=(9.81, 0, 0, -1),
        dt=1e-5,
        output=str(output),
        seed=3,
        species=[{"material": params.organic, "radius": ("constant", r)} for r in BEADS],
        mesh={"drum": {"triangles": drum, "material": params.organic}},
    ) as sim:
        lower_half = ("intersect", ("block", -R, R, -L / 2, L / 2, -R, 0.01), drum)
        sim.insert(species=(1, 2), value=count, region=lower_half)
        sim.moveMesh("drum", rotate=("origin", 0, 0, 0), axis=(0, 1, 0), period=2.0)
        sim.run(steps)
        return sim.extractCoords(), sim.extractRadii(), sim.lost


@pytest.mark.parametrize("engine", ["native", "liggghts"])
def test_a_drum_filled_inside_its_mesh_loses_no_particle(engine: str, tmp_path: Path) -> None:
    require_engine(engine)
    x, radius, lost = drum_study(engine, tmp_path / engine, count=200, steps=1000)
    assert len(x) == 200 and lost == 0
    drum = geometry.drum(radius=R, length=L, axis="y")
    assert drum.contains(x).all()
    # no bead deeper in the wall than 5 % of its radius (they settle under gravity)
    assert np.all(triangle_distance(x, drum.triangles) > 0.95 * radius)
    assert sorted(np.unique(np.round(radius, 6))) == sorted(BEADS)


def test_a_hopper_filled_through_a_region_cut_by_a_cone(tmp_path: Path) -> None:
    outlet, top, height = 2e-3, 8e-3, 12e-3
    hopper = geometry.hopper(radius=top, outlet=outlet, height=height, wall_height=6e-3)
    radius = 4e-4
    with simulation.DEM(
        engine="native",
        box=(-0.009, 0.009, -0.009, 0.009, -0.002, 0.02),
        gravity=(9.81, 0, 0, -1),
        dt=4e-6,
        output=str(tmp_path / "hopper"),
        seed=5,
        species=({"material": params.organic, "radius": ("constant", radius)},),
        mesh={"hopper": {"triangles": hopper, "material": params.organic}},
    ) as sim:
        sim.setupWall(wtype="primitive", plane="zplane", peq=0.0)  # the closed outlet
        cone = ("cone", "z", 0, 0, outlet, top, 0.0, height)
        upper = ("block", -top, top, -top, top, 4e-3, height)
        sim.insert(species=1, value=300, region=("intersect", upper, cone))
        placed = sim.extractCoords()
        sim.run(400)
        lost = sim.lost
    assert len(placed) == 300 and lost == 0
    # every centre inside the cone, at least a radius from its side, none across the mesh
    rho, z = np.hypot(placed[:, 0], placed[:, 1]), placed[:, 2]
    side = outlet + (top - outlet) * z / height
    slope = math.cos(math.atan2(top - outlet, height))
    assert np.all((side - rho) * slope >= radius - 1e-12) and np.all(
        (z >= 4e-3 + radius) & (z <= height - radius)
    )
    assert np.all(triangle_distance(placed, hopper.triangles) >= radius)
    gaps = np.linalg.norm(placed[:, None] - placed[None], axis=-1) + np.eye(len(placed))
    assert gaps.min() >= 2 * radius


def full_box(tmp_path: Path) -> simulation.DEM:
    return simulation.DEM(
        engine="native",
        box=(0, 0.01, 0, 0.01, 0, 0.01),
        dt=1e-5,
        output=str(tmp_path / "full"),
        species=({"material": params.organic, "radius": ("constant", 1e-3)},),
    )


def test_a_shortfall_is_a_warning_at_the_users_line_with_the_count(tmp_path: Path) -> None:
    with full_box(tmp_path) as sim, pytest.warns(InsertionWarning) as caught:
        sim.insert(species=1, value=9, region=("block", 0, 0.004, 0, 0.004, 0, 0.004))  # jams before 9
        made = len(sim.extractIds())
    assert 0 < made < 9
    (warning,) = caught
    assert f"{made} of 9 particles inserted" in str(warning.message)
    assert warning.filename == __file__  # the insert line above, not PyGran's code


def test_asked_strictly_a_shortfall_is_an_error(tmp_path: Path) -> None:
    with full_box(tmp_path) as sim, warnings.catch_warnings():
        warnings.simplefilter("error", InsertionWarning)
        with pytest.raises(InsertionWarning, match=r"of 9 particles inserted"):
            sim.insert(species=1, value=9, region=("block", 0, 0.004, 0, 0.004, 0, 0.004))


def test_no_particle_is_placed_across_a_cylinder_wall(tmp_path: Path) -> None:
    with simulation.DEM(
        engine="native",
        box=(-0.01, 0.01, -0.01, 0.01, 0, 0.01),
        dt=1e-5,
        output=str(tmp_path / "cylinder"),
        seed=2,
        species=({"material": params.organic, "radius": ("constant", 5e-4)},),
    ) as sim:
        sim.setupWall(wtype="primitive", axis="z", centre=(0, 0), radius=0.005)
        sim.insert(species=1, value=150, region=("block", -0.009, 0.009, -0.009, 0.009, 0.001, 0.009))
        x = sim.extractCoords()
    assert len(x) == 150
    assert np.all(np.abs(np.hypot(x[:, 0], x[:, 1]) - 0.005) >= 5e-4)


def test_a_primitive_cylinder_wall_does_not_turn_and_says_what_does(tmp_path: Path) -> None:
    with simulation.DEM(
        engine="native",
        box=(-0.01, 0.01, -0.01, 0.01, 0, 0.01),
        dt=1e-5,
        output=str(tmp_path / "turn"),
        species=({"material": params.organic, "radius": ("constant", 5e-4)},),
    ) as sim:
        wall = sim.setupWall(wtype="primitive", axis="z", centre=(0, 0), radius=0.005)
        with pytest.raises(ConfigError, match=r"is a primitive wall.*geometry\.drum\(radius=") as refused:
            sim.moveMesh(wall, rotate=("origin", 0, 0, 0), axis=(0, 0, 1), period=1.0)
        assert "Known: ." not in str(refused.value)
        with pytest.raises(ConfigError, match="has no mesh to move"):
            sim.moveMesh("drum", rotate=("origin", 0, 0, 0), axis=(0, 0, 1), period=1.0)
