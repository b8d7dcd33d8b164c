"""Discovery of the first-party plugins and lookups by name."""

from pathlib import Path

import pytest

from pygran_core import registry
from pygran_core.errors import PluginNotFound
from pygran_core.hookspecs import EngineSpec, ReaderSpec

FIRST_PARTY = {
    "native": "pygran-native",
    "liggghts": "pygran-liggghts",
    "yade": "pygran-yade",
    "readers": "pygran-readers",
}


def test_all_four_plugins_discovered():
    loaded = registry.plugins()
    for plugin, dist in FIRST_PARTY.items():
        assert loaded[plugin][0] == dist


def test_engines_come_from_their_distributions():
    engines = registry.available("engine")
    assert {name: p.distribution for name, p in engines.items() if name in FIRST_PARTY} == {
        "native": "pygran-native",
        "liggghts": "pygran-liggghts",
        "yade": "pygran-yade",
    }


def test_builtin_models_registered_by_core():
    models = registry.available("model")
    assert {"SpringDashpot", "HertzMindlin", "ThorntonNing"} <= set(models)
    assert all(models[m].distribution == "pygran-core" for m in ("SpringDashpot", "HertzMindlin"))


def test_plugin_manager_is_cached_until_refresh():
    first = registry.get_plugin_manager()
    assert registry.get_plugin_manager() is first
    registry.refresh()
    assert registry.get_plugin_manager() is not first


def test_unknown_engine_lists_installed_and_suggests():
    with pytest.raises(PluginNotFound) as info:
        registry.get_engine("ligghts")
    text = str(info.value)
    assert "No engine named 'ligghts'" in text
    assert "Did you mean 'liggghts'?" in text
    assert "native (pygran-native 0.1.0)" in text


def test_missing_first_party_plugin_says_how_to_install(monkeypatch):
    monkeypatch.setattr(registry, "available", lambda kind: {})
    with pytest.raises(PluginNotFound, match=r"pip install \./plugins/pygran-liggghts"):
        registry.get_engine("liggghts")


def test_unknown_kind_rejected():
    with pytest.raises(ValueError, match="Unknown plugin kind 'engines'"):
        registry.available("engines")


@pytest.mark.parametrize(
    ("name", "chain"),
    [("a.dump", [".dump"]), ("traj.dump.gz", [".dump.gz", ".gz"]), ("README", []), ("m.VTK", [".vtk"])],
)
def test_extension_chain(name, chain):
    assert registry.extension_chain(Path(name)) == chain


def test_records_validate_themselves():
    with pytest.raises(ValueError, match="unknown capabilities"):
        EngineSpec(name="x", factory=object, capabilities=frozenset({"teleport"}))
    with pytest.raises(ValueError, match="must start with '.'"):
        ReaderSpec(name="x", extensions=("dump",), open=object)
    with pytest.raises(ValueError, match="identifier-like"):
        EngineSpec(name="two words", factory=object)
