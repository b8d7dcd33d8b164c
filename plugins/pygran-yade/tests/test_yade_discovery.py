"""Finding the YADE launcher: explicit path, PATH, and the install message when missing."""

import pytest
from pygran_yade.launcher import LAUNCHER_ENV, find_launcher

from pygran_core import registry
from pygran_core.errors import EngineError


def test_registered():
    assert registry.lookup("engine", "yade").distribution == "pygran-yade"


def test_explicit_launcher_wins(tmp_path, monkeypatch):
    launcher = tmp_path / "yade"
    launcher.write_text("#!/bin/sh\n")
    launcher.chmod(0o755)
    monkeypatch.setenv(LAUNCHER_ENV, str(launcher))
    assert find_launcher() == str(launcher)


def test_explicit_launcher_must_be_executable(tmp_path, monkeypatch):
    launcher = tmp_path / "yade"
    launcher.write_text("")
    monkeypatch.setenv(LAUNCHER_ENV, str(launcher))
    with pytest.raises(EngineError, match="not an executable"):
        find_launcher()


def test_missing_yade_says_how_to_install(monkeypatch):
    monkeypatch.delenv(LAUNCHER_ENV, raising=False)
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(EngineError, match="apt-get install -y yade"):
        find_launcher()
