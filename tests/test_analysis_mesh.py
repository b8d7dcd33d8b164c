"""Mesh: cells as elements, shared points, areas and centres, slicing, transforms."""

import numpy as np
import pytest

from pygran_core.analysis import Mesh

# a unit square split into two triangles plus a unit square quad, z = 0 and z = 1
POINTS = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [2, 0, 1], [2, 1, 1], [0, 1, 1]]
CELLS = [[0, 1, 2, -1], [0, 2, 3, -1], [4, 5, 6, 7]]


@pytest.fixture
def mesh():
    return Mesh(points=POINTS, cells=CELLS, point_data={"pressure": np.arange(8.0)}, meshid=[1, 1, 2])


def test_cells_are_elements_and_points_are_shared(mesh):
    assert len(mesh) == mesh.nCells() == 3 and mesh.nPoints() == 8
    np.testing.assert_array_equal(mesh.meshid, [1, 1, 2])
    np.testing.assert_array_equal(mesh.pressure, np.arange(8.0))
    assert set(mesh.point_data) == {"points", "pressure"} and set(mesh.cell_data) == {"meshid"}
    wall = mesh[mesh.meshid == 2]
    assert type(wall) is Mesh and wall.nCells() == 1 and wall.nPoints() == 8
    assert [len(cell) for cell in mesh] == [1, 1, 1]


def test_areas_and_centres(mesh):
    np.testing.assert_allclose(mesh.computeAreas(), [0.5, 0.5, 2.0])
    np.testing.assert_allclose(mesh.computeCentres(), [[2 / 3, 1 / 3, 0], [1 / 3, 2 / 3, 0], [1, 0.5, 1]])


def test_translate_scale_and_units_act_on_points(mesh):
    mesh.translate((1.0, 0.0, 0.0))
    np.testing.assert_allclose(mesh.points[:, 0], np.array(POINTS)[:, 0] + 1)
    mesh.scale(2.0)
    np.testing.assert_allclose(mesh.computeAreas(), [2.0, 2.0, 8.0])
    before = mesh.points
    mesh.convert("cgs")
    np.testing.assert_allclose(mesh.points, before * 100)
    np.testing.assert_array_equal(mesh.convert("si").points, before)
    np.testing.assert_array_equal(mesh.meshid, [1, 1, 2])


def test_add_renumbers_cells(mesh):
    both = mesh + mesh[2]
    assert both.nCells() == 4 and both.nPoints() == 16
    np.testing.assert_allclose(both.computeAreas(), [0.5, 0.5, 2.0, 2.0])
    with pytest.raises(TypeError, match="defined for Particles, not for Mesh"):
        mesh * mesh


def test_bad_meshes_are_rejected():
    with pytest.raises(ValueError, match="Mesh needs points"):
        Mesh(cells=CELLS)
    with pytest.raises(ValueError, match="refer to points 0..9; there are 8"):
        Mesh(points=POINTS, cells=[[0, 1, 9]])
    with pytest.raises(ValueError, match="one row per point"):
        Mesh(points=POINTS, cells=CELLS, point_data={"p": [1.0]})
    copy = Mesh(Mesh=Mesh(points=POINTS, cells=CELLS))
    assert copy.nPoints() == 8
