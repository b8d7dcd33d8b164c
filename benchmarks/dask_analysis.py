"""Benchmark: per-frame analysis with ``System.map`` on a Dask LocalCluster of 1 and of 2 worker
processes (not part of the tests).

A bed of N spheres (radius 1 mm, density 2500 kg/m^3) on a jittered simple-cubic lattice of
spacing 2.02 r in a box periodic in x and y, discharging: frame k holds N - k * N / 1000
particles (the highest ids leave) moved by a small random step. PyGran's H5MD writer writes
the frames without compression (the write rate is printed). Each frame's analysis, as a user
writes it: the RDF to 4 r, coordination numbers (``equilibrium.Neighbors``) and coarse-grained
density and velocity on a 3-D grid of 2 r cells (Lucy kernel of width r), returned as profiles
along z.

For each cluster (1 worker, then 2; one thread each, and Dask's nanny gives workers
``OMP_NUM_THREADS=1``) the workers are warmed up (imports, a first frame), ``System.map``
reads every frame alone, then runs the analysis, timed (cluster start-up excluded). Printed:
the seconds, the speed-up of 2 workers over 1 (the issue's target: at least 1.8 at N = 10^6,
50 frames), and each worker's peak memory above its idle memory (Linux's VmHWM, reset before
each map) while reading alone and while analysing, also in units of one frame's data (9
columns of 8 bytes per particle). The results of both clusters must be identical.

    python benchmarks/dask_analysis.py [--particles 1e6] [--frames 50] [--folder DIR]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core import analysis
from pygran_core.io import Frame, open_writer

RADIUS = 1e-3
SPACING = 2.02 * RADIUS


def write_trajectory(path: Path, n: int, frames: int) -> float:
    """Write the discharging bed to ``path``; return the write rate in MB/s."""
    side = int(np.ceil(np.sqrt(n / 10)))
    layers = int(np.ceil(n / side**2))
    rng = np.random.default_rng(1)
    cells = np.indices((side, side, layers)).reshape(3, -1).T[:n]
    positions = (cells + 0.5) * SPACING + rng.uniform(-0.005, 0.005, (n, 3)) * RADIUS
    box = np.array([[0.0, side * SPACING], [0.0, side * SPACING], [0.0, (layers + 2) * SPACING]])
    written, seconds = 0, 0.0
    with open_writer(path, compression=0) as writer:
        for k in range(frames):
            count = n - k * (n // 1000)
            velocity = rng.normal(0.0, 0.01, (count, 3))
            positions[:count] += rng.uniform(-0.002, 0.002, (count, 3)) * RADIUS
            arrays = {
                "id": np.arange(1, count + 1, dtype=np.int64),
                "type": np.ones(count, dtype=np.int64),
                "x": positions[:count, 0],
                "y": positions[:count, 1],
                "z": positions[:count, 2],
                "vx": velocity[:, 0],
                "vy": velocity[:, 1],
                "vz": velocity[:, 2],
                "radius": np.full(count, RADIUS),
            }
            frame = Frame(arrays, timestep=1000 * k, time=1e-2 * k, box=box, boundary=("pp", "pp", "ff"))
            start = time.perf_counter()
            writer.write_frame(frame)
            seconds += time.perf_counter() - start
            written += sum(a.nbytes for a in arrays.values())
    return written / 1e6 / seconds


def analyse(system: analysis.System) -> dict[str, Any]:
    """One frame's analysis: RDF, coordination numbers, coarse-grained fields, and the worker's
    peak memory so far."""
    particles = system.Particles
    coon = analysis.equilibrium.Neighbors(particles).coon
    cells = np.ceil(np.diff(particles.meta["box"], axis=1).ravel() / (2 * RADIUS)).astype(int)
    grid = analysis.Grid3D(bins=(int(cells[0]), int(cells[1]), int(cells[2])))
    fields = analysis.CoarseGrain(system, grid=grid, kernel="lucy", width=RADIUS, density=2500.0).compute()
    return {
        "n": len(particles),
        "rdf": particles.computeRDF(dr=RADIUS / 10, rMax=4 * RADIUS).g,
        "coon": np.bincount(coon),
        "density": fields.density.mean(axis=(0, 1)),  # profiles along z
        "velocity": fields.velocity.mean(axis=(0, 1)),
        "pid": os.getpid(),
        "peak_rss": peak_rss(),
    }


def peak_rss() -> int:
    """The calling process's peak resident memory (bytes) since :func:`restart_peak`."""
    return _status("VmHWM")


