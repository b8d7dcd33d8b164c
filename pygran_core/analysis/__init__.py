"""Post-processing of DEM trajectories: :class:`System`, :class:`Particles`, :class:`Mesh`,
neighbour analysis (:mod:`~pygran_core.analysis.equilibrium`), time series
(:mod:`~pygran_core.analysis.dynamics`), mixing indices (:mod:`~pygran_core.analysis.mixing`)
and image analysis (:mod:`~pygran_core.analysis.imaging`)."""

from pygran_core.analysis import dynamics, equilibrium, imaging, mixing
from pygran_core.analysis.mesh import Mesh
from pygran_core.analysis.particles import Particles
from pygran_core.analysis.subsystem import SubSystem
from pygran_core.analysis.system import System

__all__ = ["Mesh", "Particles", "SubSystem", "System", "dynamics", "equilibrium", "imaging", "mixing"]
