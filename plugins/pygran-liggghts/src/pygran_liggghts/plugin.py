"""Registers the LIGGGHTS engine with PyGran."""

from pygran_core.errors import UnsupportedFeature
from pygran_core.hookspecs import EngineSpec, hookimpl
from pygran_liggghts.library import find_library


def _create(spec: object) -> None:
    raise UnsupportedFeature(
        "The LIGGGHTS engine's front end is not part of this pygran-liggghts release yet"
    )


@hookimpl
def pygran_engines():
    yield EngineSpec(
        name="liggghts",
        factory=_create,
        description="LIGGGHTS 3.x shared library through its C API",
        locate_solver=find_library,
    )
