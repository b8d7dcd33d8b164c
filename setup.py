"""Build of the core's optional compiled kernels, pygran_core._accel (metadata: pyproject.toml)."""

from Cython.Build import cythonize
from setuptools import Extension, setup

# -O3 without -ffast-math or -march=native, so results are reproducible across machines;
# -fno-math-errno lets sqrt compile to one instruction; -ffp-contract=off keeps the sweep's
# dx*dx + dy*dy + dz*dz unfused, so its distances equal numpy's bit for bit.
(kernels,) = cythonize(
    [
        Extension(
            "pygran_core._accel",
            ["pygran_core/_accel.pyx"],
            extra_compile_args=["-O3", "-fno-math-errno", "-ffp-contract=off", "-fopenmp"],
            extra_link_args=["-fopenmp"],
        )
    ],
    language_level=3,
)
# Optional: without a C compiler with OpenMP the core installs without it and uses numpy.
# Set here because cythonize copies only the compile settings of the Extension it is given.
kernels.optional = True
setup(ext_modules=[kernels])
