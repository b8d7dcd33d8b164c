"""Dump parsing speed: PyGran's dump reader vs numpy.loadtxt (and MDAnalysis), plain and gzip.

Writes a synthetic LIGGGHTS dump (id type x y z radius vx vy vz fx fy fz; 5 frames of
200,000 particles, 131 MB), then times reading every frame with each reader, in turn within
each repetition (best of ``--repeats``, so a busy machine slows them alike), and prints MB/s
of dump text and the ratios. PyGran runs as installed (with the core's compiled parser
when it is importable; for the .dump.gz, it then parses frames on a second thread while it
decompresses, when this process may use more than one CPU) and on the core's numpy path.
numpy.loadtxt gets each frame's atom rows as bytes (its fastest input); for the .dump.gz
its time includes decompressing the file once, with ``gzip.open(path).read()`` (one call, the
standard library's fastest way), and splitting it into frames. Every reader's values are
checked bit for bit against numpy.loadtxt's. MDAnalysis is optional: used when importable
here, or through another interpreter that has it (``--mdanalysis-python /path/to/python``).

    python benchmarks/read_dump.py [--particles 200000] [--frames 5] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import io
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.formats import dump
from pygran_core.formats.dump import DumpTrajectory, format_frame
from pygran_core.io import Frame

COLUMNS = "id type x y z radius vx vy vz fx fy fz".split()
HEADER_LINES = 9

MDA_SCRIPT = """
import sys, time
import MDAnalysis as mda
start = time.perf_counter()
u = mda.Universe(sys.argv[1], format="LAMMPSDUMP", lammps_coordinate_convention="unscaled")
for ts in u.trajectory:
    pass
print(time.perf_counter() - start)
"""


def make_dump(path: Path, particles: int, frames: int) -> None:
    rng = np.random.default_rng(0)
    with open(path, "w") as out:
        for k in range(frames):
            arrays = {"id": np.arange(1, particles + 1), "type": rng.integers(1, 3, particles)}
            for name in COLUMNS[2:]:
                arrays[name] = np.round(rng.normal(size=particles) * 1e-3, 9)
            out.write(
                format_frame(
                    Frame(
                        arrays,
                        timestep=1000 * k,
                        box=np.array([[-0.1, 0.1], [-0.1, 0.1], [0.0, 0.4]]),
                        boundary=("ff", "ff", "ff"),
                    )
                )
            )


@contextlib.contextmanager
def numpy_path() -> Iterator[None]:
    """The core without its compiled parser."""
    kernels, dump._accel = dump._accel, None
    try:
        yield
    finally:
        dump._accel = kernels


def pygran(path: Path) -> list[Frame]:
    with DumpTrajectory([path]) as trajectory:
        return list(trajectory)


def table(frame: Frame) -> np.ndarray:
    return np.column_stack([frame.arrays[name] for name in COLUMNS]).astype(np.float64)


def loadtxt(path: Path, particles: int, frames: int) -> list[np.ndarray]:
    """Each frame's atom rows (the layout is known) parsed by numpy.loadtxt."""
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rb") as handle:
        lines = handle.read().split(b"\n")
    tables = []
    for k in range(frames):
        start = k * (HEADER_LINES + particles) + HEADER_LINES
        rows = b"\n".join(lines[start : start + particles])
        tables.append(np.loadtxt(io.BytesIO(rows), dtype=np.float64, comments=None, ndmin=2))
    return tables


def race(contenders: dict[str, Callable[[], Any]], repeats: int) -> tuple[dict[str, float], dict[str, Any]]:
    best, results = dict.fromkeys(contenders, np.inf), {}
    for _ in range(repeats):  # interleaved: every contender once per round
        for name, run in contenders.items():
            start = time.perf_counter()
            results[name] = run()
            best[name] = min(best[name], time.perf_counter() - start)
    return best, results


def mdanalysis(python: str | None, path: Path, repeats: int) -> float | None:
    if python is None:
        try:
            import MDAnalysis  # noqa: F401

            python = sys.executable
        except ImportError:
            print("MDAnalysis: not importable here (pass --mdanalysis-python)")
            return None
    command = [python, "-c", MDA_SCRIPT, str(path)]
    return min(
        float(subprocess.run(command, capture_output=True, text=True, check=True).stdout)
        for _ in range(repeats)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=200_000)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mdanalysis-python", help="an interpreter with MDAnalysis installed")
    args = parser.parse_args()
    parser_name = "the core's compiled parser" if dump._accel is not None else "numpy (no compiled kernels)"
    print(f"pygran: as installed, {parser_name}; pygran-numpy: the core's numpy path; best of {args.repeats}")
    print(f"CPUs this process may use: {dump._cpus()}")
    with tempfile.TemporaryDirectory() as folder:
        plain = Path(folder) / "bench.dump"
        make_dump(plain, args.particles, args.frames)
        packed = plain.with_suffix(".dump.gz")
        packed.write_bytes(gzip.compress(plain.read_bytes(), compresslevel=6, mtime=0))
        megabytes = plain.stat().st_size / 1e6
        print(
            f"{args.frames} frames x {args.particles} particles x {len(COLUMNS)} columns: {megabytes:.1f} MB"
        )
        for path in (plain, packed):

            def pygran_numpy(path: Path = path) -> list[Frame]:
                with numpy_path():
                    return pygran(path)

            contenders = {
                "pygran": lambda path=path: pygran(path),
                "pygran-numpy": pygran_numpy,
                "numpy.loadtxt": lambda path=path: loadtxt(path, args.particles, args.frames),
            }
            best, results = race(contenders, args.repeats)
            for name in ("pygran", "pygran-numpy"):
                for frame, reference in zip(results[name], results["numpy.loadtxt"], strict=True):
                    assert np.array_equal(table(frame).view(np.int64), reference.view(np.int64)), (
                        f"{name} differs"
                    )
            if path == plain:
                seconds = mdanalysis(args.mdanalysis_python, path, args.repeats)
                if seconds is not None:
                    best["MDAnalysis LAMMPSDUMP"] = seconds
            print(f"{path.name} (values identical to numpy.loadtxt, bit for bit):")
            for name, seconds in best.items():
                print(f"  {name:<24} {megabytes / seconds:8.1f} MB/s  ({seconds:.3f} s)")
            for mine in ("pygran", "pygran-numpy"):
                for name, seconds in best.items():
                    if not name.startswith("pygran"):
                        print(f"  {mine} / {name}: {seconds / best[mine]:.2f}x")


if __name__ == "__main__":
    main()
