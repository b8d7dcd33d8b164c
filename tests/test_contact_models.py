"""Contact models against closed-form contact mechanics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.optimize import brentq

from pygran_core import params, registry
from pygran_core.errors import ConfigError, UnsupportedFeature
from pygran_core.simulation.models import ContactModel, HertzMindlin, SpringDashpot, ThorntonNing, plugin

# The manual's Listing 3.2 powder.
POWDER = {
    "youngsModulus": 1e8,
    "poissonsRatio": 0.25,
    "coefficientRestitution": 0.9,
    "characteristicVelocity": 0.1,
    "density": 997.164,
    "radius": 1e-4,
}
E_STAR = 1 / (2 * (1 - 0.25**2) / 1e8)  # particle against a wall of the same material
MASS = 4 / 3 * math.pi * 1e-4**3 * 997.164


def hertz_max_overlap(m, R, E, v):
    return (15 * m * v**2 / (16 * E * math.sqrt(R))) ** 0.4


# --- Hertz -------------------------------------------------------------------------------
@pytest.mark.parametrize("v", [0.01, 0.1, 1.0, 10.0])
def test_undamped_hertz_impact_matches_closed_forms(v):
    model = HertzMindlin(material=dict(POWDER, coefficientRestitution=1))
    impact = model.displacement(v)
    t_c = 2.868 * (MASS**2 / (1e-4 * E_STAR**2 * v)) ** 0.2
    d_max = hertz_max_overlap(MASS, 1e-4, E_STAR, v)
    f_max = 4 / 3 * E_STAR * math.sqrt(1e-4) * d_max**1.5
    assert impact.contact_time == pytest.approx(t_c, rel=0.01)
    assert impact.max_overlap == pytest.approx(d_max, rel=0.01)
    assert impact.max_force == pytest.approx(f_max, rel=0.01)
    assert impact.restitution == pytest.approx(1, abs=1e-6)
    assert model.contactTime(v) == pytest.approx(t_c, rel=1e-9)


def test_sphere_sphere_contact_uses_effective_radius_and_mass():
    model = HertzMindlin(material=dict(POWDER, coefficientRestitution=1), partner=POWDER)
    e_star = 1 / (2 * (1 - 0.25**2) / 1e8)
    assert model.effective_radius == pytest.approx(0.5e-4)
    assert model.effective_mass == pytest.approx(MASS / 2)
    t_c = 2.868 * ((MASS / 2) ** 2 / (0.5e-4 * e_star**2 * 0.1)) ** 0.2
    assert model.displacement().contact_time == pytest.approx(t_c, rel=0.01)


@pytest.mark.parametrize("e", [0.3, 0.6, 0.9])
@pytest.mark.parametrize("v", [0.1, 0.5, 2.0, 10.0])
def test_hertz_mindlin_realises_the_requested_restitution(e, v):
    model = HertzMindlin(material=dict(POWDER, coefficientRestitution=e))
    assert model.restitution(v) == pytest.approx(e, rel=0.01)


def test_hertz_mindlin_force_is_not_clamped_by_default():
    # LIGGGHTS' default (limitForce off): damping makes the force attractive before the
    # overlap returns to zero; the contact ends at zero overlap.
    time, soln, force = HertzMindlin(material=dict(POWDER, coefficientRestitution=0.5)).displacement()
    assert force.min() < -0.01 * force.max()
    assert soln[-1, 0] == pytest.approx(0, abs=1e-9 * soln[:, 0].max())
    assert np.all(soln[1:, 0] > -1e-9 * soln[:, 0].max())


@pytest.mark.parametrize("model_class", [HertzMindlin, SpringDashpot])
def test_limit_force_clamps_and_raises_the_restitution(model_class):
    material = dict(POWDER, coefficientRestitution=0.5)
    clamped = model_class(material=material, limitForce=True).displacement()
    assert clamped.force.min() >= 0
    assert clamped.restitution > 0.5 * 1.05
    assert model_class(material=material).restitution() == pytest.approx(0.5, rel=0.005)


# --- spring-dashpot ----------------------------------------------------------------------
def hooke_coefficients(e, v_char=0.1):
    """LIGGGHTS gran model hooke, from the documentation."""
    kn = 16 / 15 * math.sqrt(1e-4) * E_STAR * (15 * MASS * v_char**2 / (16 * math.sqrt(1e-4) * E_STAR)) ** 0.2
    gamman = 0.0 if e == 1 else math.sqrt(4 * MASS * kn / (1 + (math.pi / math.log(e)) ** 2))
    return kn, gamman


@pytest.mark.parametrize("e", [0.05, 0.2, 0.5, 0.8, 0.95, 1.0])
def test_spring_dashpot_restitution_and_contact_time(e):
    model = SpringDashpot(material=dict(POWDER, coefficientRestitution=e))
    kn, gamman = hooke_coefficients(e)
    assert (model.kn, model.gamman) == pytest.approx((kn, gamman), rel=1e-12)
    t_c = math.pi / math.sqrt(kn / MASS - (gamman / (2 * MASS)) ** 2)
    for v in (0.05, 3.0):
        impact = model.displacement(v)
        assert impact.restitution == pytest.approx(e, rel=0.005)
        assert impact.contact_time == pytest.approx(t_c, rel=0.005)
    assert model.contactTime() == pytest.approx(t_c, rel=1e-12)


@pytest.mark.parametrize("limit", [False, True])
@pytest.mark.parametrize("e", [0.3, 0.9, 1.0])
def test_spring_dashpot_closed_form_matches_the_integrated_impact(e, limit):
    model = SpringDashpot(material=dict(POWDER, coefficientRestitution=e), limitForce=limit)
    kn, gamman = hooke_coefficients(e)
    alpha, omega = gamman / (2 * MASS), math.sqrt(kn / MASS - (gamman / (2 * MASS)) ** 2)
    time, soln, force = exact = model.displacementAnalytical()
    numeric = model.displacement()
    assert time[0] == 0 and soln[0].tolist() == [0.0, 0.1] and soln[-1, 0] == 0
    assert np.diff(time[:-1]) == pytest.approx(0.01 * model.contactTime(), rel=1e-9)
    inside = time < math.pi / omega
    delta = 0.1 / omega * np.exp(-alpha * time) * np.sin(omega * time)
    np.testing.assert_allclose(soln[inside & (force != 0), 0], delta[inside & (force != 0)], rtol=1e-12)
    assert exact.restitution == pytest.approx(numeric.restitution, rel=1e-7)
    assert exact.contact_time == pytest.approx(numeric.contact_time, rel=1e-7)
    np.testing.assert_allclose(
        np.interp(time, numeric.time, numeric.soln[:, 0]), soln[:, 0], atol=1e-5 * soln[:, 0].max()
    )
    if limit and e < 1:  # the particle leaves with the speed it has when k delta + gamma ddelta/dt = 0

        def rate(t):
            return 0.1 * math.exp(-alpha * t) * (math.cos(omega * t) - alpha / omega * math.sin(omega * t))

        def push(t):
            return kn * 0.1 / omega * math.exp(-alpha * t) * math.sin(omega * t) + gamman * rate(t)

        t_star = brentq(push, 1e-3 / omega, math.pi / omega, xtol=1e-20, rtol=1e-14)
        assert force.min() >= 0 and exact.restitution > e
        assert exact.restitution == pytest.approx(-rate(t_star) / 0.1, rel=1e-10)
    else:
        assert exact.restitution == pytest.approx(e, rel=1e-12)


def test_closed_form_refuses_cohesion_and_bad_steps():
    with pytest.raises(ConfigError, match="closed form has no cohesion"):
        SpringDashpot(material=dict(POWDER, cohesionEnergyDensity=1e5)).displacementAnalytical()
    with pytest.raises(ConfigError, match="dt must be > 0"):
        SpringDashpot(material=POWDER).displacementAnalytical(0)


def test_undamped_spring_reaches_the_hertz_overlap_at_the_characteristic_velocity():
    impact = SpringDashpot(material=dict(POWDER, coefficientRestitution=1)).displacement()
    assert impact.max_overlap == pytest.approx(hertz_max_overlap(MASS, 1e-4, E_STAR, 0.1), rel=0.005)


# --- simplified JKR ----------------------------------------------------------------------
@pytest.mark.parametrize("k", [1e5, 1e6])
def test_sjkr_cohesion_deepens_the_undamped_impact_by_its_work(k):
    material = dict(POWDER, coefficientRestitution=1, cohesionEnergyDensity=k)
    impact = HertzMindlin(material=material).displacement()
    R = 1e-4

    def energy(d):  # kinetic energy left at overlap d: 1/2 m v^2 + W_sjkr - W_hertz
        return (
            0.5 * MASS * 0.1**2
            + k * math.pi * (R * d**2 - d**3 / 3)
            - 8 / 15 * E_STAR * math.sqrt(R) * d**2.5
        )

    d_max = brentq(energy, 1e-12, 0.5 * R)
    assert d_max > 1.05 * hertz_max_overlap(MASS, R, E_STAR, 0.1)
    assert impact.max_overlap == pytest.approx(d_max, rel=0.005)
    assert impact.restitution == pytest.approx(1, abs=1e-6)  # the SJKR force is conservative


# --- Thornton-Ning -----------------------------------------------------------------------
def thornton_restitution(v, v_y):
    """Thornton (1997) eq. (30): elastic-perfectly plastic restitution above yield."""
    r = v_y / v
    return (
        math.sqrt(6 * math.sqrt(3) / 5)
        * math.sqrt(1 - r**2 / 6)
        * (r / (r + 2 * math.sqrt(6 / 5 - r**2 / 5))) ** 0.25
    )


def yield_velocity(p_y, E=E_STAR, R=1e-4, m=MASS):
    d_y = (math.pi * p_y / (2 * E)) ** 2 * R  # Hertzian overlap at which p_max = p_y
    return math.sqrt(16 / 15 * E * math.sqrt(R) * d_y**2.5 / m)


def test_yield_velocity_is_thorntons():
    p_y = 2e6
    thornton = math.sqrt(p_y**5 / (E_STAR**4 * 997.164))
    assert yield_velocity(p_y) == pytest.approx(1.56 * thornton, rel=0.005)
    model = ThorntonNing(material=dict(POWDER, yieldPress=p_y))
    assert model.yieldVel == pytest.approx(math.pi**2 / math.sqrt(40) * thornton, rel=1e-12)
    assert model.yieldVel == pytest.approx(1.56 * thornton, rel=4e-4)  # Thornton rounds pi^2/sqrt(40)
    assert model.restitution(0.999 * model.yieldVel) == pytest.approx(1, abs=1e-6)  # still elastic
    assert model.restitution(1.05 * model.yieldVel) < 1 - 1e-4  # yields


def test_thornton_ning_limit_force_holds_without_adhesion_and_is_refused_with_it():
    material = dict(POWDER, yieldPress=1e6)
    limited = ThorntonNing(material=material, limitForce=True).displacement()
    assert limited.force.min() >= 0
    assert limited.restitution == pytest.approx(ThorntonNing(material=material).restitution(), rel=1e-12)
    with pytest.raises(ConfigError, match="limitForce=True would remove the JKR adhesion"):
        ThorntonNing(material=dict(material, cohesionEnergyDensity=0.04), limitForce=True)
    with pytest.raises(ConfigError, match="limitForce must be True or False"):
        HertzMindlin(material=POWDER, limitForce="on")


@pytest.mark.parametrize("p_y", [1e6, 3e6])
def test_thornton_ning_restitution_follows_thornton(p_y):
    model = ThorntonNing(material=dict(POWDER, yieldPress=p_y))
    v_y = yield_velocity(p_y)
    for ratio in (0.2, 0.95):
        assert model.restitution(ratio * v_y) == pytest.approx(1, abs=1e-6)
    previous = 1.0
    for ratio in (1.2, 2.0, 5.0, 20.0, 100.0):
        e = model.restitution(ratio * v_y)
        assert e == pytest.approx(thornton_restitution(ratio * v_y, v_y), rel=0.02)
        assert e < previous
        previous = e


def test_plastic_contact_leaves_a_permanent_overlap():
    model = ThorntonNing(material=dict(POWDER, yieldPress=1e6))
    time, soln, force = model.displacement()
    assert soln[-1, 0] > 0.1 * soln[:, 0].max()  # separates at delta_p > 0
    assert abs(force[-1]) < 1e-9 * force.max() and force.min() >= 0


ADHESIVE = {
    "youngsModulus": 6e9,
    "poissonsRatio": 0.25,
    "density": 1500.0,
    "radius": 2e-5,
    "cohesionEnergyDensity": 0.04,
    "yieldPress": 1e11,
    "characteristicVelocity": 0.04,
}


def jkr_separation_work(gamma, R, E):
    """Work to pull an elastic JKR contact from zero overlap to rupture (fixed grips)."""
    a_0 = (4 * math.pi * gamma * R**2 / E) ** (1 / 3)  # contact radius at zero overlap
    a_f = (math.pi * gamma * R**2 / (4 * E)) ** (1 / 3)  # rupture

    def integrand(a):
        force = 4 * E * a**3 / (3 * R) - 4 * math.sqrt(math.pi * gamma * E * a**3)
        d_overlap = 2 * a / R - math.sqrt(math.pi * gamma / (E * a))
        return -force * d_overlap

    return quad(integrand, a_f, a_0, epsabs=0, epsrel=1e-12)[0]


def test_jkr_pull_off_force_is_3_pi_gamma_r():
    # Gamma = cohesionEnergyDensity is the surface energy of each surface (work of adhesion 2 Gamma).
    model = ThorntonNing(material=ADHESIVE)
    pull_off = 3 * math.pi * 0.04 * 2e-5
    impact = model.displacement(1.0)
    assert not impact.captured
    assert -impact.force.min() == pytest.approx(pull_off, rel=0.01)
    overlaps = np.linspace(-1e-7, 1e-7, 20001)
    assert -model.normal_force(overlaps, 0.0, 0.0).min() == pytest.approx(pull_off, rel=0.01)


def test_jkr_capture_below_the_sticking_velocity():
    model = ThorntonNing(material=ADHESIVE)
    E = model.effective_modulus
    m = model.effective_mass
    v_s = math.sqrt(2 * jkr_separation_work(0.04, 2e-5, E) / m)
    assert v_s < 0.01 * yield_velocity(1e11, E, 2e-5, m)  # elastic throughout
    for ratio in (0.5, 0.95):
        impact = model.displacement(ratio * v_s)
        assert impact.captured and impact.restitution == 0
        assert abs(impact.soln[-1, 1] / impact.soln[0, 1]) < 1e-6  # the manual's COR formula agrees
    for ratio in (1.05, 2.0):
        # energy balance: 1/2 m v_out^2 = 1/2 m v_in^2 - W_separation
        expected = math.sqrt(1 - ratio**-2)
        assert model.restitution(ratio * v_s) == pytest.approx(expected, rel=0.01)


def test_plastic_flattening_raises_the_pull_off_force():
    elastic = ThorntonNing(material=ADHESIVE).displacement(1.0)
    plastic = ThorntonNing(material=dict(ADHESIVE, yieldPress=4e7)).displacement(1.0)
    assert -plastic.force.min() > 1.5 * -elastic.force.min()
    assert plastic.restitution < elastic.restitution


def test_manual_cohesive_example_gives_a_full_curve():
    powder = {
        "radius": 2e-5,
        "yieldPress": 4e7,
        "density": 1500.0,
        "youngsModulus": 6e9,
        "cohesionEnergyDensity": 0.04,
        "poissonsRatio": 0.25,
        "characteristicVelocity": 0.04,
    }
    time, delta, force = ThorntonNing(material=powder).displacement()
    assert len(time) == len(delta) == len(force) > 100
    assert np.all(np.diff(time) > 0)
    assert force.max() > 0 > force.min()
    assert delta[:, 1].max() > delta[0, 1] > 0 > delta[:, 1].min()  # snap-in accelerates, then rebound


# --- tangential and rolling --------------------------------------------------------------
def test_mindlin_tangential_force_below_and_at_the_coulomb_limit():
    material = dict(POWDER, coefficientFriction=0.5, coefficientRestitution=1)
    model = HertzMindlin(material=material)
    G_star = 1 / (2 * 2 * (2 - 0.25) * (1 + 0.25) / 1e8)
    d = 1e-7
    kt = 8 * G_star * math.sqrt(1e-4 * d)
    fn = float(model.normal_force(d, 0.0))
    xi = np.array([[1e-10, 0.0, 0.0], [0.0, 1e-6, 0.0]])
    force, history = model.tangential_force(d, xi, np.zeros(3), fn)
    assert force[0] == pytest.approx([-kt * 1e-10, 0, 0], rel=1e-9)
    assert np.linalg.norm(force[1]) == pytest.approx(0.5 * fn, rel=1e-9)
    assert force[1, 1] < 0
    np.testing.assert_allclose(-kt * history, force, rtol=1e-9)
    zero_force, zero_history = model.tangential_force(-d, xi, np.zeros(3), 0.0)
    assert not zero_force.any() and not zero_history.any()


def test_sliding_contact_is_the_spring_scaled_to_coulomb_without_dashpot():
    model = SpringDashpot(material=dict(POWDER, coefficientFriction=0.3, coefficientRestitution=0.5))
    xi, v = np.array([2e-7, -1e-7, 0.0]), np.array([0.01, 0.02, 0.0])
    assert model.kt * np.linalg.norm(xi) > 0.3e-6  # the spring alone breaks Coulomb's limit
    force, history = model.tangential_force(1e-7, xi, v, 1e-6)
    assert np.linalg.norm(force) == pytest.approx(0.3e-6, rel=1e-9)
    np.testing.assert_allclose(force, -0.3e-6 * xi / np.linalg.norm(xi), rtol=1e-9)
    np.testing.assert_allclose(-model.kt * history, force, rtol=1e-9)


def test_sticking_contact_keeps_its_dashpot_even_past_coulomb():
    """LIGGGHTS' tangential_model_history: the limit is tested on the spring alone."""
    model = SpringDashpot(material=dict(POWDER, coefficientFriction=0.3, coefficientRestitution=0.5))
    xi, v = np.array([2e-7, -1e-7, 0.0]), np.array([0.5, 0.5, 0.0])
    force, history = model.tangential_force(1e-7, xi, v, 1e-3)
    assert model.kt * np.linalg.norm(xi) < 0.3e-3 < np.linalg.norm(force)
    np.testing.assert_allclose(force, -model.kt * xi - model.gammat * v, rtol=1e-12)
    np.testing.assert_array_equal(history, xi)


