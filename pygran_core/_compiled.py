"""The optional compiled kernels the core uses when pygran-native is installed.

``kernels`` is ``pygran_native._accel`` (the cell-list pair sweep behind the RDF and
neighbour analysis, the parser of a dump's atom rows, and the coarse-graining deposits of
particles and contact lines onto Cartesian grids), or None without it. Every caller
has a numpy path that gives the same results, so the core never needs a compiler.
"""

import importlib
from types import ModuleType


def _load() -> ModuleType | None:
    try:
        return importlib.import_module("pygran_native._accel")
    except ImportError:  # pragma: no cover - depends on the installation
        return None


kernels = _load()
