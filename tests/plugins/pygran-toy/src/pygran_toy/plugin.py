"""A complete third-party plugin: a toy engine (ballistic point masses), a reader and a writer.

The ``.toy`` format is a text file per frame: a ``# toy`` line, then ``x y z`` per particle.
"""

from pathlib import Path

import numpy as np

from pygran_core import Engine, hookimpl
from pygran_core.hookspecs import EngineSpec, ReaderSpec, WriterSpec
from pygran_core.io import Frame, Trajectory, TrajectoryWriter


class ToyEngine(Engine):
    """Point masses in free fall (exact constant-acceleration update); contacts are ignored."""

    name = "toy"
    capabilities = frozenset({"spring-dashpot", "multisphere"})

    def __init__(self, spec):
        super().__init__(spec)
        self.gravity = spec.gravity.vector if spec.gravity is not None else np.zeros(3)
        self.x = np.zeros((0, 3))
        self.v = np.zeros((0, 3))
        self.radius = np.zeros(0)

    def _create(self, request):
        if request.style != "single":
            raise self._unsupported(f"createParticles style {request.style!r}")
        species = self.spec.species[request.species - 1]
        self.x = np.vstack([self.x, request.position])
        self.v = np.vstack([self.v, request.velocity])
        self.radius = np.append(self.radius, request.radius or species.radius.mean)
        return 1

    def _advance(self, nsteps):
        t = nsteps * self.dt
        self.x = self.x + self.v * t + 0.5 * self.gravity * t**2
        self.v = self.v + self.gravity * t

    def _extract(self, quantity):
        n = len(self.x)
        values = {
            "x": self.x,
            "v": self.v,
            "radius": self.radius,
            "id": np.arange(1, n + 1),
            "type": np.ones(n, int),
            "mass": np.ones(n),
            "omega": np.zeros((n, 3)),
            "f": np.tile(self.gravity, (n, 1)),
            "torque": np.zeros((n, 3)),
        }
        return values[quantity].copy()


class ToyTrajectory(Trajectory):
    def __init__(self, paths, **options):
        self.paths = list(paths)

    @property
    def n_frames(self):
        return len(self.paths)

    def _read_frame(self, index):
        xyz = np.loadtxt(self.paths[index], comments="#", ndmin=2)
        return Frame({"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}, timestep=index)


class ToyWriter(TrajectoryWriter):
    def __init__(self, path, **options):
        self.path = Path(path)
        self.count = 0

    def write_frame(self, frame):
        xyz = np.column_stack([frame.arrays[k] for k in "xyz"])
        target = self.path.with_name(f"{self.path.stem}{self.count}{self.path.suffix}")
        np.savetxt(target, xyz, header="toy")
        self.count += 1


def can_open(path):
    try:
        with open(path, "rb") as handle:
            return handle.read(5) == b"# toy"
    except OSError:
        return False


@hookimpl
def pygran_engines():
    yield EngineSpec(name="toy", factory=ToyEngine, capabilities=ToyEngine.capabilities)


@hookimpl
def pygran_readers():
    yield ReaderSpec(name="toy", extensions=(".toy",), open=ToyTrajectory, can_open=can_open)


@hookimpl
def pygran_writers():
    yield WriterSpec(name="toy", extensions=(".toy",), open=ToyWriter)
