import numpy as np

from pygran_core import Engine, hookimpl
from pygran_core.errors import EngineError
from pygran_core.hookspecs import EngineSpec


class BallisticEngine(Engine):
    """Spheres in free flight under gravity. It has no contact forces: it runs the
    spring-dashpot model only as long as no two spheres touch, and raises when they do."""

    name = "ballistic"
    capabilities = frozenset({"spring-dashpot"})  # honoured while nothing touches (see _advance)

    def __init__(self, spec):  # spec: pygran_core.simulation.specs.SimulationSpec
        super().__init__(spec)
        self.g = spec.gravity.vector if spec.gravity else np.zeros(3)
        self.x, self.v, self.r, self.m = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0)

    def _create(self, request):  # sim.createParticles(1, "single", x, y, z, vel=...)
        if request.style != "single":
            raise self._unsupported(f"createParticles style {request.style!r}")
        self.x = np.vstack([self.x, request.position])
        self.v = np.vstack([self.v, request.velocity])
        species = self.spec.species[request.species - 1]
        radius = request.radius or species.radius.mean
        self.r = np.append(self.r, radius)
        self.m = np.append(self.m, species.density * 4 / 3 * np.pi * radius**3)
        return 1

    def _advance(self, nsteps):  # exact for constant acceleration
        t = nsteps * self.dt
        self.x, self.v = self.x + self.v * t + 0.5 * self.g * t**2, self.v + self.g * t
        gaps = np.linalg.norm(self.x[:, None] - self.x[None], axis=-1) - (self.r[:, None] + self.r[None])
        np.fill_diagonal(gaps, np.inf)
        if (gaps < 0).any():  # checked at the end of each stretch of steps the front end runs
            raise EngineError(f"ballistic engine: no contact forces, and spheres touch at step {self.step}.")

    def _extract(self, quantity):  # per-particle arrays, ordered by id
        n, zeros = len(self.x), np.zeros((len(self.x), 3))
        vectors = {"x": self.x, "v": self.v, "f": self.m[:, None] * self.g, "omega": zeros, "torque": zeros}
        scalars = {"radius": self.r, "mass": self.m, "id": np.arange(1, n + 1), "type": np.ones(n, int)}
        return {**vectors, **scalars}[quantity].copy()


@hookimpl
def pygran_engines():
    yield EngineSpec(name="ballistic", factory=BallisticEngine, capabilities=BallisticEngine.capabilities)
