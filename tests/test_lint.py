"""The repository follows its own ruff configuration (lint rules and formatting) and its typed
Python passes mypy (configured in pyproject.toml: strict about None, no stale ``type: ignore``)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUFF = [sys.executable, "-m", "ruff"]
#: What mypy checks: the core, every plugin package and the test suite's toy engine plugin.
TYPED = [
    "pygran_core",
    "plugins/pygran-readers/src/pygran_readers",
    "plugins/pygran-yade/src/pygran_yade",
    "plugins/pygran-liggghts/src/pygran_liggghts",
    "plugins/pygran-native/src/pygran_native",
    "tests/plugins/pygran-toy/src/pygran_toy",
]


def test_ruff_check():
    result = subprocess.run(
        [*RUFF, "check", "--no-cache", str(ROOT)], capture_output=True, text=True, cwd=ROOT
    )
    assert result.returncode == 0, result.stdout


def test_ruff_format():
    result = subprocess.run(
        [*RUFF, "format", "--check", "--no-cache", str(ROOT)], capture_output=True, text=True, cwd=ROOT
    )
    assert result.returncode == 0, result.stdout


def test_mypy():
    result = subprocess.run([sys.executable, "-m", "mypy", *TYPED], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
