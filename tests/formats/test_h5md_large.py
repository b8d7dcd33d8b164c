"""H5MD trajectories larger than a block of rows (10^5 particles): frames in which particles
leave, arrive and change order come back exactly, each particle in its own row; a large frame
is written uncompressed in chunks of equal size; and ``analysis.System`` stepping through the
frames holds at most two frames, however many it visits."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

from pygran_core.formats.h5md import BLOCK_ROWS
from pygran_core.io import Frame, open_trajectory, open_writer

N = 100_000
FRAMES = 12
#: bytes of a frame in memory: id, type, x y z, radius, mass, vx vy vz
FRAME_BYTES = 10 * 8 * N


def frames() -> list[Frame]:
    """Frame k: the particles of ids 1 + 500 k to N + 500 k (the lowest leave, new ones come),
    in an order of their own in every other frame; vectors as an engine gives them (the
    columns of one (n, 3) array) in the others."""
    rng = np.random.default_rng(11)
    made = []
    for k in range(FRAMES):
        ids = np.arange(1 + 500 * k, N + 1 + 500 * k, dtype=np.int64)
        if k % 2:
            ids = rng.permutation(ids)
        positions, velocities = rng.normal(size=(N, 3)), rng.normal(size=(N, 3))
        radius = 1e-3 * (1 + ids % 3)
        arrays = {
            "id": ids,
            "type": 1 + ids % 3,
            **dict(zip("x y z".split(), positions.T if k % 2 else [positions[:, j] for j in range(3)])),
            "radius": radius,
            "mass": 2500 * radius**3,
            **dict(zip("vx vy vz".split(), [velocities[:, j] for j in range(3)])),
        }
        made.append(Frame(arrays, timestep=100 * k, time=1e-3 * k, box=np.array([[-5, 5]] * 3, float)))
    return made


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    path = tmp_path_factory.mktemp("large") / "traj.h5md"
    made = frames()
    with open_writer(path) as out:
        for frame in made:
            out.write_frame(frame)
    return path, made


def test_frames_come_back_exactly_with_a_row_per_particle(written):
    path, made = written
    assert N > BLOCK_ROWS  # rows are written and read in several blocks
    with open_trajectory(path) as trajectory:
        assert len(trajectory) == FRAMES
        for want, got in zip(made, trajectory):
            assert list(got.arrays) == list(want.arrays)
            for name, values in want.arrays.items():
                np.testing.assert_array_equal(got.arrays[name], values, err_msg=name)
                assert got.arrays[name].flags.c_contiguous
    with h5py.File(path, "r") as f:
        ids = f["particles/trajectory/id/value"][:]
        position = f["particles/trajectory/position/value"]
        assert ids.shape == (FRAMES, N + 500 * (FRAMES - 1))
        held = np.where(ids >= 0, ids, 0).max(axis=0)
        assert ((ids == held) | (ids == -1)).all()  # each row one particle throughout
        np.testing.assert_array_equal(np.sort(held), np.arange(1, ids.shape[1] + 1))
        np.testing.assert_array_equal(held[:N], made[0].arrays["id"])  # rows in order of arrival
        assert position.compression is None and position.chunks == (1, N // 2, 3)  # two equal chunks


MEMORY = """
import json, sys
from pathlib import Path
from pygran_core import analysis

def status(field):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024

peaks = []
with analysis.System(Particles=sys.argv[1]) as system:
    len(system.Particles)  # the imports and buffers of a first read
    system.goto(1)  # no frame in memory
    Path("/proc/self/clear_refs").write_text("5")  # the peak from here on
    baseline = status("VmRSS")
    for frame in system.frames():
        held = system.Particles  # a user's loop keeps the previous frame until this one is read
        peaks.append(status("VmHWM") - baseline)
    ids = held.id
print(json.dumps({"peaks": peaks, "last": [int(ids[0]), int(ids[-1])]}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the peak memory from /proc")
def test_system_stepping_through_the_frames_holds_two_at_most(written):
    path, made = written
    # freed arrays leave the resident memory at once (glibc's dynamic threshold would keep
    # arrays of this size in its heap, blurring the peak)
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(MEMORY), str(path)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "MALLOC_MMAP_THRESHOLD_": "131072"},
    )
    measured = json.loads(done.stdout)
    assert measured["last"] == [int(made[-1].arrays["id"][0]), int(made[-1].arrays["id"][-1])]
    peaks = np.array(measured["peaks"]) / FRAME_BYTES
    assert len(peaks) == FRAMES
    # the previous frame, the one being read, and the buffers (at this size a third of a frame:
    # a block of rows of x y z and where each row's particle goes)
    assert peaks[-1] <= 2.5, peaks
    assert peaks[-1] - peaks[3] <= 0.25, peaks  # no growth with the frames visited
