"""``PyGran``: the import name of PyGran 1.x, an alias of :mod:`pygran_core`.

Scripts written for the original PyGran run unchanged: ``import PyGran``,
``from PyGran import simulation, analysis, params``, ``import PyGran.simulation as sim`` and
``from PyGran.simulation.models import HertzMindlin`` give the very modules and classes of
``pygran_core`` (never second copies), as do the original demos' ``PyGran.modules.params``.
Nothing in PyGran itself imports this package.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType
from typing import Any

import pygran_core

#: Alias prefixes, longest first, and the ``pygran_core`` prefix each stands for.
_PREFIXES = ((f"{__name__}.modules.", "pygran_core."), (f"{__name__}.", "pygran_core."))


def _target(alias: str) -> str | None:
    """The ``pygran_core`` module an alias such as ``PyGran.simulation.models`` stands for."""
    if alias == f"{__name__}.modules":
        return "pygran_core"
    for prefix, real in _PREFIXES:
        if alias.startswith(prefix):
            return real + alias[len(prefix) :]
    return None


class _AliasFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``PyGran.x.y`` as the module ``pygran_core.x.y`` itself."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        real = _target(fullname)
        if real is None or importlib.util.find_spec(real) is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, self, origin=real)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(spec.origin)
        spec.loader_state = module.__spec__  # the import machinery sets the alias's spec on it
        return module

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__ = module.__spec__.loader_state  # the module's own spec back


if not any(isinstance(finder, _AliasFinder) for finder in sys.meta_path):
    # ahead of the path finder, which would load a second copy of a submodule through the
    # aliased parent's __path__
    sys.meta_path.insert(0, _AliasFinder())


def __getattr__(name: str) -> Any:
    """Every public name of :mod:`pygran_core` (``simulation``, ``analysis``, ``params``, ...)."""
    return getattr(pygran_core, name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(pygran_core.__all__))