def test_rolling_resistance_is_a_constant_directional_torque():
    model = HertzMindlin(material=dict(POWDER, coefficientRollingFriction=0.1))
    omega = np.array([[0.0, 0.0, 5.0], [3.0, -4.0, 0.0], [0.0, 0.0, 0.0]])
    torque = model.rolling_torque(np.array([2.0, 2.0, 2.0]), omega)
    magnitude = 0.1 * 1e-4 * 2.0
    expected = [[0, 0, -magnitude], [-0.6 * magnitude, 0.8 * magnitude, 0], [0, 0, 0]]
    np.testing.assert_allclose(torque, expected)


@pytest.mark.parametrize("model_class", [SpringDashpot, HertzMindlin, ThorntonNing])
def test_rolling_model_keyword_defaults_to_cdt_on_class_and_instance(model_class):
    material = dict(POWDER, yieldPress=1e6, coefficientRollingFriction=0.1)
    assert model_class.rolling == "cdt"
    assert model_class(material=material).rolling == "cdt"
    for name in ("cdt", "epsd", "epsd2", "epsd3"):
        model = model_class(material=material, rolling=name)
        assert model.rolling == name and model_class.rolling == "cdt"
    assert "rolling='epsd2'" in repr(model_class(material=material, rolling="epsd2"))
    with pytest.raises(ConfigError, match="Did you mean 'epsd2'"):
        model_class(material=material, rolling="espd2")
    with pytest.raises(ConfigError, match="cdt, epsd, epsd2, epsd3"):
        model_class(material=material, rolling=2)


