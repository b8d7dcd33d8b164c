"""Post-processing of DEM trajectories."""

from pygran_core.analysis.subsystem import SubSystem

__all__ = ["SubSystem"]
