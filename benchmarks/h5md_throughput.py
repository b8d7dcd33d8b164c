"""Benchmark: H5MD trajectories of 10^7 particles: write and read rates, and the memory of
``analysis.System`` stepping through the frames (not part of the tests).

Each frame is what an engine hands its writer (``Engine._frame``): the default ``traj``
columns (``id type x y z radius mass density vx vy vz fx fy fz omegax omegay omegaz``, 136
bytes per particle), vectors as the columns of one (N, 3) array. Frames are written through
``open_writer(path)`` with no options, as the engines open it (H5MD and its XDMF sidecar), and
again with ``xdmf=False`` (the H5MD file alone); the reference is a plain h5py file holding
the same columns as one contiguous dataset each, written and read in the same run.

Rates are MB (10^6 bytes) of frame data per second. A write is timed until its files are on
disk (``fsync``), so the page cache does not count as disk; before reading, the files'
pages are dropped from the cache (``posix_fadvise``, this benchmark's files only), so reads
come from the disk (on a virtual machine, perhaps from the host's cache of it: compare the
ratios, measured in one run, not the rates). Reading is ``open_trajectory(path)[k]``, every column in memory.

Memory: a fresh process opens ``analysis.System(Particles=path)`` and steps through every
frame, holding the current ``Particles`` as a user's loop does (``p = system.Particles``, so
the previous frame is alive while the next one is read), and again without holding it;
printed is its peak resident memory (Linux's VmHWM) above its memory once the System is
open, in frames (136 bytes per particle); the target is at most 2.

    python benchmarks/h5md_throughput.py [--particles 1e7] [--frames 5] [--folder DIR]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.simulation.specs import TrajectorySpec

VECTORS = {"x": ("x", "y", "z"), "v": ("vx", "vy", "vz"), "f": ("fx", "fy", "fz")}
VECTORS["omega"] = ("omegax", "omegay", "omegaz")
DENSITIES = np.array([0.0, 2500.0, 1500.0])  # of the species, by type

MEMORY_SCRIPT = """
import sys
from pathlib import Path
from pygran_core import analysis

def status(field):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024

with analysis.System(Particles=sys.argv[1]) as system:
    Path("/proc/self/clear_refs").write_text("5")  # the peak from here on
    baseline = status("VmRSS")
    total = 0.0
    for frame in system.frames():
        if sys.argv[2] == "held":
            p = system.Particles  # held until the next frame's replaces it
            total += float(p.x[0])
        else:
            total += float(system.Particles.x[0])
    print(status("VmHWM") - baseline, len(system))
"""


def engine_frames(n: int, frames: int) -> Iterator[Frame]:
    """Frames of ``n`` particles as an engine builds them: the default columns, vectors as
    column views of (n, 3) arrays; each frame moves the particles."""
    rng = np.random.default_rng(7)
    kinds = rng.integers(1, 3, n)
    radius = np.where(kinds == 1, 1e-3, 1.5e-3)
    quantities = {q: rng.normal(0.0, 1e-2, (n, 3)) for q in VECTORS}
    for k in range(frames):
        quantities["x"] += quantities["v"] * 1e-3
        arrays = {}
        for quantity, names in VECTORS.items():
            arrays.update({c: quantities[quantity][:, i] for i, c in enumerate(names)})
        arrays.update(
            id=np.arange(1, n + 1, dtype=np.int64),
            type=kinds,
            radius=radius,
            mass=DENSITIES[kinds] * 4 / 3 * np.pi * radius**3,
            density=DENSITIES[kinds],
        )
        yield Frame(
            {c: arrays[c] for c in TrajectorySpec.args},
            timestep=1000 * k,
            time=1e-3 * k,
            box=np.array([[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]]),
            boundary=("pp", "pp", "ff"),
        )


def frame_bytes(n: int) -> int:
    return 8 * len(TrajectorySpec.args) * n


def to_disk(paths: list[Path]) -> None:
    """Put the files on disk (fsync) and drop their pages from the page cache."""
    for path in paths:
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
        finally:
            os.close(fd)


def written_files(path: Path) -> list[Path]:
    return [p for p in (path, path.with_suffix(".xdmf"), path.with_suffix(".xdmf.h5")) if p.exists()]


def timed(action: Callable[[], object], files: Callable[[], list[Path]]) -> tuple[float, float]:
    """Seconds until ``action`` returns, and until its ``files`` are on disk."""
    start = time.perf_counter()
    action()
    returned = time.perf_counter() - start
    to_disk(files())
    return returned, time.perf_counter() - start


def plain_h5py(path: Path, n: int, frames: int) -> tuple[list[tuple[float, float]], list[float]]:
    """Write, then read back, each frame's columns as contiguous datasets with h5py alone."""
    import h5py

    writes, reads = [], []
    with h5py.File(path, "w") as f:
        for k, frame in enumerate(engine_frames(n, frames)):

            def write(f: h5py.File = f, k: int = k, frame: Frame = frame) -> None:
                group = f.create_group(str(k))
                for name, values in frame.arrays.items():
                    group.create_dataset(name, data=values)
                f.flush()

            writes.append(timed(write, lambda: [path]))
    to_disk([path])
    with h5py.File(path, "r") as f:
        for k in range(frames):
            start = time.perf_counter()
            arrays = {name: dataset[...] for name, dataset in f[str(k)].items()}
            reads.append(time.perf_counter() - start)
            del arrays
    return writes, reads


