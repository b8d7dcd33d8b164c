"""Installing one plugin alone into a fresh environment, then uninstalling it."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(*args, **kwargs):
    return subprocess.run([str(a) for a in args], check=True, capture_output=True, text=True, **kwargs)


@pytest.mark.slow
def test_readers_plugin_alone_then_uninstalled(tmp_path):
    venv = tmp_path / "venv"
    _run(sys.executable, "-m", "venv", venv)
    python, pygran = venv / "bin" / "python", venv / "bin" / "pygran"
    _run(python, "-m", "pip", "install", "-q", "--no-build-isolation", "setuptools>=77", "wheel")
    _run(python, "-m", "pip", "install", "-q", "--no-build-isolation", ROOT)
    _run(python, "-m", "pip", "install", "-q", "--no-build-isolation", ROOT / "plugins" / "pygran-readers")

    listing = _run(pygran, "plugins").stdout
    assert "readers          pygran-readers 0.1.0" in listing
    for absent in ("pygran-native", "pygran-liggghts", "pygran-yade"):
        assert absent not in listing

    _run(python, "-m", "pip", "uninstall", "-y", "-q", "pygran-readers")
    assert "pygran-readers" not in _run(pygran, "plugins").stdout