def test_rolling_torque_of_spring_models_is_left_to_the_engines():
    model = HertzMindlin(material=dict(POWDER, coefficientRollingFriction=0.1), rolling="epsd")
    with pytest.raises(UnsupportedFeature, match="rolling='cdt'"):
        model.rolling_torque(1.0, np.ones(3))


# --- construction and errors -------------------------------------------------------------
def test_manual_listing_style_and_coefficients():
    model = HertzMindlin(material=dict(params.stearicAcid, radius=1e-4))
    time, soln, force = model.displacement()
    deltan, deltav = soln[:, 0], soln[:, 1]
    assert abs(deltav[-1] / deltav[0]) == pytest.approx(0.9, rel=0.01)
    assert deltan.max() > 0 and time[0] == 0 and len(force) == len(time)
    coefficients = model.coefficients
    assert coefficients["friction"] == 0.5 and coefficients["effective_radius"] == 1e-4
    with pytest.raises(TypeError):
        coefficients["friction"] = 1.0  # type: ignore[index]


def test_mass_overrides_density():
    model = HertzMindlin(material=dict(POWDER, mass=2 * MASS))
    assert model.effective_mass == pytest.approx(2 * MASS)


def without(key):
    return {k: v for k, v in POWDER.items() if k != key}


@pytest.mark.parametrize(
    ("model_class", "material", "message"),
    [
        (HertzMindlin, without("radius"), "radius"),
        (HertzMindlin, without("density"), "density"),
        (SpringDashpot, without("characteristicVelocity"), "characteristicVelocity"),
        (ThorntonNing, POWDER, "yieldPress"),
        (HertzMindlin, dict(POWDER, youngModulus=1e8), "Did you mean 'youngsModulus'"),
        (HertzMindlin, dict(POWDER, radius=-1.0), "radius"),
        (HertzMindlin, dict(POWDER, coefficientRestitution=0), "coefficientRestitution"),
    ],
)
def test_invalid_materials_raise_config_errors(model_class, material, message):
    with pytest.raises(ConfigError, match=message):
        model_class(material=material)


