"""Post-processing of DEM trajectories: :class:`System`, :class:`Particles`, :class:`Mesh`,
neighbour analysis (:mod:`~pygran_core.analysis.equilibrium`), time series
(:mod:`~pygran_core.analysis.dynamics`), mixing indices (:mod:`~pygran_core.analysis.mixing`),
image analysis (:mod:`~pygran_core.analysis.imaging`), plots (:mod:`~pygran_core.analysis.plot`),
a drum's angle of repose (:mod:`~pygran_core.analysis.drum`), contact records
(:class:`Contacts`) and continuum fields (:mod:`~pygran_core.analysis.coarse_grain`)."""

from pygran_core.analysis import coarse_grain, drum, dynamics, equilibrium, imaging, mixing, plot
from pygran_core.analysis.coarse_grain import CoarseGrain, Fields, Grid1D, Grid2D, Grid3D, GridCylindrical
from pygran_core.analysis.contacts import Contacts
from pygran_core.analysis.mesh import Mesh
from pygran_core.analysis.particles import Particles
from pygran_core.analysis.subsystem import SubSystem
from pygran_core.analysis.system import System

__all__ = [
    "CoarseGrain",
    "Contacts",
    "Fields",
    "Grid1D",
    "Grid2D",
    "Grid3D",
    "GridCylindrical",
    "Mesh",
    "Particles",
    "SubSystem",
    "System",
    "coarse_grain",
    "drum",
    "dynamics",
    "equilibrium",
    "imaging",
    "mixing",
    "plot",
]
