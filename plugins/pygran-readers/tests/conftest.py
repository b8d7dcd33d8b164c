"""The real LIGGGHTS fixtures beside the repository (read-only: tests copy what they need)."""

from pathlib import Path

import pytest

FIXTURES = Path(__file__).resolve().parents[3] / ".." / "shared" / "fixtures"


@pytest.fixture(scope="session")
def fixtures() -> Path:
    """``shared/fixtures``; a missing folder fails the test (it is part of the acceptance)."""
    if not (FIXTURES / "liggghts-hopper").is_dir():
        pytest.fail(
            f"The shared fixtures are missing: expected {FIXTURES.resolve()}/liggghts-hopper "
            "(a checkout of the project with shared/ beside the repository)"
        )
    return FIXTURES
