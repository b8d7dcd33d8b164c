"""Contact models: reference implementations engines map to their kernels and are tested against.

``SpringDashpot``, ``HertzMindlin`` (both with simplified-JKR cohesion) and ``ThorntonNing``
(elastic-plastic with JKR adhesion), all derived from :class:`ContactModel`; the pair
mixing rules are in :mod:`~pygran_core.simulation.models.mixing`.
"""

from pygran_core.simulation.models import mixing
from pygran_core.simulation.models.base import ROLLING_MODELS, ContactModel, Impact
from pygran_core.simulation.models.thornton_ning import ThorntonNing
from pygran_core.simulation.models.viscoelastic import HertzMindlin, SpringDashpot

__all__ = [
    "ROLLING_MODELS",
    "ContactModel",
    "HertzMindlin",
    "Impact",
    "SpringDashpot",
    "ThorntonNing",
    "mixing",
]
