"""PyGran: DEM simulation and analysis of granular materials.

Public names: :mod:`simulation`, :mod:`analysis`, :mod:`params`, :mod:`units`,
:mod:`errors`, :data:`hookimpl` and the base classes :class:`Engine`, :class:`SubSystem`
and :class:`ContactModel`.
"""

from importlib import import_module
from importlib.metadata import version as _version
from typing import Any

from pygran_core import errors, params, simulation, units
from pygran_core.hookspecs import hookimpl
from pygran_core.simulation import Engine
from pygran_core.simulation.models import ContactModel

__version__ = _version("pygran-core")


def __getattr__(name: str) -> Any:
    """``analysis`` (and its ``SubSystem``) load on first use: a simulation script that
    never analyses does not pay for scipy.spatial."""
    if name == "analysis":
        return import_module("pygran_core.analysis")
    if name == "SubSystem":
        return import_module("pygran_core.analysis").SubSystem
    raise AttributeError(f"module 'pygran_core' has no attribute {name!r}")


__all__ = [
    "ContactModel",
    "Engine",
    "SubSystem",
    "analysis",
    "errors",
    "hookimpl",
    "params",
    "simulation",
    "units",
]