def test_missing_optional_coefficients_raise_when_needed():
    model = HertzMindlin(material=POWDER)
    with pytest.raises(ConfigError, match="coefficientFriction"):
        model.tangential_force(1e-7, np.zeros(3), np.zeros(3), 1.0)
    with pytest.raises(ConfigError, match="coefficientRollingFriction"):
        model.rolling_torque(1.0, np.ones(3))
    with pytest.raises(ConfigError, match="velocity"):
        model.displacement(-1.0)


def test_contact_model_is_abstract():
    with pytest.raises(TypeError):
        ContactModel(material=POWDER)  # type: ignore[abstract]


def test_plugin_registers_the_three_models():
    specs = list(plugin.pygran_models())
    assert [(s.name, s.model) for s in specs] == [
        ("SpringDashpot", SpringDashpot),
        ("HertzMindlin", HertzMindlin),
        ("ThorntonNing", ThorntonNing),
    ]
    assert registry.get_model("ThorntonNing").model is ThorntonNing


# --- properties over random valid materials ----------------------------------------------
def log_uniform(low, high):
    return st.floats(math.log10(low), math.log10(high)).map(lambda x: 10.0**x)


materials = st.fixed_dictionaries(
    {
        "youngsModulus": log_uniform(1e6, 1e11),
        "poissonsRatio": st.floats(-0.9, 0.49),
        "coefficientRestitution": st.floats(0.05, 1.0),
        "coefficientFriction": st.one_of(st.just(0.0), st.floats(1e-6, 1.0)),  # no denormal squares in norms
        "characteristicVelocity": log_uniform(0.01, 10),
        "density": log_uniform(100, 2e4),
        "radius": log_uniform(1e-6, 1e-2),
        "yieldPress": log_uniform(1e5, 1e10),
    }
)
MODELS = (SpringDashpot, HertzMindlin, ThorntonNing)


