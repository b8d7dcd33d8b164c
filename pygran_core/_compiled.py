"""The core's optional compiled kernels, ``kernels``: ``pygran_core._accel`` (the cell-list pair
sweep behind the RDF and neighbour analysis, the parser of a dump's atom rows, and the
coarse-graining deposits of particles and contact lines onto Cartesian grids), or None when
it was not built (no C compiler with OpenMP at install time). Every caller has a numpy path
that gives the same results.
"""

import os
from types import ModuleType


def _load() -> ModuleType | None:
    # OpenMP's threads sleep while they wait (passive policy) unless the user chose a policy:
    # spinning threads take the cores a busy machine's other programs need. libgomp reads
    # OMP_WAIT_POLICY once, when it is first loaded (here or by pygran-native, which sets the
    # same), so the variable is set for that moment only.
    chosen = "OMP_WAIT_POLICY" in os.environ
    if not chosen:
        os.environ["OMP_WAIT_POLICY"] = "passive"
    try:
        from pygran_core import _accel
    except ImportError:  # pragma: no cover - depends on the installation
        return None
    finally:
        if not chosen:
            del os.environ["OMP_WAIT_POLICY"]
    return _accel


kernels = _load()
