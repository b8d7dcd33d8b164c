"""A complete third-party plugin: a toy engine (ballistic point masses), a reader and a writer.

The ``.toy`` format is a text file per frame: a ``# toy`` line, then ``x y z`` per particle.
"""

from pathlib import Path

import numpy as np

from pygran_core import Engine, hookimpl
from pygran_core.hookspecs import EngineSpec, ReaderSpec, WriterSpec
from pygran_core.io import Frame, Trajectory, TrajectoryWriter

GRAVITY = np.array([0.0, 0.0, -9.81])


class ToyEngine(Engine):
    """Point masses in free fall: exact constant-acceleration update, no contacts."""

    name = "toy"
    capabilities = frozenset({"multisphere"})

    def __init__(self, output, **options):
        super().__init__(output, **options)
        self.positions = np.zeros((0, 3))
        self.velocities = np.zeros((0, 3))

    def add_particle(self, position, velocity=(0.0, 0.0, 0.0)):
        self.positions = np.vstack([self.positions, position])
        self.velocities = np.vstack([self.velocities, velocity])
        return self._new_handle("particle", f"p{len(self.positions)}")

    def _advance(self, nsteps):
        t = nsteps * self.dt
        self.positions = self.positions + self.velocities * t + 0.5 * GRAVITY * t**2
        self.velocities = self.velocities + GRAVITY * t

    def _remove(self, handle):
        index = int(handle.label[1:]) - 1
        self.positions[index] = np.nan


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
