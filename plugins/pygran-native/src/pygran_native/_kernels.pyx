# cython: boundscheck=False, wraparound=False
"""Compiled kernels of the native engine."""

cimport openmp


def openmp_threads() -> int:
    """Threads an OpenMP parallel region will use (``OMP_NUM_THREADS`` or all cores)."""
    return openmp.omp_get_max_threads()
