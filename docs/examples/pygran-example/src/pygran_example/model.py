import math

from pygran_core import hookimpl
from pygran_core.hookspecs import ModelSpec
from pygran_core.simulation.models import SpringDashpot


class StiffSpringDashpot(SpringDashpot):
    """LIGGGHTS' hooke spring-dashpot with ``factor`` times the stiffness, same restitution."""

    factor = 10.0

    def __init__(self, material, *, partner=None, limitForce=False):
        super().__init__(material, partner=partner, limitForce=limitForce)
        self.kn *= self.factor
        self.gamman = -self.beta * math.sqrt(4 * self.effective_mass * self.kn)
        self.kt, self.gammat = self.kn, self.gamman


@hookimpl
def pygran_models():
    yield ModelSpec(
        name="StiffSpringDashpot", model=StiffSpringDashpot, description="hooke spring-dashpot, 10x stiffer"
    )
