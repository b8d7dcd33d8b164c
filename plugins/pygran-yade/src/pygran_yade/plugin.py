"""Registers the YADE engine with PyGran (YADE itself is only touched by the worker process)."""

from pygran_core.hookspecs import EngineSpec, hookimpl
from pygran_yade.launcher import find_launcher


def _create(spec):
    from pygran_yade.engine import YadeEngine

    return YadeEngine(spec)


@hookimpl
def pygran_engines():
    from pygran_yade.engine import YadeEngine

    yield EngineSpec(
        name="yade",
        factory=_create,
        capabilities=YadeEngine.capabilities,
        description="YADE, driven in a worker process",
        locate_solver=find_launcher,
    )
