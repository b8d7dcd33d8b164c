"""SubSystem: named read-only arrays, slicing, concatenation, iteration, transforms."""

import numpy as np
import pytest

from pygran_core import SubSystem


class Grains(SubSystem):
    """A user subclass: slicing and copying must keep the class."""

    def __init__(self, **data):
        super().__init__(**data)
        self.made_by_init = True


@pytest.fixture
def grains():
    return Grains(
        id=[1, 2, 3, 4],
        x=[0.0, 1.0, 2.0, 3.0],
        y=np.zeros(4),
        z=[5.0, 6.0, 7.0, 8.0],
        radius=[1.0, 2.0, 1.0, 2.0],
        timestep=100,
        box=((0, 1), (0, 1), (0, 1)),
    )


def test_attributes_and_metadata(grains):
    assert len(grains) == 4
    assert grains.keys() == ["id", "x", "y", "z", "radius"]
    np.testing.assert_array_equal(grains.radius, [1, 2, 1, 2])
    assert grains.timestep == 100 and np.shape(grains.box) == (3, 2)
    assert grains["x"] is grains.x
    assert "x" in grains and "timestep" not in grains


def test_arrays_are_read_only(grains):
    with pytest.raises(ValueError, match="read-only"):
        grains.x[0] = 7
    with pytest.raises(AttributeError, match="Grains.x is read-only"):
        grains.x = np.zeros(4)


def test_unknown_attribute_suggests(grains):
    with pytest.raises(AttributeError, match="no attribute 'radiu'. Did you mean 'radius'"):
        _ = grains.radiu


def test_mismatched_lengths_rejected():
    with pytest.raises(ValueError, match="different lengths"):
        SubSystem(x=[1, 2], y=[1, 2, 3])


@pytest.mark.parametrize(
    ("selection", "ids"),
    [
        (1, [2]),
        (-1, [4]),
        (slice(1, 3), [2, 3]),
        ([0, 3], [1, 4]),
        (np.array([2]), [3]),
        (np.array([True, False, False, True]), [1, 4]),
        ([], []),
    ],
)
def test_slicing_keeps_class_and_metadata(grains, selection, ids):
    part = grains[selection]
    assert type(part) is Grains and part.timestep == 100
    np.testing.assert_array_equal(part.id, ids)


def test_boolean_combinations(grains):
    part = grains[(grains.radius > 1) & (grains.x < 2) | (grains.id == 3)]
    np.testing.assert_array_equal(part.id, [2, 3])


@pytest.mark.parametrize("bad", [4, -5, [0, 9], np.array([True, False]), np.array([0.5])])
def test_bad_selection_is_a_clear_index_error(grains, bad):
    with pytest.raises(IndexError, match="out of range|does not match|Cannot select"):
        grains[bad]


def test_iteration_yields_single_elements(grains):
    items = list(grains)
    assert [len(i) for i in items] == [1] * 4
    assert [int(i.id[0]) for i in items] == [1, 2, 3, 4]
    assert all(type(i) is Grains for i in items)


def test_add_concatenates_common_attributes(grains):
    other = SubSystem(id=[9], x=[9.0], y=[9.0], z=[9.0])
    both = grains + other
    assert type(both) is Grains and len(both) == 5 and "radius" not in both
    np.testing.assert_array_equal(both.id, [1, 2, 3, 4, 9])


def test_iadd_requires_every_attribute(grains):
    with pytest.raises(ValueError, match=r"lacks \['radius'\]"):
        grains += SubSystem(id=[9], x=[9.0], y=[9.0], z=[9.0])
    more = SubSystem(id=[9], x=[9.0], y=[9.0], z=[9.0], radius=[3.0], vx=[1.0])
    grains += more
    assert len(grains) == 5 and "vx" not in grains


def test_copy_constructor_and_copy(grains):
    clone = Grains(Grains=grains)
    assert clone.made_by_init and clone.keys() == grains.keys() and clone.timestep == 100
    np.testing.assert_array_equal(clone.z, grains.z)
    base_copy = SubSystem(SubSystem=grains)
    assert type(base_copy) is SubSystem and len(base_copy) == 4
    independent = grains.copy()
    independent.translate(1.0)
    assert grains.x[0] == 0.0 and independent.x[0] == 1.0


def test_translate_scale_noise_in_place(grains):
    assert grains.translate((1.0, 2.0, 3.0)) is grains
    np.testing.assert_array_equal(grains.y, [2, 2, 2, 2])
    np.testing.assert_array_equal(grains.z, [8, 9, 10, 11])
    grains.scale(3, ("radius",))
    np.testing.assert_array_equal(grains.radius, [3, 6, 3, 6])
    before = grains.x.copy()
    grains.noise(0.1, "x", seed=1)
    again = Grains(Grains=grains).translate(0.0)
    assert not np.array_equal(grains.x, before)
    np.testing.assert_allclose(grains.x, before + np.random.default_rng(1).normal(0, 0.1, 4))
    np.testing.assert_array_equal(again.x, grains.x)
    with pytest.raises(KeyError, match=r"no attributes \['vx'\]"):
        grains.scale(2, "vx")
