"""SubSystem: named read-only arrays, slicing, concatenation, iteration, transforms."""

import numpy as np
import pytest

from pygran_core import SubSystem
from pygran_core.errors import ConfigError


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
    with pytest.raises(ConfigError, match=r"no attributes \['vx'\]"):
        grains.scale(2, "vx")


# -- units, the '*' product, write ---------------------------------------------------------------


def test_unit_conversion_round_trips_exactly():
    rng = np.random.default_rng(5)
    original = {k: rng.random(50) * 1e-3 for k in ("x", "y", "z", "radius", "vx", "fx")}
    grains = Grains(id=np.arange(50), **original, box=((0, 1e-3),) * 3, time=0.25)
    grains.convert("micro")
    assert grains.units == "micro"
    np.testing.assert_allclose(grains.x, original["x"] * 1e6, rtol=1e-15)
    np.testing.assert_allclose(
        grains.fx, original["fx"] * 1e9, rtol=1e-15
    )  # N = 1e15 pg * 1e6 um / 1e12 us^2
    np.testing.assert_allclose(grains.box, [[0, 1e3]] * 3)
    assert grains.time == pytest.approx(0.25e6)
    np.testing.assert_array_equal(grains.id, np.arange(50))
    grains.convert("nano").convert("cgs").convert("si")
    for key, values in original.items():
        np.testing.assert_array_equal(grains.data[key], values)  # bit-identical
    part = grains.convert("micro")[10:20]
    np.testing.assert_array_equal(part.convert("si").x, original["x"][10:20])
    with pytest.raises(Exception, match="Unknown unit system 'furlongs'"):
        grains.convert("furlongs")


def test_transform_after_conversion_is_kept():
    grains = Grains(x=[1.0], y=[0.0], z=[0.0])
    grains.convert("cgs").translate((50.0, 0.0, 0.0))
    np.testing.assert_allclose(grains.convert("si").x, [1.5])


def test_combining_different_units_is_refused():
    a, b = SubSystem(x=[1.0]), SubSystem(x=[1.0]).convert("micro")
    with pytest.raises(ValueError, match="'si' units with one in 'micro' units"):
        a + b


def test_product_is_the_geometric_mean_of_every_pair():
    i = SubSystem(radius=[1.0], x=[5.0])
    j = SubSystem(radius=[1.0, 4.0], x=[2.0, -8.0], vx=[1.0, 1.0])
    k = SubSystem(radius=[9.0, 16.0, 25.0], x=[8.0, 8.0, 2.0])
    result = i + j * k  # the manual's example: n_i + n_j n_k elements
    assert len(result) == 1 + 2 * 3 and result.keys() == ["radius", "x"]
    np.testing.assert_allclose(result.radius, [1, 3, 4, 5, 6, 8, 10])
    np.testing.assert_allclose(result.x, [5, 4, 4, 2, -8, -8, -4])  # sign kept for negative products


def test_write_and_read_back(tmp_path):
    from pygran_core.analysis import Particles, System

    particles = Particles(
        id=[1, 2], x=[0.1, 0.2], y=[0.0, 0.0], z=[0.0, 1e-3], radius=[5e-5, 6e-5], timestep=7
    )
    particles.write(tmp_path / "one.dump")
    again = System(Particles=str(tmp_path / "one.dump")).Particles
    assert again.timestep == 7 and again.keys() == particles.keys()
    for key in particles.keys():
        np.testing.assert_array_equal(again.data[key], particles.data[key])
    with pytest.raises(Exception, match="mesh|writer|format"):
        particles.write(tmp_path / "one.unknownformat")
