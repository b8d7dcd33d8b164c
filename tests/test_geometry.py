"""simulation.geometry: meshes built in metres, checked against closed forms, used as walls and
regions the way a user writes them; regions intersected with a cone (issue 44, items 1 and 2)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pygran_core import params, simulation
from pygran_core.errors import ConfigError
from pygran_core.simulation import geometry
from pygran_core.simulation.calls import parse_region
from pygran_core.simulation.specs import parse_simulation

MESHES = Path(__file__).resolve().parent / "data" / "meshes"


def polygon_area(radius: float, segments: int) -> float:
    """The area of the regular polygon of ``segments`` corners on ``radius``."""
    return segments / 2 * radius**2 * math.sin(2 * math.pi / segments)


def test_drum_is_closed_with_the_polygonal_prism_volume_and_bounds() -> None:
    drum = geometry.drum(radius=0.05, length=0.02, axis="y", centre=(0.1, 0, 0), segments=32)
    assert drum.closed and drum.open_edges == 0 and len(drum) == 4 * 32
    assert drum.volume == pytest.approx(polygon_area(0.05, 32) * 0.02, rel=1e-12)
    np.testing.assert_allclose(drum.bounds, [[0.05, 0.15], [-0.01, 0.01], [-0.05, 0.05]], atol=1e-15)
    lateral = 32 * 2 * 0.05 * math.sin(math.pi / 32) * 0.02
    assert drum.area == pytest.approx(lateral + 2 * polygon_area(0.05, 32), rel=1e-12)


def test_open_shapes_are_not_closed_and_say_why() -> None:
    tube = geometry.cylinder(radius=0.01, length=0.05, segments=24)
    assert not tube.closed and tube.open_edges == 2 * 24  # both rims
    hopper = geometry.hopper(radius=0.02, outlet=0.004, height=0.03, wall_height=0.01)
    assert not hopper.closed and hopper.open_edges == 2 * geometry.SEGMENTS
    with pytest.raises(ConfigError, match="not closed.*holes"):
        hopper.contains(np.zeros((1, 3)))
    container = geometry.box((0, 0, 0), (1, 1, 1), open_top=True)
    assert len(container) == 10 and container.open_edges == 4


def test_box_cone_and_closed_hopper_volumes() -> None:
    assert geometry.box((0, 0, 0), (0.1, 0.2, 0.3)).volume == pytest.approx(0.006, rel=1e-12)
    n = 64
    frustum = geometry.hopper(radius=0.02, outlet=0.005, height=0.03, segments=n, closed=True)
    # a frustum of regular polygons: h / 3 (A1 + A2 + sqrt(A1 A2))
    a1, a2 = polygon_area(0.005, n), polygon_area(0.02, n)
    assert frustum.volume == pytest.approx(0.03 / 3 * (a1 + a2 + math.sqrt(a1 * a2)), rel=1e-12)
    pointed = geometry.cone(0.0, 0.01, 0.02, caps=True, segments=n)
    assert pointed.closed and pointed.volume == pytest.approx(0.02 / 3 * polygon_area(0.01, n), rel=1e-12)


def test_inside_a_mesh_with_a_margin() -> None:
    drum = geometry.drum(radius=0.05, length=0.02, axis="y", segments=48)
    # along x a corner of the drum at 0.05 m, the facets on either side nearest: 0.0011 cos(pi / 48)
    gap = 0.0011 * math.cos(math.pi / 48)
    points = np.array(
        [[0, 0, 0], [0.0489, 0, 0], [0.0489, 0, 0], [0.0489, 0, 0], [0, 0.0105, 0], [0, 0.009, 0]]
    )
    margin = np.array([0.0, 0.0, gap - 1e-9, gap + 1e-9, 0.0, 0.001 - 1e-9])  # caps at y = +-0.01
    assert drum.contains(points, margin).tolist() == [True, True, True, False, False, True]
    # a facet's middle is radius * cos(pi / 48) from the axis; the facets start at +z and turn to +x
    inner = 0.05 * math.cos(math.pi / 48)
    middle = np.array([math.sin(math.pi / 48), 0, math.cos(math.pi / 48)])
    assert drum.contains(np.outer([inner - 1e-9, inner + 1e-9], middle)).tolist() == [True, False]


def test_stl_round_trip_and_the_meshes_of_the_test_data(tmp_path: Path) -> None:
    drum = geometry.drum(radius=0.05, length=0.02)
    back = geometry.Surface.read(drum.write(tmp_path / "drum.stl"))
    np.testing.assert_array_equal(back.triangles, drum.triangles)
    assert back.closed
    tumbler = geometry.Surface.read(MESHES / "tumbler.stl", scale=1e-3)
    assert tumbler.closed and len(tumbler) == 1780  # as tests/data/meshes/README.md says
    np.testing.assert_allclose(tumbler.bounds, [[-0.762, 0.761], [-0.602, 0.698], [-0.762, 0.762]], atol=1e-3)
    assert tumbler.volume == pytest.approx(1.847, rel=1e-3)  # m^3: 1.847e9 mm^3
    crests = tumbler.triangles.reshape(-1, 3)
    crests = crests[(np.abs(crests[:, 1]) < 0.38) & (np.hypot(crests[:, 0], crests[:, 2]) < 0.73)]
    angles = np.unique(np.round(np.degrees(np.arctan2(crests[:, 2], crests[:, 0])) / 40))
    assert angles.tolist() == [-4, -3, -2, -1, 0, 1, 2, 3, 4]  # nine lifter ribs, 40 degrees apart


def test_two_surfaces_make_one_mesh() -> None:
    drum = geometry.drum(radius=0.01, length=0.01, axis="x")
    cube = geometry.box((0.02, -0.005, -0.005), (0.03, 0.005, 0.005))
    both = drum + cube
    assert len(both) == len(drum) + 12 and both.closed
    assert both.volume == pytest.approx(drum.volume + 1e-6, rel=1e-12)
    assert both.contains(np.array([[0, 0, 0], [0.025, 0, 0], [0.015, 0, 0]])).tolist() == [True, True, False]


def test_bad_geometry_is_refused() -> None:
    with pytest.raises(ConfigError, match="positive length"):
        geometry.drum(radius=-1, length=0.1)
    with pytest.raises(ConfigError, match="below its radius"):
        geometry.hopper(radius=0.01, outlet=0.02, height=0.01)
    with pytest.raises(ConfigError, match=r"\(M, 3, 3\)"):
        geometry.Surface(np.zeros((4, 3)))
    with pytest.raises(ConfigError, match="axis"):
        geometry.cylinder(0.1, 0.1, axis="w")


def spec(tmp_path: Path, **extra: object) -> simulation.DEM:
    return parse_simulation(
        {
            "box": (-0.06, 0.06, -0.02, 0.02, -0.06, 0.06),
            "species": ({"material": params.glass, "radius": ("constant", 1e-3)},),
            "output": str(tmp_path / "out"),
            **extra,
        },
        "native",
        simulation.models.HertzMindlin,
    )


def test_regions_inside_a_mesh_and_intersections(tmp_path: Path) -> None:
    drum = geometry.drum(radius=0.05, length=0.02, axis="y")
    simulation_spec = spec(tmp_path, mesh={"drum": {"triangles": drum, "material": params.glass}})
    assert (tmp_path / "out" / "mesh-drum.stl").is_file()
    by_name = parse_region(("mesh", "drum"), simulation_spec)
    by_object = parse_region(drum, simulation_spec)
    lower = parse_region(
        ("intersect", ("block", -0.06, 0.06, -0.02, 0.02, -0.06, 0.0), drum), simulation_spec
    )
    assert by_name.volume() == pytest.approx(drum.volume, rel=1e-12)
    assert by_name.args[0].inscribed == drum.inscribed  # what LIGGGHTS inserts into
    moved = spec(tmp_path, mesh={"drum": {"triangles": drum, "material": params.glass, "move": (0, 0, 1e-3)}})
    assert parse_region(("mesh", "drum"), moved).args[0].inscribed is None  # not where it was built
    assert by_object.volume() == pytest.approx(drum.volume, rel=1e-12)
    assert lower.volume() == pytest.approx(drum.volume / 2, rel=0.01)  # 20,000 points: 0.4 % standard error
    np.testing.assert_allclose(lower.bounds(), [[-0.05, 0.05], [-0.01, 0.01], [-0.05, 0.0]])
    with pytest.raises(ConfigError, match="not closed"):
        parse_region(("mesh", geometry.cylinder(0.01, 0.01)), simulation_spec)
    with pytest.raises(ConfigError, match="do not overlap"):
        parse_region(
            ("intersect", ("block", 0, 0.01, 0, 0.01, 0, 0.01), ("sphere", 0.05, 0, 0, 0.001)),
            simulation_spec,
        )


def test_a_cone_region_against_its_closed_form(tmp_path: Path) -> None:
    cone = parse_region(("cone", "z", 0, 0, 0.005, 0.02, 0.0, 0.03), spec(tmp_path))
    assert cone.volume() == pytest.approx(math.pi * 0.03 / 3 * (0.005**2 + 0.005 * 0.02 + 0.02**2))
    slope = math.atan2(0.015, 0.03)
    on_axis = np.array([[0.0, 0.0, 0.015]])  # radius 0.0125 there
    assert cone.contains(on_axis, 0.0125 * math.cos(slope) - 1e-9).tolist() == [True]
    assert cone.contains(on_axis, 0.0125 * math.cos(slope) + 1e-9).tolist() == [False]


def test_mesh_wall_given_as_triangles_or_file_not_both(tmp_path: Path) -> None:
    box = geometry.box((-0.01, -0.01, -0.01), (0.01, 0.01, 0.01))
    made = spec(tmp_path, mesh={"cube": {"triangles": box.triangles, "material": params.glass}})
    np.testing.assert_allclose(made.meshes[0].triangles(), box.triangles)
    with pytest.raises(ConfigError, match="not both"):
        spec(tmp_path, mesh={"cube": {"triangles": box, "file": str(MESHES / "square.stl")}})
    with pytest.raises(ConfigError, match="'file' .* or 'triangles'"):
        spec(tmp_path, mesh={"cube": {"material": params.glass}})