@settings(max_examples=60, deadline=None)
@given(
    material=materials, fraction=st.floats(1e-6, 0.05), rate=st.floats(-10, 10), history=st.floats(1.0, 3.0)
)
def test_forces_are_finite_repulsive_and_vanish_out_of_contact(material, fraction, rate, history):
    overlap = fraction * material["radius"]
    for model_class in MODELS:
        model = model_class(material=material)
        loading = model.normal_force(overlap, abs(rate))
        unloading = model.normal_force(overlap, -abs(rate), history * overlap)
        assert np.isfinite(loading) and np.isfinite(unloading)
        assert loading > 0
        assert model.normal_force(-overlap, rate) == 0 and model.normal_force(0.0, rate) == 0
        fn = model.normal_force(overlap, 0.0)
        ft, xi = model.tangential_force([overlap, -overlap], np.full((2, 3), overlap), np.full(3, rate), fn)
        assert np.all(np.isfinite(ft)) and not ft[1].any() and not xi[1].any()
        assert np.linalg.norm(ft[0]) <= material["coefficientFriction"] * fn * (1 + 1e-12)


@settings(max_examples=40, deadline=None)
@given(
    material=materials,
    gamma=log_uniform(1e-3, 1.0),
    fraction=st.floats(-0.05, 0.05),
    history=st.floats(0.0, 0.05),
)
def test_adhesive_forces_are_finite_and_vanish_before_first_touch(material, gamma, fraction, history):
    material = dict(material, cohesionEnergyDensity=gamma)
    overlap = fraction * material["radius"]
    for model_class in MODELS:
        model = model_class(material=material)
        assert np.isfinite(model.normal_force(overlap, 1.0, history * material["radius"]))
        assert model.normal_force(-abs(overlap), 1.0) == 0


