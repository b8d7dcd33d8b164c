"""Registers the YADE engine with PyGran."""

from pygran_core.errors import UnsupportedFeature
from pygran_core.hookspecs import EngineSpec, hookimpl
from pygran_yade.launcher import find_launcher


def _create(spec: object) -> None:
    raise UnsupportedFeature("The YADE engine's front end is not part of this pygran-yade release yet")


@hookimpl
def pygran_engines():
    yield EngineSpec(
        name="yade",
        factory=_create,
        description="YADE, driven in a worker process",
        locate_solver=find_launcher,
    )