def pygran(
    path: Path, n: int, frames: int, **options: object
) -> tuple[list[tuple[float, float]], list[float]]:
    """Write through ``open_writer`` as the engines do, then read with ``open_trajectory``."""
    writes, reads = [], []
    with open_writer(path, **options) as writer:
        for frame in engine_frames(n, frames):
            writes.append(timed(lambda frame=frame: writer.write_frame(frame), lambda: written_files(path)))
    to_disk(written_files(path))
    with open_trajectory(path) as trajectory:
        for k in range(frames):
            start = time.perf_counter()
            frame = trajectory[k]
            reads.append(time.perf_counter() - start)
            assert len(frame.arrays["id"]) == n
            del frame
    return writes, reads


def system_memory(path: Path, held: str) -> tuple[int, int]:
    """Peak memory (bytes above the open System's) of stepping through ``path``, the previous
    frame's Particles ``held`` or not, and the frames."""
    done = subprocess.run(
        [sys.executable, "-c", MEMORY_SCRIPT, str(path), held], capture_output=True, text=True, check=True
    )
    grown, count = done.stdout.split()
    return int(grown), int(count)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--particles", type=float, default=1e7)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument(
        "--folder", type=Path, default=None, help="where the files go (default: a temporary folder)"
    )
    args = parser.parse_args()
    n, frames = int(args.particles), args.frames
    size = frame_bytes(n) / 1e6
    print(f"N = {n:,}, {frames} frames of {size:.0f} MB ({len(TrajectorySpec.args)} columns)")
    with tempfile.TemporaryDirectory(dir=args.folder) as folder:
        results = {}
        for label, name, run in (
            ("plain h5py", "plain.h5", plain_h5py),
            ("H5MD, xdmf=False", "alone.h5md", lambda *a: pygran(*a, xdmf=False)),
            ("H5MD + sidecar (engines)", "traj.h5md", pygran),
        ):
            path = Path(folder) / name
            writes, reads = run(path, n, frames)
            results[label] = [size / statistics.median(t) for t in (*zip(*writes), reads)]
            on_disk = sum(p.stat().st_size for p in written_files(path)) / 1e6
            print(f"{label}: {on_disk / frames:.0f} MB on disk per frame")
            if name != "traj.h5md":  # kept for the System's memory
                path.unlink()
        reference = results["plain h5py"]
        print("\nMB/s, and ratio to plain h5py; write: until it returns (page cache) / until on disk")
        print(f"{'':26} {'write (returned)':>17} {'write (on disk)':>16} {'read (from disk)':>17}")
        for label, rates in results.items():
            print(f"{label:26}" + "".join(f"{r:10.0f} {r / ref:5.2f} " for r, ref in zip(rates, reference)))
        for held in ("held", "not held"):
            grown, count = system_memory(Path(folder) / "traj.h5md", held)
            print(
                f"System stepping through {count} frames, the previous Particles {held}: peak "
                f"{grown / 1e6:.0f} MB above the open System, {grown / frame_bytes(n):.2f} frames "
                "(target <= 2)"
            )


if __name__ == "__main__":
    main()
