"""Tests that need an external solver (LIGGGHTS, YADE) or the core's compiled kernels:
fail in CI, skip with the fix elsewhere."""

from __future__ import annotations

import os
from collections.abc import Callable
from types import ModuleType

import pytest

from pygran_core.errors import EngineError


def in_ci() -> bool:
    """Whether this is a CI run (``CI=true``), where a missing solver is a failure."""
    return os.environ.get("CI", "").strip().lower() in {"1", "true", "yes"}


def require_solver(locate: Callable[[], str]) -> str:
    """Return what ``locate()`` finds; if the solver is missing, fail under CI, else skip.

    ``locate`` is an engine's ``EngineSpec.locate_solver``: it raises :class:`EngineError`
    whose message says how to install the solver.
    """
    try:
        return locate()
    except EngineError as exc:
        if in_ci():
            pytest.fail(f"CI=true and a solver is missing: {exc}", pytrace=False)
        pytest.skip(f"solver not installed: {exc}")


def kernel_path(path: str, module: ModuleType, monkeypatch: pytest.MonkeyPatch) -> str:
    """Make ``module`` (one that takes the core's compiled kernels, ``pygran_core._accel``, as
    ``_accel``) run on ``path``: ``"numpy"`` (the kernels patched away) or ``"compiled"``
    (required under CI, else a skip naming the fix). For a fixture parametrized over both paths."""
    if path == "numpy":
        monkeypatch.setattr(module, "_accel", None)
    elif module._accel is None:
        message = "the core's compiled kernels are not built (pip install -e . with a C compiler)"
        if in_ci():
            pytest.fail(message)
        pytest.skip(message)
    return path
