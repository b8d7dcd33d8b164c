"""DEM simulation: the engine-neutral front end ``DEM``, the engine base class, the contact
models (also here, as the original PyGran's scripts use them: ``simulation.ThorntonNing``) and
parameter studies (:class:`~pygran_core.simulation.study.Study`)."""

from pygran_core.simulation import geometry, models, study
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.engine import Engine, Handle, Monitor
from pygran_core.simulation.models import HertzMindlin, SpringDashpot, ThorntonNing
from pygran_core.simulation.study import Study

__all__ = [
    "DEM",
    "Engine",
    "HertzMindlin",
    "Handle",
    "Monitor",
    "SpringDashpot",
    "Study",
    "ThorntonNing",
    "geometry",
    "models",
    "study",
]
