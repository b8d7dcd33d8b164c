"""pygran-native: PyGran's embedded DEM engine (compiled Cython kernels on its own threads)."""