def restart_peak() -> tuple[int, int]:
    """Make the calling process's peak memory its present memory (Linux); its pid and that memory."""
    Path("/proc/self/clear_refs").write_text("5")
    return os.getpid(), _status("VmRSS")


def _status(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"/proc/self/status has no {field}")


def warm_up(path: str) -> None:
    """In a worker before it is measured: the imports and the reader's first frame."""
    with analysis.System(Particles=path) as system:
        len(system.Particles)


def read_only(system: analysis.System) -> dict[str, Any]:
    """Read the frame and nothing else: what a worker holds for its frames alone."""
    return {"n": len(system.Particles), "pid": os.getpid(), "peak_rss": peak_rss()}


@dataclass
class Measured:
    """One cluster's figures: the analysis' seconds and results, and each worker's peak memory
    above its memory when idle (bytes, by process id) while reading every frame alone and
    while analysing them."""

    seconds: float
    results: list[dict[str, Any]]
    reading: dict[int, int]
    analysing: dict[int, int]


def on_cluster(path: Path, workers: int) -> Measured:
    """``System.map(analyse)`` timed on a LocalCluster of ``workers`` processes, after a
    ``System.map(read_only)`` (which also brings the file into the page cache)."""
    import distributed

    with (
        distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
        analysis.System(Particles=str(path)) as system,
    ):
        client.run(warm_up, str(path))
        idle = dict(client.run(restart_peak).values())
        reading = _growth(idle, system.map(read_only, client=client))
        idle = dict(client.run(restart_peak).values())
        start = time.perf_counter()
        results = system.map(analyse, client=client)
        seconds = time.perf_counter() - start
        return Measured(seconds, results, reading, _growth(idle, results))


def _growth(start: dict[int, int], results: list[dict[str, Any]]) -> dict[int, int]:
    peaks = dict(start)
    for r in results:
        peaks[r["pid"]] = max(peaks[r["pid"]], r["peak_rss"])
    return {pid: peaks[pid] - start[pid] for pid in start}


def _in_frames(growth: dict[int, int], frame_bytes: int) -> str:
    return ", ".join(f"{b / 1e6:.0f} MB ({b / frame_bytes:.1f} frames)" for b in growth.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--particles", type=float, default=1e6)
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument(
        "--folder",
        type=Path,
        default=None,
        help="where to write the trajectory (default: a temporary folder)",
    )
    args = parser.parse_args()
    n = int(args.particles)
    measured = {}
    with tempfile.TemporaryDirectory(dir=args.folder) as folder:
        path = Path(folder) / "bed.h5"
        rate = write_trajectory(path, n, args.frames)
        os.sync()  # the kernel's write-back of the 4 GB would otherwise run beside the first cluster
        frame_bytes = n * 9 * 8
        print(
            f"{args.frames} frames of {n} to {n - (args.frames - 1) * (n // 1000)} particles: "
            f"{path.stat().st_size / 1e9:.2f} GB written at {rate:.0f} MB/s; "
            f"a frame's data {frame_bytes / 1e6:.0f} MB"
        )
        for workers in (1, 2):
            m = measured[workers] = on_cluster(path, workers)
            print(f"{workers} worker(s): {m.seconds:.1f} s, {m.seconds / args.frames:.2f} s per frame")
            print(f"  memory per worker above its start, reading alone: {_in_frames(m.reading, frame_bytes)}")
            print(f"  ... with the analysis: {_in_frames(m.analysing, frame_bytes)}")
    for one, two in zip(measured[1].results, measured[2].results, strict=True):
        for key in ("n", "rdf", "coon", "density", "velocity"):
            np.testing.assert_array_equal(one[key], two[key], err_msg=key)
    print("results of 1 and 2 workers identical")
    ratio = measured[1].seconds / measured[2].seconds
    verdict = "met" if ratio >= 1.8 else "NOT met"
    print(f"speed-up of 2 workers over 1: {ratio:.2f} (target at least 1.8: {verdict})")


if __name__ == "__main__":
    main()
