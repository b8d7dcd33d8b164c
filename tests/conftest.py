"""Shared fixtures: installing the third-party test plugins under tests/plugins for real."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from pygran_core import registry

PLUGIN_SOURCES = Path(__file__).parent / "plugins"


@pytest.fixture(scope="session")
def plugin_target(tmp_path_factory) -> Callable[..., Path]:
    """Install test plugin packages (by folder name) with pip into a fresh target directory."""
    cache: dict[tuple[str, ...], Path] = {}

    def install(*names: str) -> Path:
        if names not in cache:
            target = tmp_path_factory.mktemp("site-" + "-".join(names))
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "pip",
                    "install",
                    "-q",
                    "--no-deps",
                    "--no-build-isolation",
                    "--target",
                    str(target),
                    *(str(PLUGIN_SOURCES / n) for n in names),
                ],
                check=True,
            )
            cache[names] = target
        return cache[names]

    return install


@pytest.fixture
def with_plugins(plugin_target, monkeypatch) -> Iterator[Callable[..., None]]:
    """Make installed test plugins visible to this test (sys.path), with a fresh registry."""

    def activate(*names: str) -> None:
        monkeypatch.syspath_prepend(str(plugin_target(*names)))
        registry.refresh()

    yield activate
    monkeypatch.undo()
    registry.refresh()
