"""DEM simulation: the engine-neutral front end ``DEM``, the engine base class and the contact
models (also here, as the original PyGran's scripts use them: ``simulation.ThorntonNing``)."""

from pygran_core.simulation import models
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.engine import Engine, Handle, Monitor
from pygran_core.simulation.models import HertzMindlin, SpringDashpot, ThorntonNing

__all__ = ["DEM", "Engine", "HertzMindlin", "Handle", "Monitor", "SpringDashpot", "ThorntonNing", "models"]
