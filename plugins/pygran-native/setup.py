"""Build of the compiled kernels (metadata lives in pyproject.toml)."""

from glob import glob

import numpy
from Cython.Build import cythonize
from setuptools import Extension, setup

# -O3 without -ffast-math or -march=native, so results are reproducible across machines;
# -fno-math-errno only lets sqrt compile to one instruction (same results).
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
        depends=["src/pygran_native/team.h", *sorted(glob("src/pygran_native/_*.pxi"))],  # its include files
        include_dirs=[numpy.get_include()],
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
        extra_compile_args=["-O3", "-fno-math-errno", "-pthread"],
        extra_link_args=["-pthread"],
    ),
]
setup(ext_modules=cythonize(extensions, language_level=3))
