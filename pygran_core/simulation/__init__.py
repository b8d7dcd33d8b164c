"""DEM simulation: the engine base class and the contact models."""

from pygran_core.simulation import models
from pygran_core.simulation.engine import Engine, Handle

__all__ = ["Engine", "Handle", "models"]
