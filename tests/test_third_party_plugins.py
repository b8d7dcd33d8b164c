"""Third-party plugins installed with pip: found by name; conflicts and failures are clear."""

import warnings

import numpy as np
import pytest

from pygran_core import io, params, registry, simulation
from pygran_core.errors import PluginError, PluginNotFound
from pygran_core.registry import PluginLoadWarning
from pygran_core.simulation.models import SpringDashpot


def test_toy_engine_reader_writer_found_by_name(with_plugins, tmp_path):
    with_plugins("pygran-toy")
    provided = registry.lookup("engine", "toy")
    assert (provided.distribution, provided.version, provided.plugin) == ("pygran-toy", "0.0.1", "toy")
    species = (
        {
            "material": dict(params.glass, coefficientRollingFriction=0.0, cohesionEnergyDensity=0.0),
            "radius": 1e-3,
        },
    )
    with simulation.DEM(
        engine="toy",
        box=(-1, 1, -1, 1, 0, 2),
        gravity=(9.81, 0, 0, -1),
        species=species,
        output=str(tmp_path / "out"),
        dt=1e-3,
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.createParticles(1, "single", 0, 0, 1, vel=(1, 0, 0))
        sim.run(100)
        np.testing.assert_allclose(sim.extractCoords()[0], [0.1, 0, 1 - 0.5 * 9.81 * 0.1**2])

    with io.open_writer(tmp_path / "frame.toy") as writer:
        writer.write_frame(io.Frame({"x": np.arange(3.0), "y": np.zeros(3), "z": np.ones(3)}))
    trajectory = io.open_trajectory(tmp_path / "frame*.toy")
    assert trajectory.n_frames == 1
    np.testing.assert_array_equal(trajectory[0].arrays["x"], [0, 1, 2])


def test_reader_chosen_by_content_when_extension_is_unknown(with_plugins, tmp_path):
    with_plugins("pygran-toy")
    path = tmp_path / "snapshot.txt"
    path.write_text("# toy\n1 2 3\n")
    assert registry.reader_for(path).name == "toy"
    other = tmp_path / "other.txt"
    other.write_text("1 2 3\n")
    with pytest.raises(PluginNotFound, match="No installed reader recognises .*other.txt.*toy \\(.toy\\)"):
        registry.reader_for(other)
    assert registry.reader_for(other, format="toy").name == "toy"


def test_capability_error_names_engines_that_can(with_plugins, tmp_path):
    from pygran_core.errors import UnsupportedFeature

    with_plugins("pygran-toy")
    able = [name for name in registry.engines_with("restart") if name != "toy"]
    with simulation.DEM(engine="toy", box=(0, 1, 0, 1, 0, 1), output=str(tmp_path), progress=False) as sim:
        sim.engine.require("spring-dashpot")
        with pytest.raises(UnsupportedFeature) as info:
            sim.engine.require("restart")
    expected = f"Engines that can: {', '.join(able)}." if able else "No installed engine can."
    assert str(info.value) == f"The toy engine does not support restart (capability 'restart'). {expected}"


def test_duplicate_item_name_names_both_distributions(with_plugins):
    with_plugins("pygran-toy", "pygran-toy-clash")
    with pytest.raises(PluginError) as info:
        registry.available("engine")
    text = str(info.value)
    assert "engine name 'toy' is provided twice" in text
    assert "pygran-toy 0.0.1" in text and "pygran-toy-clash 0.0.1" in text


def test_duplicate_plugin_name_names_both_distributions(with_plugins):
    with_plugins("pygran-toy", "pygran-toy-twin")
    with pytest.raises(PluginError, match="named 'toy': pygran-toy(-twin)? and pygran-toy(-twin)?"):
        registry.plugins()


def test_failing_plugin_is_a_warning_naming_it(with_plugins, monkeypatch):
    monkeypatch.delenv(registry.STRICT_ENV, raising=False)
    with_plugins("pygran-broken")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loaded = registry.plugins()
    messages = [str(w.message) for w in caught if issubclass(w.category, PluginLoadWarning)]
    assert "broken" not in loaded and "native" in loaded
    assert len(messages) == 1
    assert "'broken' from pygran-broken 0.0.1 failed to import" in messages[0]
    assert "libbroken.so.1" in messages[0]


def test_failing_plugin_is_an_error_when_strict(with_plugins, monkeypatch):
    monkeypatch.setenv(registry.STRICT_ENV, "1")
    with_plugins("pygran-broken")
    with pytest.raises(PluginError, match="pygran-broken 0.0.1 failed to import.*PYGRAN_STRICT_PLUGINS"):
        registry.plugins()


def oblique_collision(tmp_path, friction):
    """Two organic spheres (r = 1 mm) meeting head-on at 0.1 m/s each, their paths half a
    diameter apart, on the toy engine: masses, positions, velocities and spins after it."""
    material = dict(params.organic, coefficientFriction=friction)
    sphere = dict(material, radius=1e-3)
    dt = SpringDashpot(material=sphere, partner=sphere).contactTime() / 100
    with simulation.DEM(
        engine="toy",
        model=SpringDashpot,
        box=(-5e-3, 5e-3, -5e-3, 5e-3, -5e-3, 5e-3),
        species=({"material": material, "radius": 1e-3},),
        output=str(tmp_path / f"mu{friction}"),
        dt=dt,
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.createParticles(1, "single", -1.5e-3, -0.5e-3, 0.0, vel=(0.1, 0.0, 0.0))
        sim.createParticles(1, "single", 1.5e-3, 0.5e-3, 0.0, vel=(-0.1, 0.0, 0.0))
        sim.run(round(0.01 / dt))  # they touch after 6.3 ms
        return sim.engine.extract("mass"), sim.extractCoords(), sim.extractVelocities(), sim.extractOmegas()


def test_toy_engine_contacts_have_friction(with_plugins, tmp_path):
    """The toy's spring-dashpot contact: momentum kept; without friction no spin; with it both
    spheres spin the same way, from a tangential impulse within the Coulomb limit, and the
    angular momentum is kept to within the overlap over the radius (the torque's lever is R)."""
    with_plugins("pygran-toy")
    mass, x, v, w = oblique_collision(tmp_path, 0.0)
    np.testing.assert_allclose(v.sum(axis=0), 0.0, atol=1e-15)
    np.testing.assert_array_equal(w, 0.0)
    assert np.all(v[:, 1] * [1, -1] < -0.01), v  # deflected apart

    mass, x, v, w = oblique_collision(tmp_path, 0.5)
    assert mass == pytest.approx(4 / 3 * np.pi * 1e-9 * params.organic["density"], rel=1e-12)
    np.testing.assert_allclose(v.sum(axis=0), 0.0, atol=1e-15)
    np.testing.assert_allclose(w[:, :2], 0.0, atol=1e-12)
    assert w[0, 2] > 0 and w[1, 2] == pytest.approx(w[0, 2], rel=1e-9), w
    normal = np.array([np.sqrt(3) / 2, 0.5, 0.0])  # from the first to the second at contact
    normal_impulse = mass[0] * np.dot([0.1, 0.0, 0.0] - v[0], normal)
    tangential_impulse = 0.4 * mass[0] * 1e-3 * w[0, 2]  # I w / R
    assert 0 < tangential_impulse <= 0.5 * normal_impulse, (tangential_impulse, normal_impulse)
    spin = 0.4 * mass * 1e-6 * w[:, 2]
    momentum = np.sum(mass * np.cross(x, v)[:, 2]) + spin.sum()
    assert momentum == pytest.approx(2 * mass[0] * 0.1 * 0.5e-3, rel=0.01)
