"""Fixtures for every test folder of the repository: the test data in ``tests/data``."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "tests" / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """``tests/data`` (read-only: copy what a test writes next to)."""
    return DATA


@pytest.fixture(scope="module")
def hopper(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A private copy of the real LIGGGHTS hopper run (31 dump frames, 31 mesh frames)."""
    target = tmp_path_factory.mktemp("hopper")
    for path in (DATA / "liggghts-hopper").iterdir():
        shutil.copy(path, target)
    return target
