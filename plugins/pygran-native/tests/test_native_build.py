"""The native plugin's compiled extension is built, importable and linked with OpenMP."""

import os
import subprocess
import sys

from pygran_core import registry


def test_kernels_are_compiled_extension():
    from pygran_native import _kernels

    assert _kernels.__file__.endswith(".so"), _kernels.__file__


def test_openmp_threads_follow_environment():
    code = "from pygran_native import _kernels; print(_kernels.openmp_threads())"
    env = dict(os.environ, OMP_NUM_THREADS="3")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "3"


def test_engine_registered_with_solver_description():
    provided = registry.lookup("engine", "native")
    assert provided.distribution == "pygran-native"
    assert "OpenMP threads" in provided.spec.locate_solver()
