"""Registers the native engine with PyGran."""

from pygran_core.errors import UnsupportedFeature
from pygran_core.hookspecs import EngineSpec, hookimpl


def locate_solver() -> str:
    """The compiled kernels and the OpenMP threads they will use."""
    from pygran_native import _kernels

    return f"compiled kernels {_kernels.__file__} ({_kernels.openmp_threads()} OpenMP threads)"


def _create(spec: object) -> None:
    raise UnsupportedFeature(
        "The native engine's time-step loop is not part of this pygran-native release yet"
    )


@hookimpl
def pygran_engines():
    yield EngineSpec(
        name="native",
        factory=_create,
        description="PyGran's own Cython/OpenMP DEM engine",
        locate_solver=locate_solver,
    )
