"""Build of the compiled kernels (metadata lives in pyproject.toml)."""

import os
from glob import glob

import numpy
from Cython.Build import cythonize
from setuptools import Extension, setup

# The thread team's heuristics (team.h: no spinning while a thread waits for its CPU, moving a
# thread off a teammate's CPU; the Tuner's choice of one thread): PYGRAN_NATIVE_TEAM_HEURISTICS=0
# builds without them.
heuristics = os.environ.get("PYGRAN_NATIVE_TEAM_HEURISTICS", "1")
if heuristics not in ("0", "1"):
    raise SystemExit(f"PYGRAN_NATIVE_TEAM_HEURISTICS: 0 or 1, got {heuristics!r}")

# -O3 without -ffast-math or -march=native, so results are reproducible across machines;
# -fno-math-errno only lets sqrt compile to one instruction, and -fno-trapping-math lets the
# pair law (pair_law.h) compute both sides of a choice and its batched loop vectorise (same results:
# neither changes a value). -ffp-contract=off keeps its AVX2 version from fusing multiply-adds.
openmp = {"extra_compile_args": ["-O3", "-fno-math-errno", "-fopenmp"], "extra_link_args": ["-fopenmp"]}
extensions = [
    Extension("pygran_native._kernels", ["src/pygran_native/_kernels.pyx"], **openmp),
    Extension(  # its own threads (team.h), not OpenMP's
        "pygran_native._solver",
        ["src/pygran_native/_solver.pyx"],
        depends=sorted(glob("src/pygran_native/_*.pxi") + glob("src/pygran_native/*.h")),  # its include files
        include_dirs=[numpy.get_include()],
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION"), ("PG_TEAM_HEURISTICS", heuristics)],
        extra_compile_args=[
            "-O3",
            "-fno-math-errno",
            "-fno-trapping-math",
            "-ffp-contract=off",
            "-pthread",
        ],
        extra_link_args=["-pthread"],
    ),
]
setup(ext_modules=cythonize(extensions, language_level=3))
