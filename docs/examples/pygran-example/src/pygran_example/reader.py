from pathlib import Path

import numpy as np

from pygran_core import hookimpl
from pygran_core.hookspecs import ReaderSpec
from pygran_core.io import Frame, Trajectory


class XYZTrajectory(Trajectory):
    """XYZ files: per frame a count line, a comment line, then ``element x y z`` lines."""

    def __init__(self, paths, **options):
        self.frames = []  # small files: read at once (large formats index frame offsets)
        for path in paths:
            lines = Path(path).read_text().splitlines()
            while lines and lines[0].strip():
                n = int(lines[0])
                self.frames.append(np.array([row.split()[1:4] for row in lines[2 : 2 + n]], float))
                lines = lines[2 + n :]

    @property
    def n_frames(self):
        return len(self.frames)

    def _read_frame(self, index):
        xyz = self.frames[index].reshape(-1, 3)
        ids = np.arange(1, len(xyz) + 1)
        return Frame({"id": ids, "x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}, timestep=index)


@hookimpl
def pygran_readers():
    yield ReaderSpec(name="xyz", extensions=(".xyz",), open=XYZTrajectory)
