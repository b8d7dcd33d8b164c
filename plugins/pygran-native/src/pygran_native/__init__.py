"""pygran-native: PyGran's embedded DEM engine (compiled Cython/OpenMP kernels)."""

import os

# OpenMP's threads sleep while they wait (passive policy) unless the user chose a policy:
# spinning threads take the cores a busy machine's other programs need. libgomp reads
# OMP_WAIT_POLICY once, when it is loaded (here, with the first compiled module), so the
# variable is set for that moment only and the environment is left as it was.
_policy_chosen = "OMP_WAIT_POLICY" in os.environ
if not _policy_chosen:
    os.environ["OMP_WAIT_POLICY"] = "passive"
try:
    from pygran_native import _kernels as _kernels
finally:
    if not _policy_chosen:
        del os.environ["OMP_WAIT_POLICY"]
