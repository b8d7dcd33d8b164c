"""The optional compiled kernels the core uses when pygran-native is installed.

``kernels`` is ``pygran_native._accel`` (the cell-list pair sweep behind the RDF and
neighbour analysis, and the parser of a dump's atom rows), or None without it. Every caller
has a numpy path that gives the same results, so the core never needs a compiler.
"""

from types import ModuleType

kernels: ModuleType | None
try:
    from pygran_native import _accel as kernels
except ImportError:  # pragma: no cover - depends on the installation
    kernels = None
