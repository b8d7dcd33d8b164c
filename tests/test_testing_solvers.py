"""A missing solver fails a test under CI=true and skips it elsewhere, saying how to install."""

import subprocess
import sys

TEST = """
from pygran_core.errors import EngineError
from pygran_core.testing.solvers import require_solver

def missing():
    raise EngineError("FooSolver is not installed: apt-get install -y foo")

def test_needs_foo():
    require_solver(missing)
"""


def _run(tmp_path, ci):
    (tmp_path / "test_foo.py").write_text(TEST)
    env = {"CI": ci, "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
    )


def test_missing_solver_fails_in_ci(tmp_path):
    result = _run(tmp_path, "true")
    assert result.returncode == 1
    assert (
        "CI=true and a solver is missing: FooSolver is not installed: apt-get install -y foo" in result.stdout
    )


def test_missing_solver_skips_outside_ci(tmp_path):
    result = _run(tmp_path, "")
    assert result.returncode == 0
    assert "1 skipped" in result.stdout and "apt-get install -y foo" in result.stdout
