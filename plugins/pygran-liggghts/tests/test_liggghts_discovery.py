"""Finding libliggghts: explicit path, loader, and the install message when missing."""

import subprocess
import sys

import pytest
from pygran_liggghts.library import LIBRARY_ENV, find_library

from pygran_core import registry
from pygran_core.errors import EngineError


def test_registered():
    assert registry.lookup("engine", "liggghts").distribution == "pygran-liggghts"


def test_explicit_path_wins(tmp_path, monkeypatch):
    lib = tmp_path / "libliggghts.so"
    lib.write_bytes(b"")
    monkeypatch.setenv(LIBRARY_ENV, str(lib))
    assert find_library() == str(lib)


def test_explicit_path_must_exist(tmp_path, monkeypatch):
    monkeypatch.setenv(LIBRARY_ENV, str(tmp_path / "nope.so"))
    with pytest.raises(EngineError, match="is not a file"):
        find_library()


def test_missing_library_says_how_to_install(monkeypatch):
    monkeypatch.delenv(LIBRARY_ENV, raising=False)
    monkeypatch.setattr("ctypes.util.find_library", lambda name: None)
    with pytest.raises(EngineError, match="apt-get install -y liggghts libliggghts-dev"):
        find_library()


def test_worker_imports_no_pygran_core():
    """The worker starts in the time of numpy, mpi4py and the library, not of PyGran's imports."""
    code = (
        "import sys, pygran_liggghts.worker, pygran_liggghts.binding; "
        "print(sorted(m for m in sys.modules if m.startswith('pygran_core')))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
