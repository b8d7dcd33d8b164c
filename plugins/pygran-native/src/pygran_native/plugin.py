"""Registers the native engine with PyGran."""

from pygran_core.hookspecs import EngineSpec, hookimpl


def locate_solver() -> str:
    """The compiled kernels and the OpenMP threads they will use."""
    from pygran_native import _kernels

    return f"compiled kernels {_kernels.__file__} ({_kernels.openmp_threads()} OpenMP threads)"


@hookimpl
def pygran_engines():
    from pygran_native.engine import NativeEngine

    yield EngineSpec(
        name="native",
        factory=NativeEngine,
        capabilities=NativeEngine.capabilities,
        description="PyGran's own Cython DEM engine",
        locate_solver=locate_solver,
    )
