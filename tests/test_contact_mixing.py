"""Pair mixing rules: scalars, arrays, walls and per-type tables."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pygran_core import params
from pygran_core.simulation.models import HertzMindlin, mixing

GLASS_E, GLASS_NU = 6.3e10, 0.23
STEEL_E, STEEL_NU = 2.1e11, 0.3


def test_effective_modulus_of_glass_on_steel():
    expected = 1 / ((1 - 0.23**2) / 6.3e10 + (1 - 0.3**2) / 2.1e11)  # 5.19e10 Pa
    value = mixing.effective_modulus(GLASS_E, GLASS_NU, STEEL_E, STEEL_NU)
    assert value == pytest.approx(expected, rel=1e-12)
    assert 5.1e10 < expected < 5.3e10


def test_effective_shear_modulus_matches_liggghts_form():
    # LIGGGHTS: 1/G* = 2 (2 - nu1)(1 + nu1)/E1 + 2 (2 - nu2)(1 + nu2)/E2
    expected = 1 / (2 * (2 - 0.23) * 1.23 / 6.3e10 + 2 * (2 - 0.3) * 1.3 / 2.1e11)
    assert mixing.effective_shear_modulus(GLASS_E, GLASS_NU, STEEL_E, STEEL_NU) == pytest.approx(expected)


def test_walls_have_infinite_radius_and_mass():
    assert mixing.effective_radius(2e-4) == 2e-4
    assert mixing.effective_mass(3e-9, math.inf) == 3e-9
    assert mixing.effective_radius(2e-4, 2e-4) == pytest.approx(1e-4)
    np.testing.assert_allclose(mixing.effective_radius([1.0, 2.0], [1.0, np.inf]), [0.5, 2.0])


def test_pair_rules_for_friction_restitution_and_cohesion():
    assert mixing.pair_friction(0.5, 0.3) == 0.3
    assert mixing.pair_restitution(0.9, 0.4) == pytest.approx(0.6)
    assert mixing.pair_restitution(0.9, 0.9) == pytest.approx(0.9)
    assert mixing.pair_cohesion(0.04, 0.01) == pytest.approx(0.02)
    assert mixing.pair_yield_pressure(1e6, 5e5) == 5e5


def test_pair_table_is_symmetric_and_matches_scalar_calls():
    materials = [params.sodaLimeGlass, params.bearingSteel, params.microcrystallineCellulose]
    E = [m["youngsModulus"] for m in materials]
    nu = [m["poissonsRatio"] for m in materials]
    table = mixing.pair_table(mixing.effective_modulus, E, nu)
    assert table.shape == (3, 3)
    np.testing.assert_allclose(table, table.T)
    assert table[0, 1] == pytest.approx(mixing.effective_modulus(E[0], nu[0], E[1], nu[1]))
    friction = mixing.pair_table(mixing.pair_friction, [m["coefficientFriction"] for m in materials])
    assert friction[0, 2] == 0.092


def test_models_use_the_mixing_rules_for_a_partner_material():
    glass = dict(params.sodaLimeGlass, radius=1e-3)
    steel_wall = dict(params.bearingSteel)
    model = HertzMindlin(material=glass, partner=steel_wall)
    expected = mixing.effective_modulus(GLASS_E, GLASS_NU, STEEL_E, STEEL_NU)
    assert model.effective_modulus == pytest.approx(expected)
    assert model.effective_radius == 1e-3
    assert model.friction == 0.092
    assert model.restitution_coefficient == pytest.approx(math.sqrt(0.97 * 0.9))
    assert model.restitution() == pytest.approx(math.sqrt(0.97 * 0.9), rel=0.01)
