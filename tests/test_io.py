"""The trajectory base class and file-pattern expansion."""

import numpy as np
import pytest

from pygran_core.errors import ReadError
from pygran_core.io import Frame, Trajectory, expand_paths, natural_key


class Counting(Trajectory):
    def __init__(self, n):
        self.n = n
        self.reads = []

    @property
    def n_frames(self):
        return self.n

    def _read_frame(self, index):
        self.reads.append(index)
        return Frame({"id": np.arange(index)}, timestep=10 * index)


def test_negative_and_out_of_range_indices():
    trajectory = Counting(4)
    assert trajectory[-1].timestep == 30 and trajectory.reads == [3]
    with pytest.raises(IndexError, match="Frame 4 is out of range: the trajectory has 4 frames"):
        trajectory.read_frame(4)
    with pytest.raises(IndexError):
        trajectory[-5]


def test_iteration_is_repeatable_and_lazy():
    trajectory = Counting(3)
    assert trajectory.reads == []
    assert [f.timestep for f in trajectory] == [0, 10, 20]
    assert [len(f.arrays["id"]) for f in trajectory] == [0, 1, 2]


def test_glob_in_natural_order(tmp_path):
    for step in (0, 1000, 200, 30000, 10):
        (tmp_path / f"particles{step}.dump").write_text("")
    names = [p.name for p in expand_paths(tmp_path / "particles*.dump")]
    assert names == [
        "particles0.dump",
        "particles10.dump",
        "particles200.dump",
        "particles1000.dump",
        "particles30000.dump",
    ]
    assert natural_key("a10b2") == ["a", 10, "b", 2, ""]


def test_missing_files_are_read_errors(tmp_path):
    with pytest.raises(ReadError, match="File not found: .*nope.dump"):
        expand_paths(tmp_path / "nope.dump")
    with pytest.raises(ReadError, match="No file matches .*x\\*.dump"):
        expand_paths(str(tmp_path / "x*.dump"))
    with pytest.raises(ReadError, match="empty list"):
        expand_paths([])
