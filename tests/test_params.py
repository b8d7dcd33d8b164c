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


COMMON = {  # shared by the six original materials
    "coefficientFriction": 0.5,
    "coefficientRollingFriction": 0.0,
    "coefficientRestitution": 0.9,
    "coefficientRollingViscousDamping": 0.1,
    "characteristicVelocity": 0.1,
}
#: The original PyGran's materials: (E, nu, cohesionEnergyDensity or None, yieldPress, density).
ORIGINAL = {
    "glass": (63e9, 0.24, 0.05, 62e9, 2500),
    "organic": (1e7, 0.25, 0, 2.2e6, 1000),
    "stearicAcid": (4.15e7, 0.25, 0.033, 2.2e6, 997.164),
    "cohesionless": (1e7, 0.25, None, 2.2e6, 1000),
    "cohesive": (1e7, 0.25, 2e5, 2.2e6, 1000),
    "steel": (2e11, 0.3, 0, 2e10, 8050),
}
REALISTIC = ["sodaLimeGlass", "bearingSteel", "microcrystallineCellulose", "cohesivePowder", "quartzSand"]


def test_stearic_acid_has_the_manual_values():
    assert params.stearicAcid == STEARIC_ACID


@pytest.mark.parametrize("name", ORIGINAL)
def test_the_original_materials_carry_the_original_values(name):
    youngs, poisson, cohesion, yield_press, density = ORIGINAL[name]
    expected = COMMON | {
        "youngsModulus": youngs,
        "poissonsRatio": poisson,
        "yieldPress": yield_press,
        "density": density,
    }
    if cohesion is not None:
        expected["cohesionEnergyDensity"] = cohesion
    material = getattr(params, name)
    assert material == expected and type(material) is dict
    assert params.validate(material) == material


def test_organic_is_soft_enough_for_the_original_scripts_time_step():
    # spheres of 50 um at the original scripts' dt = 1e-6 s: below half the Rayleigh time
    # (with E = 8 GPa it was 8 Rayleigh times and the particles exploded)
    organic = params.organic
    shear = organic["youngsModulus"] / (2 * (1 + organic["poissonsRatio"]))
    rayleigh = math.pi * 5e-5 * math.sqrt(organic["density"] / shear) / (0.1631 * 0.25 + 0.8766)
    assert 2e-6 < rayleigh < 3e-6


@pytest.mark.parametrize("name", REALISTIC)
def test_realistic_materials_are_complete_and_valid(name):
    material = getattr(params, name)
    assert set(material) == params.KEYS
    assert params.validate(material) == material == dict(params.MATERIALS[name])


def test_realistic_materials_are_physically_distinct():
    glass, steel, cellulose = params.sodaLimeGlass, params.bearingSteel, params.microcrystallineCellulose
    assert steel["density"] > glass["density"] > cellulose["density"]
    assert steel["youngsModulus"] > glass["youngsModulus"] > cellulose["youngsModulus"]
    assert params.cohesivePowder["cohesionEnergyDensity"] > 0 == params.quartzSand["cohesionEnergyDensity"]


def test_a_script_changes_its_copy_and_nothing_else():
    from pygran_core.params import steel

    steel["radius"] = 1e-3
    steel["youngsModulus"] = 1e9
    assert "radius" not in params.steel and params.steel["youngsModulus"] == 2e11
    from pygran_core.params import steel as again

    assert again["youngsModulus"] == 2e11 and again is not steel
    assert params.MATERIALS["steel"]["youngsModulus"] == 2e11
    with pytest.raises(TypeError):
        params.MATERIALS["glass"]["density"] = 1.0  # type: ignore[index]
    with pytest.raises(AttributeError, match="no attribute 'glas'"):
        params.glas  # noqa: B018


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
