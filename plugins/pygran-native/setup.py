"""Build of the compiled kernels (metadata lives in pyproject.toml)."""

from glob import glob

import numpy
from Cython.Build import cythonize
from setuptools import Extension, setup

# -O3 without -ffast-math or -march=native, so results are reproducible across machines;
# -fno-math-errno only lets sqrt compile to one instruction, and -fno-trapping-math lets the
# batched pair loop (pair_batch.h) compute both sides of a choice and vectorise (same results:
# neither changes a value). -ffp-contract=off keeps its AVX2 version from fusing multiply-adds.
openmp = {"extra_compile_args": ["-O3", "-fno-math-errno", "-fopenmp"], "extra_link_args": ["-fopenmp"]}
extensions = [
    Extension("pygran_native._kernels", ["src/pygran_native/_kernels.pyx"], **openmp),
    Extension(
        "pygran_native._accel",
        ["src/pygran_native/_accel.pyx"],
        **openmp | {"extra_compile_args": [*openmp["extra_compile_args"], "-ffp-contract=off"]},
    ),
    Extension(  # its own threads (team.h), not OpenMP's
        "pygran_native._solver",
        ["src/pygran_native/_solver.pyx"],
        depends=sorted(glob("src/pygran_native/_*.pxi") + glob("src/pygran_native/*.h")),  # its include files
        include_dirs=[numpy.get_include()],
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
        extra_compile_args=["-O3", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=off", "-pthread", "-fopenmp"],
        extra_link_args=["-pthread", "-fopenmp"],
    ),
]
setup(ext_modules=cythonize(extensions, language_level=3))
