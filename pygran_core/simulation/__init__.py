"""DEM simulation: the engine-neutral front end ``DEM``, the engine base class and the contact models."""

from pygran_core.simulation import models
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.engine import Engine, Handle, Monitor

__all__ = ["DEM", "Engine", "Handle", "Monitor", "models"]
