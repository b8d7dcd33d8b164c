"""Post-processing of DEM trajectories: :class:`System`, :class:`Particles`, :class:`Mesh`,
neighbour analysis (:mod:`~pygran_core.analysis.equilibrium`) and time series
(:mod:`~pygran_core.analysis.dynamics`)."""

from pygran_core.analysis import dynamics, equilibrium
from pygran_core.analysis.mesh import Mesh
from pygran_core.analysis.particles import Particles
from pygran_core.analysis.subsystem import SubSystem
from pygran_core.analysis.system import System

__all__ = ["Mesh", "Particles", "SubSystem", "System", "dynamics", "equilibrium"]
