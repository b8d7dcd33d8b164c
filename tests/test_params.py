"""Material dictionaries and their validation."""

from __future__ import annotations

import math

import pytest

from pygran_core import params
from pygran_core.errors import ConfigError

STEARIC_ACID = {  # the manual's Listing 3.1
    "youngsModulus": 4.15e7,
    "poissonsRatio": 0.25,
    "coefficientFriction": 0.5,
    "coefficientRollingFriction": 0.0,
    "cohesionEnergyDensity": 0.033,
    "coefficientRestitution": 0.9,
    "coefficientRollingViscousDamping": 0.1,
    "yieldPress": 2.2e6,
    "characteristicVelocity": 0.1,
    "density": 997.164,
}


def test_stearic_acid_has_the_manual_values():
    assert dict(params.stearicAcid) == STEARIC_ACID


@pytest.mark.parametrize("name", ["stearicAcid", "glass", "steel", "organic", "cohesive", "cohesionless"])
def test_every_material_is_complete_and_valid(name):
    material = getattr(params, name)
    assert params.MATERIALS[name] is material
    assert set(material) == params.KEYS
    assert params.validate(material) == dict(material)


def test_materials_are_physically_distinct():
    assert params.steel["density"] > params.glass["density"] > params.organic["density"]
    assert params.steel["youngsModulus"] > params.glass["youngsModulus"] > params.organic["youngsModulus"]
    assert params.cohesive["cohesionEnergyDensity"] > 0 == params.cohesionless["cohesionEnergyDensity"]


def test_module_materials_cannot_be_modified_but_can_be_copied():
    with pytest.raises(TypeError):
        params.glass["density"] = 1.0  # type: ignore[index]
    copy = dict(params.stearicAcid, radius=1e-4)
    copy["density"] = 1.0
    assert params.stearicAcid["density"] == 997.164
    assert copy["radius"] == 1e-4


def test_ints_and_floats_are_accepted_and_returned_as_floats():
    clean = params.validate({"youngsModulus": 100000000, "poissonsRatio": 0, "density": 1500})
    assert clean == {"youngsModulus": 1e8, "poissonsRatio": 0.0, "density": 1500.0}
    assert all(type(v) is float for v in clean.values())


def test_validate_returns_a_new_dict():
    material = {"density": 2.0}
    clean = params.validate(material)
    clean["density"] = 3.0
    assert material == {"density": 2.0}


@pytest.mark.parametrize(
    ("wrong", "right"),
    [
        ("youngModulus", "youngsModulus"),
        ("poissonRatio", "poissonsRatio"),
        ("coefficientRestituion", "coefficientRestitution"),
        ("yieldPressure", "yieldPress"),
        ("cohesionEnergydensity", "cohesionEnergyDensity"),
    ],
)
def test_misspelt_key_suggests_the_right_one(wrong, right):
    with pytest.raises(ConfigError, match=f"{wrong}.*Did you mean '{right}'"):
        params.validate({wrong: 1.0})


def test_radius_and_mass_only_where_allowed():
    with pytest.raises(ConfigError, match="radius"):
        params.validate({"radius": 1e-4})
    assert params.validate({"radius": 1e-4, "mass": 1e-9}, allow=("radius", "mass")) == {
        "radius": 1e-4,
        "mass": 1e-9,
    }


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("youngsModulus", -1e8),
        ("youngsModulus", 0),
        ("poissonsRatio", 0.5),
        ("poissonsRatio", -1.0),
        ("poissonsRatio", 0.7),
        ("coefficientRestitution", 0.0),
        ("coefficientRestitution", 1.2),
        ("coefficientRestitution", -0.5),
        ("density", -1000.0),
        ("density", 0),
        ("coefficientFriction", -0.1),
        ("cohesionEnergyDensity", -0.01),
        ("yieldPress", -1e6),
        ("characteristicVelocity", 0.0),
        ("youngsModulus", math.inf),
        ("density", math.nan),
    ],
)
def test_out_of_range_value_names_key_and_value(key, value):
    with pytest.raises(ConfigError, match=f"{key}.*{value!r}".replace("(", r"\(")):
        params.validate({key: value})


@pytest.mark.parametrize("value", ["1e8", None, True, [1e8], 1 + 0j])
def test_non_numbers_are_rejected(value):
    with pytest.raises(ConfigError, match="youngsModulus.*real number"):
        params.validate({"youngsModulus": value})


def test_boundary_values_are_accepted():
    assert params.validate({"coefficientRestitution": 1, "poissonsRatio": -0.99, "coefficientFriction": 0})


def test_a_material_must_be_a_mapping():
    with pytest.raises(ConfigError, match="mapping"):
        params.validate([("density", 1.0)])  # type: ignore[arg-type]
