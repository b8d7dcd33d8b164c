"""Registers the LIGGGHTS engine with PyGran."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pygran_core.hookspecs import EngineSpec, hookimpl
from pygran_liggghts.library import find_library

if TYPE_CHECKING:
    from pygran_core.simulation.specs import SimulationSpec
    from pygran_liggghts.engine import LiggghtsEngine


def _create(spec: SimulationSpec) -> LiggghtsEngine:
    """The engine for ``spec`` (imported here: the plugin module stays cheap to import)."""
    from pygran_liggghts.engine import LiggghtsEngine

    return LiggghtsEngine(spec)


@hookimpl
def pygran_engines():
    from pygran_liggghts.engine import LiggghtsEngine

    yield EngineSpec(
        name="liggghts",
        factory=_create,
        capabilities=LiggghtsEngine.capabilities,
        description="LIGGGHTS 3.x shared library through its C API, in a worker or under mpirun",
        locate_solver=find_library,
    )
