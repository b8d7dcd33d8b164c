"""The native plugin's compiled extension is built, importable and linked with OpenMP."""

import os
import subprocess
import sys

import pytest

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


@pytest.mark.parametrize(
    ("chosen", "policy"), [(None, "PASSIVE"), ("active", "ACTIVE"), ("passive", "PASSIVE")]
)
def test_openmp_waits_passively_unless_the_user_chose(chosen, policy):
    # libgomp prints the policy it runs with (OMP_DISPLAY_ENV); the environment is left as it was
    code = "import os, pygran_native; print(os.environ.get('OMP_WAIT_POLICY'))"
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"} | {"OMP_DISPLAY_ENV": "true"}
    if chosen:
        env["OMP_WAIT_POLICY"] = chosen
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert f"OMP_WAIT_POLICY = '{policy}'" in out.stderr
    assert out.stdout.strip() == str(chosen)
