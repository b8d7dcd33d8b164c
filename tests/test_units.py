"""Unit systems as pure conversion functions."""

import numpy as np
import pytest

from pygran_core import units
from pygran_core.errors import ConfigError


@pytest.mark.parametrize(
    ("dimension", "source", "target", "expected"),
    [
        ("length", "si", "cgs", 100.0),
        ("length", "si", "micro", 1e6),
        ("mass", "si", "micro", 1e15),
        ("time", "si", "nano", 1e9),
        ("density", "si", "cgs", 1e-3),
        ("force", "si", "cgs", 1e5),
        ("pressure", "si", "cgs", 10.0),
        ("energy", "si", "cgs", 1e7),
        ("velocity", "si", "micro", 1.0),
        ("force", "si", "micro", 1e9),
        ("length", "micro", "nano", 1e3),
    ],
)
def test_factors(dimension, source, target, expected):
    assert units.factor(dimension, source, target) == pytest.approx(expected, rel=1e-15)


def test_convert_and_back_is_within_one_rounding():
    rng = np.random.default_rng(7)
    values = rng.uniform(1e-5, 1e-3, 1000)
    there = units.convert(values, "length", "si", "micro")
    back = units.convert(there, "length", "micro", "si")
    assert np.max(np.abs(back - values) / values) <= 2 * np.finfo(float).eps
    assert units.convert(values, "length", "si", "si") is values


def test_unknown_names_suggest():
    with pytest.raises(ConfigError, match="Unknown unit system 'mcro'. Did you mean 'micro'"):
        units.factor("length", "si", "mcro")
    with pytest.raises(ConfigError, match="Unknown dimension 'lenght'. Did you mean 'length'"):
        units.factor("lenght", "si", "cgs")


def test_unit_name_is_a_string_that_converts_when_called():
    seen = []
    name = units.UnitName("si", seen.append)
    assert name == "si" and f"{name}" == "si" and name() == "si" and seen == []
    assert name("nano") == "nano" and seen == ["nano"]
    with pytest.raises(ConfigError, match="Unknown unit system 'mikro'. Did you mean 'micro'"):
        name("mikro")
    assert seen == ["nano"]
    import pickle

    restored = pickle.loads(pickle.dumps(name))
    assert type(restored) is str and restored == "si"