def test_configured_models_keep_their_options_and_engines_without_them_refuse(tmp_path):
    from pygran_core import params, simulation
    from pygran_core.errors import UnsupportedFeature
    from pygran_core.simulation.dem import resolve_model
    from pygran_core.simulation.models import HertzMindlin

    epsd2 = HertzMindlin.configure(rolling="epsd2")
    assert (epsd2.__name__, epsd2.rolling, HertzMindlin.rolling) == (
        "HertzMindlin[rolling=epsd2]",
        "epsd2",
        "cdt",
    )
    assert HertzMindlin.configure(rolling="cdt") is HertzMindlin
    assert epsd2(material=dict(params.glass, radius=1e-3)).rolling == "epsd2"
    instance = HertzMindlin(material=dict(params.glass, radius=1e-3), rolling="epsd", limitForce=True)
    resolved = resolve_model(instance)
    assert (resolved.__name__, resolved.rolling, resolved.limit_force) == (
        "HertzMindlin[rolling=epsd,limitForce=True]",
        "epsd",
        True,
    )
    with pytest.raises(ConfigError, match="Did you mean 'epsd2'"):
        HertzMindlin.configure(rolling="epsd22")
    with pytest.raises(
        UnsupportedFeature, match=r"rolling-friction model epsd3 \(capability 'rolling-epsd3'\)"
    ):
        simulation.DEM(
            engine="native",
            model=HertzMindlin.configure(rolling="epsd3"),
            box=(0, 1e-2, 0, 1e-2, 0, 1e-2),
            species=({"material": dict(params.organic, coefficientRollingFriction=0.05), "radius": 5e-4},),
            output=str(tmp_path / "out"),
            progress=False,
        )
