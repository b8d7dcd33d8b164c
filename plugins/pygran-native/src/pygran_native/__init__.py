"""pygran-native: PyGran's embedded DEM engine (compiled Cython/OpenMP kernels)."""
