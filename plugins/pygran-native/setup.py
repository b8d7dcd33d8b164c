"""Build of the compiled kernels (metadata lives in pyproject.toml)."""

from Cython.Build import cythonize
from setuptools import Extension, setup

openmp = {"extra_compile_args": ["-O3", "-fopenmp"], "extra_link_args": ["-fopenmp"]}
extensions = [Extension("pygran_native._kernels", ["src/pygran_native/_kernels.pyx"], **openmp)]
setup(ext_modules=cythonize(extensions, language_level=3))
