"""PyGran: DEM simulation and analysis of granular materials.

Public names: :mod:`simulation`, :mod:`analysis`, :mod:`params`, :mod:`units`,
:mod:`errors`, :data:`hookimpl` and the base classes :class:`Engine`, :class:`SubSystem`
and :class:`ContactModel`.
"""

from importlib.metadata import version as _version

from pygran_core import analysis, errors, params, simulation, units
from pygran_core.analysis import SubSystem
from pygran_core.hookspecs import hookimpl
from pygran_core.simulation import Engine
from pygran_core.simulation.models import ContactModel

__version__ = _version("pygran-core")
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
