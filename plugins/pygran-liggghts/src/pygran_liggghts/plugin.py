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


def _capabilities() -> frozenset[str]:
    """The engine's capabilities, decided when the registry is first asked for them (whether
    the add-on loads is found in a probe process, which loading the registry does not start)."""
    from pygran_liggghts.engine import capabilities

    return capabilities()


@hookimpl
def pygran_engines():
    yield EngineSpec(
        name="liggghts",
        factory=_create,
        capabilities=_capabilities,
        description="LIGGGHTS 3.x shared library through its C API, in a worker or under mpirun",
        locate_solver=find_library,
    )
