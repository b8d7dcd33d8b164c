"""The built-in contact models, registered like any plugin's (entry-point group ``pygran.models``)."""

from __future__ import annotations

from collections.abc import Iterator

from pygran_core.hookspecs import ModelSpec, hookimpl
from pygran_core.simulation.models import HertzMindlin, SpringDashpot, ThorntonNing


@hookimpl
def pygran_models() -> Iterator[ModelSpec]:
    yield ModelSpec("SpringDashpot", SpringDashpot, "linear spring-dashpot (LIGGGHTS hooke), SJKR cohesion")
    yield ModelSpec(
        "HertzMindlin", HertzMindlin, "Hertz-Mindlin with viscous damping (LIGGGHTS hertz), SJKR cohesion"
    )
    yield ModelSpec("ThorntonNing", ThorntonNing, "elastic-plastic Thornton-Ning with JKR adhesion")
