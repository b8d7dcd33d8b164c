"""The readers plugin is discovered through its entry point."""

from pygran_core import registry


def test_registered():
    assert registry.plugins()["readers"][0] == "pygran-readers"
